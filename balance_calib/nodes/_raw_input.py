"""A subscription read by its own thread, serialized, in batches: the calibrator's fast path.

rclpy's executors rebuild a wait set of *every* entity of the node (its services, the parameter
services, timers) at each wake-up and run one callback per message: at 1 kHz on a node with a
dozen services that is most of the CPU a sample costs. RawInput takes one subscription away from the
executors (its callback group is never schedulable) and waits on it alone in a thread of its own
(rcl_wait releases the GIL), takes what is waiting as bytes (`take_message(..., raw=True)`, up to
`max_batch`) and hands the batch to one callback. Services, timers and the other subscriptions stay
on the node's executor, which never wakes for this topic.

Threading: the callback runs in RawInput's thread; the node locks whatever it shares with its
service callbacks. Stopped by `close()` (joins the thread) or by the context's shutdown.
"""
from __future__ import annotations

import threading
from typing import Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

WAIT_TIMEOUT_NS = 200_000_000       # re-check the stop flag at least this often


class OwnThreadGroup(CallbackGroup):
    """A callback group no executor schedules: its subscription is read by RawInput's thread."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


def _never_called(_message) -> None:       # the executors never take this subscription
    raise AssertionError('RawInput subscription taken by an executor')


class RawInput:
    """`topic` (msg_type, serialized) read in a thread of its own; `on_batch(list[bytes])` per wake-up."""

    def __init__(self, node, msg_type, topic: str, qos, on_batch: Callable[[list], None], *,
                 max_batch: int = 1000, qos_overriding_options=None, thread_name: str = 'raw_input'):
        self._msg_type, self._on_batch, self._max_batch = msg_type, on_batch, int(max_batch)
        self._logger = node.get_logger()
        self._context = node.context
        self.subscription = node.create_subscription(msg_type, topic, _never_called, qos, raw=True,
                                                     callback_group=OwnThreadGroup(),
                                                     qos_overriding_options=qos_overriding_options)
        with self._context.handle:
            self._wake = _rclpy.GuardCondition(self._context.handle)
        self._stopping = False
        self._context.on_shutdown(self._request_stop)
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _request_stop(self) -> None:
        self._stopping = True
        try:
            self._wake.trigger_guard_condition()
        except Exception:        # already destroyed with its context: the wait times out instead
            pass

    def close(self) -> None:
        """Stop the thread and wait for it (the subscription is destroyed with the node)."""
        self._request_stop()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def take_waiting(self) -> list:
        """What is waiting on the subscription, as bytes (up to max_batch)."""
        batch = []
        handle, msg_type, limit = self.subscription.handle, self._msg_type, self._max_batch
        with handle:
            while len(batch) < limit:
                taken = handle.take_message(msg_type, True)
                if taken is None:
                    break
                batch.append(taken[0])
        return batch

    def _run(self) -> None:
        try:
            with self._context.handle:
                wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self._context.handle)
            while not self._stopping and self._context.ok():
                with self.subscription.handle, self._wake, self._context.handle:
                    wait_set.clear_entities()
                    wait_set.add_subscription(self.subscription.handle)
                    wait_set.add_guard_condition(self._wake)
                    wait_set.wait(WAIT_TIMEOUT_NS)
                if self._stopping:
                    break
                batch = self.take_waiting()
                while batch:
                    try:
                        self._on_batch(batch)
                    except Exception as err:     # one bad batch must not stop the stream
                        self._logger.error(f'{type(err).__name__} while processing {len(batch)} samples: {err}',
                                           throttle_duration_sec=5.0)
                    batch = self.take_waiting() if len(batch) >= self._max_batch and not self._stopping else []
        except Exception as err:       # the node or its context went away under us: nothing more to read
            if not self._stopping and self._context.ok():
                self._logger.error(f'balance/raw reader stopped: {type(err).__name__}: {err}')
