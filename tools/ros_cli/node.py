"""`ros node list|info`: the nodes on the graph, what one publishes, subscribes and serves."""

from __future__ import annotations

import time

from .errors import ToolError
from .session import node_name, other_nodes, rosout_nodes, Session, settled


def node_list(args) -> int:
    with Session() as session:
        nodes = settled(
            session,
            lambda: other_nodes(session),
            args.timeout,
            complete=lambda listing: rosout_nodes(session) <= set(listing),
        )
    for name in nodes:
        print(name)
    return 0


def node_info(args) -> int:
    node = node_name(args.node)
    namespace, _, name = node.rpartition('/')
    namespace = namespace or '/'
    with Session() as session:
        deadline = time.monotonic() + args.timeout
        while node not in other_nodes(session):
            if time.monotonic() > deadline:
                raise ToolError(
                    f'node {node} is not on the graph (waited {args.timeout:g} s); '
                    'see "ros node list"'
                )
            session.rclpy.spin_once(session.node, timeout_sec=0.1)
        graph = session.node

        def info():
            try:
                return (
                    sorted(graph.get_subscriber_names_and_types_by_node(name, namespace)),
                    sorted(graph.get_publisher_names_and_types_by_node(name, namespace)),
                    sorted(graph.get_service_names_and_types_by_node(name, namespace)),
                )
            except Exception:  # rclpy's NodeNameNonExistentError: it left meanwhile
                return ([], [], [])

        left = max(deadline - time.monotonic(), 0.0)
        subscribers, publishers, services = settled(session, info, left)
    print(node)
    for title, entries in (
        ('Subscribers', subscribers),
        ('Publishers', publishers),
        ('Service Servers', services),
    ):
        print(f'  {title}:')
        for topic, types in entries:
            print(f'    {topic}: {", ".join(types)}')
    return 0
