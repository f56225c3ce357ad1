"""The tools' rclpy session on the graph, and waiting for discovery to show the graph."""

from __future__ import annotations

import os
import time

from .errors import ToolError

DEFAULT_TIMEOUT_S = 10.0
SETTLE_S = 1.5  # a listing unchanged this long is the graph as discovery has it
# and it is looked at for at least this long: longer than Fast DDS's participant announcement
# period (3 s) with room for the endpoints after it, so a node that missed the new process's
# first announcements (a busy machine) is heard at its next periodic one before the list ends
MIN_LISTING_S = 4.5
EMPTY_WAIT_S = 5.0  # an empty one this long before it counts (a loaded machine is slow)
SERVICE_DISCOVERY_S = 4.0  # a service on the graph is discovered well within this


class Session:
    """rclpy init + one node, torn down on exit."""

    def __enter__(self):
        import rclpy

        self.rclpy = rclpy
        rclpy.init()
        self.node = rclpy.create_node('launchless_ros_cli', start_parameter_services=False)
        return self

    def __exit__(self, *exc):
        self.node.destroy_node()
        self.rclpy.try_shutdown()
        return False

    def call(self, service_type, name: str, request, timeout: float):
        client = self.node.create_client(service_type, name)
        try:
            if not name.split('/')[-1].endswith('parameters'):
                await_service_in_graph(self, name, timeout)  # says at once when nobody serves it
            if not client.wait_for_service(timeout_sec=timeout):
                raise ToolError(
                    f'service {name} is not available (is the node running? waited {timeout:g} s)'
                )
            future = client.call_async(request)
            self.rclpy.spin_until_future_complete(self.node, future, timeout_sec=timeout)
            if not future.done():
                raise ToolError(f'no reply from {name} within {timeout:g} s')
            return future.result()
        finally:
            self.node.destroy_client(client)

    def topic_type(self, topic: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while True:
            for name, types in self.node.get_topic_names_and_types():
                if name == topic and types:
                    return types[0]
            if time.monotonic() > deadline:
                raise ToolError(
                    f'topic {topic} has no publisher (waited {timeout:g} s); see "ros topic list"'
                )
            self.rclpy.spin_once(self.node, timeout_sec=0.1)

    def qos_for(self, topic: str):
        """Reliable and transient-local only when every publisher offers it (as ros2 topic
        echo).
        """
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        publishers = self.node.get_publishers_info_by_topic(topic)
        reliable = bool(publishers) and all(
            p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers
        )
        latched = bool(publishers) and all(
            p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers
        )
        return QoSProfile(
            depth=100,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )


def await_service_in_graph(session, name: str, timeout: float) -> None:
    """Return once some node on the graph offers the service `name`; ToolError (one line) when
    none does after discovery has had SERVICE_DISCOVERY_S (not the whole timeout: a service that
    is not there will not answer, and a refit's timeout is minutes).
    """
    wanted = node_name(name)
    deadline = time.monotonic() + min(timeout, SERVICE_DISCOVERY_S)
    while not any(n == wanted for n, _ in session.node.get_service_names_and_types()):
        if time.monotonic() > deadline:
            nodes = other_nodes(session)
            seen = f'nodes seen: {", ".join(nodes)}' if nodes else 'no other node seen'
            raise ToolError(
                f'service {wanted} is not in the graph ({seen} on ROS_DOMAIN_ID='
                f'{os.environ.get("ROS_DOMAIN_ID", "0")}); is the node running?'
            )
        session.rclpy.spin_once(session.node, timeout_sec=0.1)


def node_name(name: str) -> str:
    """A node (or service) name with its leading slash."""
    return name if name.startswith('/') else '/' + name


def settled(
    session,
    listing,
    timeout: float,
    *,
    settle_s: float = SETTLE_S,
    min_s: float = MIN_LISTING_S,
    empty_s: float = EMPTY_WAIT_S,
    complete=lambda listing: True,
):
    """listing() once it has not changed for settle_s (looked at for at least min_s; while it is
    empty, for at least empty_s) and complete(listing) holds, or at the timeout: DDS discovers the
    other participants and then their endpoints one by one, so one early look shows only a part
    (and a loaded machine can pause longer than settle_s between two nodes' endpoints).
    """
    start = time.monotonic()
    last, changed = listing(), start
    while True:
        session.rclpy.spin_once(session.node, timeout_sec=0.05)
        now = time.monotonic()
        current = listing()
        if current != last:
            last, changed = current, now
        looked = now - start
        if looked >= timeout or (
            now - changed >= settle_s
            and looked >= min_s
            and (last or looked >= empty_s)
            and complete(last)
        ):
            return last


def full_name(name: str, namespace: str) -> str:
    return namespace.rstrip('/') + '/' + name


def own_name(session) -> str:
    """The tools' own node, left out of every listing."""
    return full_name(session.node.get_name(), session.node.get_namespace())


def rosout_nodes(session) -> set[str]:
    """The other nodes whose /rosout publisher discovery has seen (every rclpy node has one):
    endpoints and node names arrive separately, so a node can be known by this before its name.
    """
    return {
        full_name(info.node_name, info.node_namespace)
        for info in session.node.get_publishers_info_by_topic('/rosout')
    } - {own_name(session)}


def other_nodes(session) -> list[str]:
    own = own_name(session)
    return sorted(
        n
        for n in (full_name(name, ns) for name, ns in session.node.get_node_names_and_namespaces())
        if n != own
    )
