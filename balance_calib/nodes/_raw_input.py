"""A subscription read by its own thread, serialized, in batches: the calibrator's fast path.

rclpy's executors rebuild a wait set of *every* entity of the node (its services, the parameter
services, timers) at each wake-up and run one callback per message: at 1 kHz on a node with a
dozen services that is most of the CPU a sample costs. RawInput takes one subscription away from
the executors (its callback group is never schedulable) and waits on it alone in a thread of its
own (rcl_wait releases the GIL), takes what is waiting as bytes (`take_message(..., raw=True)`, up
to `max_batch`) and hands the batch to one callback. Services, timers and the other subscriptions
stay on the node's executor, which never wakes for this topic.

`also_read(topic, on_batch)` adds further subscriptions to the same thread and wait set (the
benchmark's sink reads both of the calibrator's topics that way: one thread, no GIL shared between
readers); at each wake-up they are drained in the order they were added.

Threading: the callbacks run in RawInput's thread; the node locks whatever it shares with its
service callbacks. Stopped by `close()` (joins the thread) or by the context's shutdown.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

WAIT_TIMEOUT_NS = 200_000_000  # re-check the stop flag at least this often


class OwnThreadGroup(CallbackGroup):
    """A callback group no executor schedules: its subscription is read by RawInput's thread."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


_NOTHING = contextlib.nullcontext()


@contextlib.contextmanager
def _holding(handles):
    """Hold further subscriptions' handles (kept alive) while waiting on them."""
    with contextlib.ExitStack() as stack:
        for handle in handles:
            stack.enter_context(handle)
        yield


def _never_called(_message) -> None:  # the executors never take this subscription
    raise AssertionError('RawInput subscription taken by an executor')


class RawInput:
    """`topic` (msg_type, serialized) read in a thread of its own; `on_batch(list[bytes])` per
    wake-up.
    """

    def __init__(
        self,
        node,
        msg_type,
        topic: str,
        qos,
        on_batch: Callable[[list], None],
        *,
        max_batch: int = 1000,
        qos_overriding_options=None,
        thread_name: str = 'raw_input',
    ):
        self._node, self._msg_type, self._max_batch = node, msg_type, int(max_batch)
        self._logger = node.get_logger()
        self._context = node.context
        self._group = OwnThreadGroup()
        self._readers: list = []  # (subscription, on_batch), drained in this order
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self.subscription = self.also_read(
            topic, on_batch, qos, qos_overriding_options=qos_overriding_options
        )
        with self._context.handle:
            self._wake = _rclpy.GuardCondition(self._context.handle)
        self._stopping = False
        self._context.on_shutdown(self._request_stop)

    def also_read(
        self, topic: str, on_batch: Callable[[list], None], qos, *, qos_overriding_options=None
    ):
        """One more subscription (same message type) read by this thread; before start().
        Returns it.
        """
        if self._thread.ident is not None:
            raise RuntimeError(f'RawInput.also_read({topic!r}) after start()')
        subscription = self._node.create_subscription(
            self._msg_type,
            topic,
            _never_called,
            qos,
            raw=True,
            callback_group=self._group,
            qos_overriding_options=qos_overriding_options,
        )
        self._readers.append((subscription, on_batch))
        return subscription

    def start(self) -> None:
        self._thread.start()

    def _request_stop(self) -> None:
        self._stopping = True
        try:
            self._wake.trigger_guard_condition()
        except Exception:  # already destroyed with its context: the wait times out instead
            pass

    def close(self) -> None:
        """Stop the thread and wait for it (the subscription is destroyed with the node)."""
        self._request_stop()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def take_waiting(self, subscription=None) -> list:
        """What is waiting on the (first) subscription, as bytes (up to max_batch)."""
        batch = []
        subscription = self.subscription if subscription is None else subscription
        handle, msg_type, limit = subscription.handle, self._msg_type, self._max_batch
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
                wait_set = _rclpy.WaitSet(len(self._readers), 1, 0, 0, 0, 0, self._context.handle)
            first, more = (
                self._readers[0][0].handle,
                [subscription.handle for subscription, _ in self._readers[1:]],
            )
            while not self._stopping and self._context.ok():
                with first, self._wake, self._context.handle, _holding(more) if more else _NOTHING:
                    wait_set.clear_entities()
                    wait_set.add_subscription(first)
                    for handle in more:
                        wait_set.add_subscription(handle)
                    wait_set.add_guard_condition(self._wake)
                    wait_set.wait(WAIT_TIMEOUT_NS)
                for subscription, on_batch in self._readers:
                    if self._stopping:
                        return
                    self._drain(subscription, on_batch)
        # the node or its context went away under us: nothing more to read
        except Exception as err:
            if not self._stopping and self._context.ok():
                self._logger.error(
                    f'{self.subscription.topic_name} reader stopped: {type(err).__name__}: {err}'
                )

    def _drain(self, subscription, on_batch) -> None:
        batch = self.take_waiting(subscription)
        while batch:
            try:
                on_batch(batch)
            except Exception as err:  # one bad batch must not stop the stream
                self._logger.error(
                    f'{type(err).__name__} while processing {len(batch)} samples: {err}',
                    throttle_duration_sec=5.0,
                )
            batch = (
                self.take_waiting(subscription)
                if len(batch) >= self._max_batch and not self._stopping
                else []
            )
