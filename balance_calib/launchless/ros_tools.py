"""`launchless_scripts/ros`: the few `ros2` CLI habits this package's users need, over rclpy.

There is no ros2cli in the venv (ROS 2 comes from PyPI wheels). This is not a re-implementation
of it, only the everyday verbs, with the same spelling:

    ros param list NODE                 ros2 param list NODE
    ros param get NODE NAME             ros2 param get NODE NAME
    ros param set NODE NAME VALUE       ros2 param set NODE NAME VALUE   (VALUE in YAML: 3, 0.5,
                                                                         true,
                                        "[a.mcap, b.mcap]"; kept in the parameter's current type)
    ros param describe NODE NAME ...    ros2 param describe NODE NAME    (type, description,
                                                                         constraints)
    ros param dump NODE                 ros2 param dump NODE             (a params-file YAML)
    ros topic list                      ros2 topic list -t
    ros topic info TOPIC [-v]           ros2 topic info TOPIC [-v]       (-v: each endpoint's QoS)
    ros topic echo TOPIC [--count N]    ros2 topic echo TOPIC            (YAML documents, ---;
                                                                         --once = --count 1)
    ros topic hz TOPIC [--duration S]   ros2 topic hz TOPIC
    ros service list                    ros2 service list -t
    ros service call SERVICE            ros2 service call SERVICE std_srvs/srv/Trigger
    ros node list                       ros2 node list
    ros node info NODE                  ros2 node info NODE              (publishers, subscribers,
                                                                          services)
    ros bag info BAG                    ros2 bag info BAG                 (no DDS: reads the files)
    ros bag record OUT [TOPIC ...]      ros2 bag record -s mcap -o OUT    (balance_recorder)
    ros bag play BAG [BAG ...]          ros2 bag play BAG                 (bridge_publisher replay)

The lists (topic, service, node) wait until discovery has settled: until what the graph shows has
not changed for SETTLE_S, at most --timeout. A reader that goes away (`... | head`) ends the
output quietly.

Parameters go through the node's rcl_interfaces services (~/list_parameters, ~/get_parameters,
~/set_parameters), as ros2 param does. Exit status 0 on success, 1 when the node, topic or service
does not answer within --timeout, 2 on bad arguments; errors are one line on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import math
from pathlib import Path
import signal
import subprocess
import sys
import time

from ..closed_pipe import stdout_closed

DEFAULT_TIMEOUT_S = 10.0
SETTLE_S = 1.5  # a listing unchanged this long is the graph as discovery has it
# and it is looked at for at least this long (a second participant can take 2 s to be discovered by
# a new process on a busy machine)
MIN_LISTING_S = 3.0
EMPTY_WAIT_S = 5.0  # an empty one this long before it counts (a loaded machine is slow)


class ToolError(Exception):
    """One line for stderr; exit status 1."""


# ---------------------------------------------------------------------------- values

_TYPE_NAMES = {
    1: 'bool',
    2: 'integer',
    3: 'double',
    4: 'string',
    5: 'byte array',
    6: 'bool array',
    7: 'integer array',
    8: 'double array',
    9: 'string array',
}


def parameter_value_to_python(value):
    """rcl_interfaces/ParameterValue -> a Python value (None when the parameter is not set)."""
    kind = value.type
    fields = {
        1: 'bool_value',
        2: 'integer_value',
        3: 'double_value',
        4: 'string_value',
        5: 'byte_array_value',
        6: 'bool_array_value',
        7: 'integer_array_value',
        8: 'double_array_value',
        9: 'string_array_value',
    }
    if kind not in fields:
        return None
    result = getattr(value, fields[kind])
    return list(result) if kind >= 5 else result


def python_to_parameter_value(text: str, current_type: int, name: str = ''):
    """VALUE as typed on the command line (YAML) -> ParameterValue, in the parameter's current type
    when it has one (so `set calibration_bags bag1` gives a one-element string array, and
    `set envelope_margin 2` stays a double). For a double, the words YAML 1.1 leaves as strings
    are numbers as Python spells them (`nan`, `inf`, `1e3`): the node, which knows the parameter's
    range, is the one to refuse a NaN, with its reason.
    """
    from rcl_interfaces.msg import ParameterType, ParameterValue
    import yaml

    try:
        value = yaml.safe_load(text) if text.strip() else ''
    except yaml.YAMLError:
        value = text
    out = ParameterValue()
    kind = current_type or _infer_type(value)
    try:
        if kind == ParameterType.PARAMETER_BOOL:
            if not isinstance(value, bool):
                raise ValueError
            out.bool_value = value
        elif kind == ParameterType.PARAMETER_INTEGER:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError
            out.integer_value = value
        elif kind == ParameterType.PARAMETER_DOUBLE:
            if isinstance(value, str):
                value = float(value)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError
            out.double_value = float(value)
        elif kind == ParameterType.PARAMETER_STRING:
            out.string_value = text if not isinstance(value, str) else value
        elif kind in (
            ParameterType.PARAMETER_STRING_ARRAY,
            ParameterType.PARAMETER_DOUBLE_ARRAY,
            ParameterType.PARAMETER_INTEGER_ARRAY,
            ParameterType.PARAMETER_BOOL_ARRAY,
        ):
            items = value if isinstance(value, list) else ([] if value in ('', None) else [value])
            if kind == ParameterType.PARAMETER_STRING_ARRAY:
                out.string_array_value = [str(v) for v in items]
            elif kind == ParameterType.PARAMETER_DOUBLE_ARRAY:
                out.double_array_value = [float(v) for v in items]
            elif kind == ParameterType.PARAMETER_INTEGER_ARRAY:
                out.integer_array_value = [int(v) for v in items]
            else:
                out.bool_array_value = [bool(v) for v in items]
        else:
            raise ValueError
    except (ValueError, TypeError):
        what = f' for {name}' if name else ''
        raise ToolError(
            f'value {text!r}{what} is not a {_TYPE_NAMES.get(kind, "supported")} '
            "(the parameter's type)"
        ) from None
    out.type = kind
    return out


def _infer_type(value) -> int:
    if isinstance(value, bool):
        return 1
    if isinstance(value, int):
        return 2
    if isinstance(value, float):
        return 3
    if isinstance(value, list):
        if value and all(isinstance(v, bool) for v in value):
            return 6
        if value and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return 7
        if value and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return 8
        return 9
    return 4


def message_to_plain(message):
    """A ROS message -> nested dicts/lists of plain values (what `topic echo` prints as YAML)."""
    if hasattr(message, 'get_fields_and_field_types'):
        return {
            name: message_to_plain(getattr(message, name))
            for name in message.get_fields_and_field_types()
        }
    if isinstance(message, (list, tuple)) or type(message).__name__ == 'ndarray':
        return [message_to_plain(v) for v in message]
    if isinstance(message, float) and not math.isfinite(message):
        return str(message)
    if isinstance(message, (bytes, bytearray)):
        return list(message)
    return message


def message_class(type_name: str):
    """'geometry_msgs/msg/WrenchStamped' -> the class."""
    parts = type_name.split('/')
    if len(parts) != 3:
        raise ToolError(f'type {type_name!r}: expected package/msg/Name')
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise ToolError(f'type {type_name} is not installed in this environment') from None


# ---------------------------------------------------------------------------- graph helpers


class _Session:
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


SERVICE_DISCOVERY_S = 4.0  # a service on the graph is discovered well within this


def await_service_in_graph(session, name: str, timeout: float) -> None:
    """Return once some node on the graph offers the service `name`; ToolError (one line) when
    none does after discovery has had SERVICE_DISCOVERY_S (not the whole timeout: a service that
    is not there will not answer, and a refit's timeout is minutes).
    """
    import os

    wanted = _node_name(name)
    deadline = time.monotonic() + min(timeout, SERVICE_DISCOVERY_S)
    while not any(n == wanted for n, _ in session.node.get_service_names_and_types()):
        if time.monotonic() > deadline:
            nodes = _other_nodes(session)
            seen = f'nodes seen: {", ".join(nodes)}' if nodes else 'no other node seen'
            raise ToolError(
                f'service {wanted} is not in the graph ({seen} on ROS_DOMAIN_ID='
                f'{os.environ.get("ROS_DOMAIN_ID", "0")}); is the node running?'
            )
        session.rclpy.spin_once(session.node, timeout_sec=0.1)


def _node_name(name: str) -> str:
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


def _full_name(name: str, namespace: str) -> str:
    return namespace.rstrip('/') + '/' + name


def _rosout_nodes(session) -> set[str]:
    """The other nodes whose /rosout publisher discovery has seen (every rclpy node has one):
    endpoints and node names arrive separately, so a node can be known by this before its name.
    """
    own = _full_name(session.node.get_name(), session.node.get_namespace())
    return {
        _full_name(info.node_name, info.node_namespace)
        for info in session.node.get_publishers_info_by_topic('/rosout')
    } - {own}


def _other_nodes(session) -> list[str]:
    own = _full_name(session.node.get_name(), session.node.get_namespace())
    return sorted(
        n
        for n in (
            _full_name(name, ns) for name, ns in session.node.get_node_names_and_namespaces()
        )
        if n != own
    )


# ---------------------------------------------------------------------------- param


def param_list(args) -> int:
    from rcl_interfaces.srv import ListParameters

    with _Session() as session:
        reply = session.call(
            ListParameters,
            f'{_node_name(args.node)}/list_parameters',
            ListParameters.Request(),
            args.timeout,
        )
    for name in sorted(reply.result.names):
        print(f'  {name}')
    return 0


def _get(session, node: str, names, timeout: float):
    from rcl_interfaces.srv import GetParameters

    request = GetParameters.Request(names=list(names))
    return session.call(GetParameters, f'{node}/get_parameters', request, timeout).values


def param_get(args) -> int:
    with _Session() as session:
        values = _get(session, _node_name(args.node), [args.name], args.timeout)
    if not values or values[0].type == 0:
        raise ToolError(
            f'{_node_name(args.node)} has no parameter {args.name!r}; see "ros param list '
            f'{args.node}"'
        )
    value = values[0]
    print(f'{_TYPE_NAMES[value.type].capitalize()} value is: {parameter_value_to_python(value)}')
    return 0


def param_set(args) -> int:
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters

    node = _node_name(args.node)
    with _Session() as session:
        current = _get(session, node, [args.name], args.timeout)
        kind = current[0].type if current else 0
        value = python_to_parameter_value(args.value, kind, args.name)
        reply = session.call(
            SetParameters,
            f'{node}/set_parameters',
            SetParameters.Request(parameters=[Parameter(name=args.name, value=value)]),
            args.timeout,
        )
    result = reply.results[0]
    if not result.successful:
        raise ToolError(
            f'setting {args.name} on {node} failed: {result.reason or "refused by the node"}'
        )
    print('Set parameter successful')
    return 0


def param_describe(args) -> int:
    from rcl_interfaces.srv import DescribeParameters

    node = _node_name(args.node)
    with _Session() as session:
        reply = session.call(
            DescribeParameters,
            f'{node}/describe_parameters',
            DescribeParameters.Request(names=list(args.names)),
            args.timeout,
        )
    for name, descriptor in zip(args.names, reply.descriptors):
        if descriptor.type == 0:
            raise ToolError(f'{node} has no parameter {name!r}; see "ros param list {args.node}"')
        print(f'Parameter name: {name}')
        print(f'  Type: {_TYPE_NAMES.get(descriptor.type, descriptor.type)}')
        if descriptor.description:
            print(f'  Description: {descriptor.description}')
        print('  Constraints:')
        if descriptor.read_only:
            print('    Read only: true')
        for bound in list(descriptor.floating_point_range) + list(descriptor.integer_range):
            print(f'    Min value: {bound.from_value}')
            print(f'    Max value: {bound.to_value}')
            if bound.step:
                print(f'    Step: {bound.step}')
        if descriptor.additional_constraints:
            print(f'    Additional constraints: {descriptor.additional_constraints}')
    return 0


def param_dump(args) -> int:
    """The node's parameters as a params file (`--params-file`), as ros2 param dump prints it:
    dotted names nested.
    """
    from rcl_interfaces.srv import ListParameters
    import yaml

    node = _node_name(args.node)
    with _Session() as session:
        names = sorted(
            session.call(
                ListParameters, f'{node}/list_parameters', ListParameters.Request(), args.timeout
            ).result.names
        )
        values = _get(session, node, names, args.timeout) if names else []
        if len(values) != len(names):  # rclpy answers nothing when one is unset: one by one
            values = [(_get(session, node, [name], args.timeout) or [None])[0] for name in names]
    tree: dict = {}
    for name, value in zip(names, values):
        if value is None or value.type == 0:
            continue  # not set (a string array without a default)
        *path, leaf = name.split('.')
        branch = tree
        for part in path:
            branch = branch.setdefault(part, {})
        branch[leaf] = parameter_value_to_python(value)
    print(
        yaml.safe_dump(
            {node: {'ros__parameters': tree}}, sort_keys=False, allow_unicode=True
        ).rstrip()
    )
    return 0


# ---------------------------------------------------------------------------- topic


def topic_list(args) -> int:
    with _Session() as session:
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
    with _Session() as session:
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
    with _Session() as session:
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
    with _Session() as session:
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


# ---------------------------------------------------------------------------- service


def service_list(args) -> int:
    with _Session() as session:
        own = _full_name(session.node.get_name(), session.node.get_namespace()) + '/'
        services = settled(
            session,
            lambda: sorted(
                (name, types)
                for name, types in session.node.get_service_names_and_types()
                if not name.startswith(own)
            ),
            args.timeout,
            complete=lambda listing: _every_node_listed(session, listing),
        )
    for name, types in services:
        print(f'{name} [{", ".join(types)}]')
    return 0


# what every rclpy node serves (unless started without parameter services)
PARAMETER_SERVICES = (
    'describe_parameters',
    'get_parameter_types',
    'get_parameters',
    'list_parameters',
    'set_parameters',
    'set_parameters_atomically',
)


def _every_node_listed(session, services) -> bool:
    """Every other node on the graph has all its parameter services in the listing: DDS brings a
    node's service servers one by one, so a node with only some of them is not yet the whole
    picture (a node without parameter services makes the listing wait for --timeout).
    """
    names = {name for name, _ in services}
    nodes = set(_other_nodes(session)) | _rosout_nodes(session)
    return all(f'{node}/{service}' in names for node in nodes for service in PARAMETER_SERVICES)


def service_call(args) -> int:
    if args.type not in ('std_srvs/srv/Trigger', 'std_srvs/srv/Empty'):
        raise ToolError(
            f'service type {args.type}: only std_srvs/srv/Trigger and std_srvs/srv/Empty are '
            'supported'
        )
    from std_srvs.srv import Empty, Trigger

    service_type = Trigger if args.type.endswith('Trigger') else Empty
    with _Session() as session:
        reply = session.call(service_type, args.service, service_type.Request(), args.timeout)
    if service_type is Empty:
        print('response: (empty)')
        return 0
    print(f'success: {str(reply.success).lower()}\nmessage: {reply.message}')
    return 0 if reply.success else 1


# ---------------------------------------------------------------------------- node


def node_list(args) -> int:
    with _Session() as session:
        nodes = settled(
            session,
            lambda: _other_nodes(session),
            args.timeout,
            complete=lambda listing: _rosout_nodes(session) <= set(listing),
        )
    for name in nodes:
        print(name)
    return 0


def node_info(args) -> int:
    node = _node_name(args.node)
    namespace, _, name = node.rpartition('/')
    namespace = namespace or '/'
    with _Session() as session:
        deadline = time.monotonic() + args.timeout
        while node not in _other_nodes(session):
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


# ---------------------------------------------------------------------------- bag


def bag_info(args) -> int:
    print(format_bag_info(Path(args.bag)))
    return 0


def _run_node(command: list[str], duration: float = 0.0) -> int:
    """A node executable in the foreground, its output ours; Ctrl-C, SIGTERM or the end of
    duration (s, 0 = none) stop it with SIGINT, as a terminal's Ctrl-C would. Its exit status.
    """

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    # its own session: a terminal's Ctrl-C reaches it once, through us
    child = subprocess.Popen(command, start_new_session=True)
    try:
        end = time.monotonic() + duration if duration > 0 else None
        while child.poll() is None and (end is None or time.monotonic() < end):
            time.sleep(0.05)
    except KeyboardInterrupt:
        pass
    finally:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
            try:
                child.wait(timeout=15.0)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        signal.signal(signal.SIGTERM, previous)
    return child.returncode


def bag_record(args) -> int:
    from .processes import ros_args

    parameters = {'output': args.out}
    if args.topics:
        parameters['topics'] = list(args.topics)
    if args.duration is not None and not args.duration > 0:
        raise ToolError(f'--duration {args.duration:g}: give a positive number of seconds')
    status = _run_node(['balance_recorder', *ros_args(parameters)], args.duration or 0.0)
    return 0 if status in (0, -signal.SIGINT) else status


def bag_play(args) -> int:
    from .processes import ros_args

    if not args.rate > 0 or not math.isfinite(args.rate):
        raise ToolError(f'--rate {args.rate:g}: give a positive factor')
    for bag in args.bags:
        if ',' in bag:
            raise ToolError(
                f'{bag}: a bag path with a comma cannot be replayed '
                "(bridge_publisher's bag parameter separates paths by commas)"
            )
        if not Path(bag).exists():
            raise ToolError(f'{bag}: no such bag directory or .mcap file')
    parameters = {
        'mode': 'replay',
        'bag': ','.join(args.bags),
        'speed': args.rate,
        'loop': args.loop,
        'exit_when_done': not args.loop,
        'wait_for_subscribers': args.wait_for_subscribers,
    }
    return _run_node(['bridge_publisher', *ros_args(parameters), '-r', '__node:=bag_player'])


def format_bag_info(path: Path) -> str:
    """ros2 bag info's layout for a rosbag2 MCAP directory or a bare .mcap file (reads the MCAP
    summaries).
    """
    from mcap.reader import make_reader

    if path.is_dir():
        files = sorted(path.glob('*.mcap'))
    elif path.suffix == '.mcap' and path.exists():
        files = [path]
    else:
        raise ToolError(f'{path}: not a bag directory or .mcap file')
    if not files:
        raise ToolError(f'{path}: no .mcap files in it')
    topics: dict[str, list] = {}
    start, end, total, size, compression = None, None, 0, 0, set()
    for file in files:
        size += file.stat().st_size
        with open(file, 'rb') as stream:
            try:
                summary = make_reader(stream).get_summary()
            except Exception as err:  # the mcap library raises its own types for damaged files
                raise ToolError(f'{file}: cannot read its MCAP summary ({err})') from None
        if summary is None or summary.statistics is None:
            raise ToolError(f'{file}: no MCAP summary (unfinished recording?)')
        stats = summary.statistics
        if stats.message_count:
            start = (
                stats.message_start_time if start is None else min(start, stats.message_start_time)
            )
            end = stats.message_end_time if end is None else max(end, stats.message_end_time)
        total += stats.message_count
        for chunk in summary.chunk_indexes:
            compression.add(chunk.compression or 'none')
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            entry = topics.setdefault(channel.topic, [schema.name if schema else '?', 0])
            entry[1] += stats.channel_message_counts.get(channel_id, 0)
    duration = (end - start) / 1e9 if start is not None else 0.0
    lines = [
        f'Files:             {", ".join(f.name for f in files)}',
        f'Bag size:          {size / 1e6:.1f} MB',
        'Storage id:        mcap',
        f'Duration:          {duration:.3f}s',
    ]
    if start is not None:
        lines += [f'Start:             {_stamp(start)}', f'End:               {_stamp(end)}']
    lines += [
        f'Messages:          {total}',
        f'Chunk compression: {", ".join(sorted(compression)) or "none"}',
        'Topic information:',
    ]
    width = max((len(t) for t in topics), default=0)
    for topic, (type_name, count) in sorted(topics.items()):
        lines.append(
            f'  Topic: {topic:{width}} | Type: {type_name} | Count: {count} | Serialization '
            'Format: cdr'
        )
    return '\n'.join(lines)


def _stamp(nanoseconds: int) -> str:
    import datetime as dt

    moment = dt.datetime.fromtimestamp(nanoseconds / 1e9, dt.timezone.utc)
    return f'{moment:%b %d %Y %H:%M:%S.%f}'[:-3] + f' ({nanoseconds / 1e9:.9f})'


# ---------------------------------------------------------------------------- CLI


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='ros',
        description='The ros2 CLI verbs a balance_calib user needs (param, topic, '
        'service, node, bag info/record/play), '
        'over rclpy, for environments without ros2cli. Same spelling as ros2.',
        epilog='Examples: ros param set /balance_calibrator calibration_bags "[bags/campaign_1]"; '
        'ros service call /balance_calibrator/refit; ros topic hz /balance/raw; '
        'ros node info /balance_calibrator; ros bag info bags/campaign_1; '
        'ros bag record bags/run2 --duration 10; ros bag play bags/campaign_1',
    )
    verbs = parser.add_subparsers(dest='verb', required=True, metavar='VERB', title='verbs')

    def with_timeout(sub, what: str):
        sub.add_argument(
            '--timeout',
            type=float,
            default=DEFAULT_TIMEOUT_S,
            help=f'seconds to wait for {what} (default {DEFAULT_TIMEOUT_S:g})',
        )
        return sub

    param = verbs.add_parser(
        'param',
        help="list, get, set, describe or dump a running node's parameters",
        description='List, get, set, describe or dump the parameters of a running node through '
        'its rcl_interfaces parameter services.',
    )
    actions = param.add_subparsers(dest='action', required=True, metavar='ACTION', title='actions')
    sub = with_timeout(
        actions.add_parser(
            'list',
            help="names of the node's parameters",
            description="Print the names of a node's parameters.",
        ),
        'the node',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.set_defaults(func=param_list)
    sub = with_timeout(
        actions.add_parser(
            'get',
            help="one parameter's type and value",
            description="Print one parameter's type and value.",
        ),
        'the node',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.add_argument('name', help='parameter name, e.g. calibration_bags')
    sub.set_defaults(func=param_get)
    sub = with_timeout(
        actions.add_parser(
            'set',
            help='set one parameter (kept in its current type)',
            description='Set one parameter. VALUE is YAML (2.5, true, '
            '"[a, b]"); it is converted to the parameter\'s current '
            'type, so a single path sets a one-element string list.',
        ),
        'the node',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.add_argument('name', help='parameter name, e.g. calibration_bags')
    sub.add_argument('value', help='new value in YAML, e.g. "[bags/campaign_1]" or 1.2')
    sub.set_defaults(func=param_set)
    sub = with_timeout(
        actions.add_parser(
            'describe',
            help="parameters' type, description and constraints",
            description='Print the type, description and constraints (range, read-only) of '
            'parameters of a running node.',
        ),
        'the node',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.add_argument('names', nargs='+', metavar='name', help='parameter names')
    sub.set_defaults(func=param_describe)
    sub = with_timeout(
        actions.add_parser(
            'dump',
            help="every parameter's value as a params file (YAML)",
            description='Print every parameter of a running node as the YAML of a params file '
            '(NODE: ros__parameters: ...), as ros2 param dump does.',
        ),
        'the node',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.set_defaults(func=param_dump)

    topic = verbs.add_parser(
        'topic',
        help='list topics, show one, echo one, measure its rate',
        description="List topics, show a topic's endpoints and QoS, print its messages as YAML, "
        'or measure its rate.',
    )
    actions = topic.add_subparsers(dest='action', required=True, metavar='ACTION', title='actions')
    sub = with_timeout(
        actions.add_parser(
            'list',
            help='topics and their types',
            description='Print the topics seen on the graph with their types.',
        ),
        'discovery to settle',
    )
    sub.set_defaults(func=topic_list)
    sub = with_timeout(
        actions.add_parser(
            'echo',
            help='print messages as YAML documents',
            description='Print each message of a topic as a YAML document '
            '(---) until Ctrl-C or --count messages.',
        ),
        'the topic and its first message',
    )
    sub.add_argument('topic', help='topic name, e.g. /balance/wrench')
    sub.add_argument(
        'type', nargs='?', help='message type (default: the type its publishers offer)'
    )
    sub.add_argument(
        '--count', type=int, default=0, help='stop after this many messages (default 0: never)'
    )
    sub.add_argument(
        '--once', action='store_const', const=1, dest='count', help='one message, then stop'
    )
    sub.set_defaults(func=topic_echo)
    sub = with_timeout(
        actions.add_parser(
            'info',
            help="a topic's type and its publishers and subscriptions",
            description="Print a topic's type and how many publishers and subscriptions it has; "
            'with -v each endpoint with its node and QoS profile.',
        ),
        'the topic and discovery to settle',
    )
    sub.add_argument('topic', help='topic name, e.g. /balance/wrench')
    sub.add_argument(
        '-v', '--verbose', action='store_true', help="each endpoint's node and QoS profile"
    )
    sub.set_defaults(func=topic_info)
    sub = with_timeout(
        actions.add_parser(
            'hz',
            help='average rate of a topic',
            description='Measure the average rate of a topic (arrival times on '
            'this machine) over --duration seconds.',
        ),
        'the topic and its first message',
    )
    sub.add_argument('topic', help='topic name, e.g. /balance/raw')
    sub.add_argument(
        'type', nargs='?', help='message type (default: the type its publishers offer)'
    )
    sub.add_argument(
        '--duration', type=float, default=5.0, help='seconds to count messages (default 5)'
    )
    sub.set_defaults(func=topic_hz)

    service = verbs.add_parser(
        'service',
        help='list services, call a Trigger service',
        description='List services, or call a std_srvs/Trigger (or Empty) service.',
    )
    actions = service.add_subparsers(
        dest='action', required=True, metavar='ACTION', title='actions'
    )
    sub = with_timeout(
        actions.add_parser(
            'list',
            help='services and their types',
            description='Print the services seen on the graph with their types.',
        ),
        'discovery to settle',
    )
    sub.set_defaults(func=service_list)
    sub = actions.add_parser(
        'call',
        help='call a std_srvs/srv/Trigger service and print its reply',
        description='Call a std_srvs/srv/Trigger (default) or std_srvs/srv/Empty service; '
        'exit status 0 when its reply says success.',
    )
    sub.add_argument('service', help='e.g. /balance_calibrator/refit or /balance_calibrator/tare')
    sub.add_argument(
        'type',
        nargs='?',
        default='std_srvs/srv/Trigger',
        help='std_srvs/srv/Trigger (default) or std_srvs/srv/Empty',
    )
    sub.add_argument(
        '--timeout',
        type=float,
        default=300.0,
        help='seconds to wait for the service and its reply (default 300: a refit takes a while)',
    )
    sub.set_defaults(func=service_call)

    node = verbs.add_parser(
        'node',
        help='list nodes, show what one publishes, subscribes and serves',
        description="List the nodes on the graph, or show one node's publishers, subscribers "
        'and services.',
    )
    actions = node.add_subparsers(dest='action', required=True, metavar='ACTION', title='actions')
    sub = with_timeout(
        actions.add_parser(
            'list',
            help='full names of the nodes on the graph',
            description=(
                'Print the full names of the nodes on the graph, once discovery has settled.'
            ),
        ),
        'discovery to settle',
    )
    sub.set_defaults(func=node_list)
    sub = with_timeout(
        actions.add_parser(
            'info',
            help="a node's subscribers, publishers and services",
            description=(
                'Print the topics a node subscribes and publishes and the services it serves, '
                'with their types.'
            ),
        ),
        'the node and discovery to settle',
    )
    sub.add_argument('node', help='node name, e.g. /balance_calibrator')
    sub.set_defaults(func=node_info)

    bag = verbs.add_parser(
        'bag',
        help='describe, record or play a bag',
        description='Describe a recorded bag (no DDS), record topics into a bag with '
        "balance_recorder, or play bags with bridge_publisher's replay.",
    )
    actions = bag.add_subparsers(dest='action', required=True, metavar='ACTION', title='actions')
    sub = actions.add_parser(
        'info',
        help='duration, message counts and topic types of a bag',
        description="Print a bag's duration, start and end, message count, compression and "
        'topics with types and counts, from its MCAP summaries.',
    )
    sub.add_argument('bag', help='rosbag2 directory (metadata.yaml + *.mcap) or a bare .mcap file')
    sub.set_defaults(func=bag_info)
    sub = actions.add_parser(
        'record',
        help='record topics into a new rosbag2 MCAP bag (balance_recorder)',
        description="Record topics into a new rosbag2 MCAP bag directory with the package's "
        'balance_recorder, until Ctrl-C or --duration; the bag is closed '
        '(metadata.yaml written) when it stops.',
    )
    sub.add_argument('out', help='bag directory to create (it must not exist)')
    sub.add_argument(
        'topics', nargs='*', help='topics to record (default: every topic of docs/interfaces.md)'
    )
    sub.add_argument(
        '--duration', type=float, help='stop after this many seconds (default: at Ctrl-C)'
    )
    sub.set_defaults(func=bag_record)
    sub = actions.add_parser(
        'play',
        help='publish the messages of bags as recorded (bridge_publisher replay)',
        description='Publish every message of the bags in receive-time order, header stamps as '
        'recorded, with bridge_publisher in replay mode (node name bag_player); ends '
        'when the bags are played.',
    )
    sub.add_argument('bags', nargs='+', help='rosbag2 directories or bare .mcap files')
    sub.add_argument(
        '--rate', type=float, default=1.0, help='recorded seconds per real second (default 1)'
    )
    sub.add_argument('--loop', action='store_true', help='start again at the end, until Ctrl-C')
    sub.add_argument(
        '--wait-for-subscribers',
        type=int,
        default=0,
        help='start when /balance/raw has this many subscribers (default 0: at once; '
        'bridge_publisher gives up after its wait_for_subscribers_timeout_s)',
    )
    sub.set_defaults(func=bag_play)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()
        return status
    except ToolError as err:
        print(f'ros {args.verb} {args.action}: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # whoever read our output is gone (`ros topic echo ... | head`): nothing more to say, and
        # the interpreter must not fail again flushing stdout at exit
        stdout_closed()
        return 0


if __name__ == '__main__':
    sys.exit(main())
