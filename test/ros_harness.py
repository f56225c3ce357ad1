"""Helpers for the ROS tests (test_ros_*.py): real nodes over DDS on loopback.

Each test gets its own ROS_DOMAIN_ID; node processes get it in their environment, the in-process
probe node in its own rclpy context. Waits are bounded polls, never sleeps as synchronisation.
"""
from __future__ import annotations

import itertools
import os
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from balance_calib.launchless.processes import NodeProcess, ros_args  # noqa: F401 (re-exported)

_counter = itertools.count()
RELIABLE = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)


def six(msg) -> list:
    """The six components of a WrenchStamped (or Wrench), force then torque."""
    w = getattr(msg, 'wrench', msg)
    return [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]


def new_domain_id() -> int:
    """A domain in 1..99 unlikely to be shared with another test running at the same time."""
    return 1 + (os.getpid() * 13 + next(_counter) * 37) % 99


def wait_for(predicate, timeout_s: float, what: str, poll_s: float = 0.02):
    """Poll predicate until it is truthy (returns its value) or fail after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout_s:g} s waiting for {what}')
        time.sleep(poll_s)


class Probe:
    """An in-process rclpy node on the test's domain, spun by a background executor thread."""

    def __init__(self, domain_id: int, name: str = 'test_probe'):
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        # single-threaded, as rclpy.spin() runs the nodes: rclpy's MultiThreadedExecutor busy-loops while
        # a coroutine callback (the calibrator's ~/tare, ~/refit) awaits
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self.received: dict[str, list] = {}

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:   # context shut down
            pass

    def add_node(self, node: Node):
        self.executor.add_node(node)

    def subscribe(self, msg_type, topic: str, qos=RELIABLE) -> list:
        messages = self.received.setdefault(topic, [])
        self.node.create_subscription(msg_type, topic, messages.append, qos)
        return messages

    def call(self, srv_type, service: str, timeout_s: float = 30.0, request=None):
        client = self.node.create_client(srv_type, service)
        wait_for(lambda: client.service_is_ready(), 20.0, f'service {service}')
        future = client.call_async(request or srv_type.Request())
        wait_for(future.done, timeout_s, f'reply of {service}')
        return future.result()

    def call_async(self, srv_type, service: str):
        client = self.node.create_client(srv_type, service)
        wait_for(lambda: client.service_is_ready(), 20.0, f'service {service}')
        return client.call_async(srv_type.Request())

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5.0)
