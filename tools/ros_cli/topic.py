"""`ros topic list|info|echo|hz`: the topics on the graph, one topic's endpoints and QoS, its
messages as YAML documents, its rate.
"""

from __future__ import annotations

import time

from .errors import ToolError
from .session import Session, settled
from .values import message_class, message_to_plain


def topic_list(args) -> int:
    with Session() as session:
        topics = settled(
            session, lambda: sorted(session.node.get_topic_names_and_types()), args.timeout
        )
    for name, types in topics:
        print(f'{name} [{", ".join(types)}]')
    return 0


def _qos_lines(qos) -> list[str]:
    """A QoS profile as ros2 topic info -v prints it."""

    def policy(value) -> str:
        return getattr(value, 'name', str(value))

    def duration(value) -> str:
        nanoseconds = getattr(value, 'nanoseconds', None)
        if nanoseconds is None or nanoseconds >= 0x7FFFFFFFFFFFFFFF:
            return 'Infinite'
        return f'{nanoseconds} nanoseconds'

    return [
        '  QoS profile:',
        f'    Reliability: {policy(qos.reliability)}',
        f'    History (Depth): {policy(qos.history)} ({qos.depth})',
        f'    Durability: {policy(qos.durability)}',
        f'    Lifespan: {duration(qos.lifespan)}',
        f'    Deadline: {duration(qos.deadline)}',
        f'    Liveliness: {policy(qos.liveliness)}',
        f'    Liveliness lease duration: {duration(qos.liveliness_lease_duration)}',
    ]


def topic_info(args) -> int:
    with Session() as session:
        session.topic_type(args.topic, args.timeout)  # ToolError when nobody publishes it
        graph = session.node
        own = session.node.get_name()

        def endpoints():
            found = []
            for kind, infos in (
                ('PUBLISHER', graph.get_publishers_info_by_topic(args.topic)),
                ('SUBSCRIPTION', graph.get_subscriptions_info_by_topic(args.topic)),
            ):
                found += [(kind, info) for info in infos if info.node_name != own]
            return found

        def key(found):
            return sorted((k, i.node_namespace, i.node_name) for k, i in found)

        shown = settled(session, lambda: key(endpoints()), args.timeout)
        every = [e for e in endpoints() if (e[0], e[1].node_namespace, e[1].node_name) in shown]
    types = sorted({info.topic_type for _, info in every})
    publishers = [info for kind, info in every if kind == 'PUBLISHER']
    subscriptions = [info for kind, info in every if kind == 'SUBSCRIPTION']
    print(f'Type: {", ".join(types)}')
    for title, infos in (('Publisher', publishers), ('Subscription', subscriptions)):
        print(f'{title} count: {len(infos)}')
        if not args.verbose:
            continue
        print()
        for info in infos:
            print(f'Node name: {info.node_name}')
            print(f'Node namespace: {info.node_namespace}')
            print(f'Topic type: {info.topic_type}')
            print(f'Endpoint type: {title.upper()}')
            print('\n'.join(_qos_lines(info.qos_profile)))
            print()
    return 0


def topic_echo(args) -> int:
    import yaml

    received = []
    with Session() as session:
        type_name = args.type or session.topic_type(args.topic, args.timeout)
        cls = message_class(type_name)

        def show(message):
            if args.count and len(received) >= args.count:
                return
            received.append(1)
            print(
                yaml.safe_dump(
                    message_to_plain(message), sort_keys=False, allow_unicode=True
                ).rstrip()
            )
            print('---', flush=True)

        session.node.create_subscription(cls, args.topic, show, session.qos_for(args.topic))
        deadline = time.monotonic() + args.timeout
        try:
            while not args.count or len(received) < args.count:
                session.rclpy.spin_once(session.node, timeout_sec=0.1)
                if not received and time.monotonic() > deadline:
                    raise ToolError(f'no message on {args.topic} within {args.timeout:g} s')
        except KeyboardInterrupt:
            pass
    return 0


def topic_hz(args) -> int:
    stamps = []
    with Session() as session:
        type_name = args.type or session.topic_type(args.topic, args.timeout)
        cls = message_class(type_name)
        session.node.create_subscription(
            cls, args.topic, lambda _: stamps.append(time.monotonic()), session.qos_for(args.topic)
        )
        deadline = time.monotonic() + args.timeout
        while not stamps:
            session.rclpy.spin_once(session.node, timeout_sec=0.1)
            if time.monotonic() > deadline:
                raise ToolError(f'no message on {args.topic} within {args.timeout:g} s')
        end = time.monotonic() + args.duration
        try:
            while time.monotonic() < end:
                session.rclpy.spin_once(session.node, timeout_sec=0.05)
        except KeyboardInterrupt:
            pass
    if len(stamps) < 2:
        raise ToolError(
            f'only {len(stamps)} message on {args.topic} in {args.duration:g} s: no rate'
        )
    import numpy as np

    gaps = np.diff(np.asarray(stamps))
    print(f'average rate: {1.0 / gaps.mean():.3f}')
    print(
        f'\tmin: {gaps.min():.3f}s max: {gaps.max():.3f}s std dev: {gaps.std():.5f}s window: '
        f'{len(stamps)}'
    )
    return 0
