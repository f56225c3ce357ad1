"""balance_recorder: record named topics into a rosbag2 MCAP bag (there is no `ros2 bag` here).

Its parameters, `output` (the bag directory to create) and `topics`, are the table of
bags/recorder_parameters.py.

Each topic's type and its publishers' QoS come from the graph; topics without publishers yet are
looked up again every half second. Messages are recorded as serialized bytes (raw subscriptions)
through the pure BagWriter. A bag with a hole says so: samples DDS reports lost to a subscription
(a stall longer than the writers' history, nodes/_qos.py), and on a topic with one writer the gaps
in its publication sequence numbers (bags/sequence_gaps.py: what a full queue overwrote too,
confirmed at each look at the graph), are warned about as they happen (once a second a topic at
most) and counted in the closing line. SIGINT and SIGTERM both end the recording cleanly: the bag's
MCAP summary and metadata.yaml are complete afterwards. While it records, what it received is put
into the file every FLUSH_PERIOD_S (one chunk each), so a refit of the bag still being recorded
reads it up to a second ago.
"""

import importlib
import signal
import sys
import time

from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from balance_calib.bags.errors import BagError
from balance_calib.bags.recorder_parameters import DEFAULT_TOPICS, PARAMETERS
from balance_calib.bags.sequence_gaps import SequenceGaps
from balance_calib.bags.writer import BagWriter, qos_profiles_yaml
from balance_calib.parameter_table import ParameterError

from ._parameters import declare_table
from ._qos import STREAM_DEPTH
from ._run import run_node

DISCOVERY_PERIOD_S = 0.5
FLUSH_PERIOD_S = 1.0  # the file holds what was received up to this long ago
QUEUE_DEPTH = STREAM_DEPTH  # a recorder would rather buffer than drop
HOLE_WARNING_PERIOD_S = 1.0  # a topic losing samples is warned about at most this often


def offered_qos_as_dict(qos: QoSProfile) -> dict:
    """An offered QoS profile in rosbag2's v9 YAML vocabulary ('reliable', 'keep_last', ...)."""

    def duration(value):
        return {
            'sec': value.nanoseconds // 1_000_000_000,
            'nsec': value.nanoseconds % 1_000_000_000,
        }

    return {
        'history': qos.history.name.lower(),
        'depth': qos.depth,
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(),
        'deadline': duration(qos.deadline),
        'lifespan': duration(qos.lifespan),
        'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': duration(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': qos.avoid_ros_namespace_conventions,
    }


def subscription_qos(offered: list[QoSProfile]) -> QoSProfile:
    """Reliable / transient-local only if every publisher offers it, as rosbag2 adapts."""
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    transient_local = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE
        ),
    )


def message_class(msgtype: str):
    """'pkg/msg/Type' -> the generated Python class."""
    package, _, name = msgtype.rpartition('/')
    return getattr(importlib.import_module(package.replace('/', '.')), name)


class BalanceRecorder(Node):
    def __init__(self):
        super().__init__('balance_recorder')
        parameters = declare_table(self, PARAMETERS)  # read once, here (read-only)
        topics, output = parameters['topics'], parameters['output']
        self._default_topics = {self.resolve_topic_name(topic) for topic in DEFAULT_TOPICS}
        if not output:
            raise BagError('parameter output (the bag directory to create) is required')
        self._writer = BagWriter(output)
        self._writer.open()
        self._pending = [self.resolve_topic_name(topic) for topic in topics]
        self._recording = {}
        self._lost: dict[str, int] = {}  # as DDS reported them
        self._gaps = SequenceGaps()  # as the writers' numbering shows them
        self._warned_at: dict[str, float] = {}
        self._closing = False  # a shut-down context: holes go into the closing line only
        self.get_logger().info(f'recording {", ".join(self._pending)} into {output}')
        # The timer runs for the whole recording, even with every topic found: rclpy (Jazzy) wakes
        # spin() for a signal *before* it shuts the context down, so without a periodic wakeup
        # spin() could sleep through the shutdown until the next message.
        self.create_timer(DISCOVERY_PERIOD_S, self._discover)
        self._flushed = 0
        self.create_timer(FLUSH_PERIOD_S, self._flush)
        self._discover()

    def _flush(self):
        written = sum(self._writer.message_counts.values())
        if self._writer.is_open and written != self._flushed:
            self._writer.flush()
            self._flushed = written

    def _discover(self):
        for topic in self._recording:
            if self._gaps.single_writer(topic, self.count_publishers(topic) == 1):
                self._warn_of_hole(topic)
        if not self._pending:
            return
        types = dict(self.get_topic_names_and_types())
        for topic in list(self._pending):
            publishers = self.get_publishers_info_by_topic(topic)
            if topic not in types or not publishers:
                continue
            self._pending.remove(topic)
            msgtype = types[topic][0]
            if len(types[topic]) > 1:
                self.get_logger().warn(
                    f'{topic} has several types {types[topic]}; recording {msgtype}'
                )
            offered = [p.qos_profile for p in publishers if p.topic_type == msgtype]
            try:
                msg_class = message_class(msgtype)
                self._writer.add_topic(
                    topic,
                    msgtype,
                    qos_profiles_yaml([offered_qos_as_dict(q) for q in offered]),
                    type_description_hash=str(publishers[0].topic_type_hash),
                )
            except (BagError, ImportError, AttributeError) as error:
                self.get_logger().error(f'cannot record {topic}: {error}')
                continue
            self._recording[topic] = self.create_subscription(
                msg_class,
                topic,
                self._writer_for(topic),
                subscription_qos(offered),
                raw=True,
                event_callbacks=SubscriptionEventCallbacks(message_lost=self._loss_on(topic)),
            )
            self._gaps.single_writer(topic, len(publishers) == 1)
            self.get_logger().info(f'recording {topic} ({msgtype})')

    def _loss_on(self, topic):
        def lost(info: QoSMessageLostInfo):
            self._lost[topic] = info.total_count
            self._warn_of_hole(topic)

        return lost

    def _holes(self) -> dict[str, int]:
        """Samples missing per topic: the larger of DDS's count and the numbering's."""
        topics = set(self._lost) | set(self._gaps.missing)
        holes = {t: max(self._lost.get(t, 0), self._gaps.missing.get(t, 0)) for t in topics}
        return {topic: count for topic, count in sorted(holes.items()) if count}

    def _warn_of_hole(self, topic: str) -> None:
        now = time.monotonic()
        if (
            self._closing
            or now - self._warned_at.get(topic, -HOLE_WARNING_PERIOD_S) < HOLE_WARNING_PERIOD_S
        ):
            return
        self._warned_at[topic] = now
        self.get_logger().warn(
            f'{topic}: {self._holes().get(topic, 0)} message(s) so far lost before they reached '
            'the recorder; the bag has a hole'
        )

    def _writer_for(self, topic):
        def write(serialized: bytes, message_info: dict):
            self._gaps.seen(topic, message_info.get('publication_sequence_number'))
            self._writer.write(
                topic,
                self.get_clock().now().nanoseconds,
                serialized,
                message_info.get('source_timestamp'),
            )

        return write

    def destroy_node(self):
        """Write what DDS has already delivered, finish the bag, then leave the graph."""
        counts = {}
        self._closing = True
        if self._writer.is_open:
            for topic, subscription in self._recording.items():
                # After a signal the context is shut down and no executor can run; messages
                # already received are still in the reader's queue, so take them directly.
                write = self._writer_for(topic)
                while (
                    taken := subscription.handle.take_message(subscription.msg_type, True)
                ) is not None:
                    write(*taken)
            self._gaps.close()
            counts = self._writer.close()
        super().destroy_node()
        # Logged once the node is gone, as the shut-down context can no longer reach /rosout.
        summary = ', '.join(f'{topic}: {count}' for topic, count in counts.items())
        self.get_logger().info(
            f'bag {self._writer.path} closed; messages written: {summary or "none"}'
        )
        if holes := self._holes():
            said = ', '.join(f'{topic}: {count}' for topic, count in holes.items())
            self.get_logger().warn(f'messages lost before they reached the recorder: {said}')
        if self._pending:
            # the defaults cover every interface topic and a run publishes only some of them: a
            # silent default topic is not news, a silent topic the user added is
            quiet = [t for t in self._pending if t in self._default_topics]
            odd = [t for t in self._pending if t not in self._default_topics]
            if quiet:
                self.get_logger().info(f'no publishers seen on {", ".join(quiet)}')
            if odd:
                self.get_logger().warn(f'never saw publishers on {", ".join(odd)}')


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    # rclpy's own handlers for SIGINT and SIGTERM (ALL) shut the context down, so spin() returns
    # or raises ExternalShutdownException and the bag is closed in destroy_node() either way.
    # With SIGINT's default action in place, rclpy's handler does not chain to Python's, so
    # Ctrl-C cannot raise KeyboardInterrupt in the middle of writing a message.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    return run_node(
        'balance_recorder',
        BalanceRecorder,
        refused=(BagError, ParameterError),
        args=args,
        signals=SignalHandlerOptions.ALL,
    )


if __name__ == '__main__':
    sys.exit(main())
