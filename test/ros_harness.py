"""Helpers for the ROS tests (test_ros_*.py): real nodes over DDS on loopback.

Each test gets its own ROS_DOMAIN_ID from new_domain_id() (or the `ros_domain` fixture of
conftest.py, which calls it); node processes get it in their environment, the in-process
probe node in its own rclpy context. Waits are bounded polls, never sleeps as synchronisation.
"""

from __future__ import annotations

import itertools
import os
from pathlib import Path
import socket
import subprocess
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, ShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from balance_calib.launchless.processes import NodeProcess, ros_args  # noqa: F401 (re-exported)

_counter = itertools.count()
DOMAIN_IDS = range(1, 102)
DISCOVERY_PORT_0, DOMAIN_PORT_GAIN = 7410, 250  # RTPS default ports: PB + d1 = 7410, DG = 250
SCRIPTS = Path(__file__).resolve().parent.parent / 'launchless_scripts'
RELIABLE = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)


def six(msg) -> list:
    """The six components of a WrenchStamped (or Wrench), force then torque."""
    w = getattr(msg, 'wrench', msg)
    return [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]


def _xdist_worker() -> tuple[int, int]:
    """(index, count) of this pytest-xdist worker ('gw3' of 4: (3, 4)); (0, 1) without xdist."""
    name = os.environ.get('PYTEST_XDIST_WORKER', '')
    count = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1') or 1)
    return (int(name[2:]) if name.startswith('gw') else 0), max(count, 1)


def _nobody_on(domain_id: int) -> bool:
    """Fast DDS's first participant on a domain binds UDP port 7410 + 250 d (its metatraffic
    unicast port): if that port can be bound, no participant of this machine is on the domain.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind(('0.0.0.0', DISCOVERY_PORT_0 + DOMAIN_PORT_GAIN * domain_id))
        except OSError:
            return False
    return True


def new_domain_id() -> int:
    """A ROS_DOMAIN_ID for one test alone: the one allocator of the suite.

    Drawn from 1..101 (0 is everyone's default; above 101 Fast DDS's ports reach Linux's
    ephemeral range), each pytest-xdist worker from its own residue class, so two workers of a run
    never share a domain; in turn within a process, starting from a place set by its pid so that
    another run on this machine starts elsewhere; a domain on which a participant of this machine
    is already present (another run's nodes, a node left by an earlier test) is passed over.
    """
    worker, workers = _xdist_worker()
    own = [d for d in DOMAIN_IDS if d % workers == worker]
    start = (os.getpid() * 13) % len(own)
    for _ in own:
        candidate = own[(start + next(_counter)) % len(own)]
        if _nobody_on(candidate):
            return candidate
    raise RuntimeError(
        f'no free ROS domain among {own[0]}..{own[-1]} for this test: every one '
        'has a participant on this machine'
    )


def ros(domain_id: int, *args, timeout: float = 120):
    """launchless_scripts/ros ARGS on a domain (the ros2 CLI habits), output captured."""
    return subprocess.run(
        [str(SCRIPTS / 'ros'), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)),
    )


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
        # single-threaded, as rclpy.spin() runs the nodes: rclpy's MultiThreadedExecutor busy-loops
        # while a coroutine callback (the calibrator's ~/tare, ~/refit) awaits
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.errors: list[Exception] = []
        self.cycles = 0
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self.received: dict[str, list] = {}

    def _spin(self):
        """Spin until the context ends. An error in one callback (or in taking from an entity
        being destroyed) is recorded in self.errors, not allowed to end the thread silently: a
        dead spin thread looks like a node that never answers.
        """
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except (ExternalShutdownException, ShutdownException):
                break
            except Exception as error:  # noqa: BLE001 (kept for the test to see)
                if not self.context.ok():
                    break
                self.errors.append(error)
            self.cycles += 1

    def add_node(self, node: Node):
        self.executor.add_node(node)

    def retire(self, node: Node, timeout_s: float = 5.0):
        """Remove `node` from the executor and destroy it once the executor has gone round
        without it (destroying entities the spin thread is waiting on can raise there).
        """
        self.executor.remove_node(node)
        seen = self.cycles
        wait_for(lambda: self.cycles >= seen + 2, timeout_s, 'the executor to let go of the node')
        node.destroy_node()

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
        assert not self.errors, f'the probe executor raised in a callback: {self.errors!r}'
