"""`ros VERB ACTION ...`: the parser, built from one table of sub-commands, and main()."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import sys
from typing import Any, Callable

from balance_calib.broken_pipe import stdout_closed

from . import bag, node, param, service, topic
from .errors import ToolError
from .session import DEFAULT_TIMEOUT_S


@dataclass(frozen=True)
class Argument:
    """One add_argument call: its flags or name, and its keywords."""

    names: tuple[str, ...]
    options: dict[str, Any] = field(default_factory=dict)


def arg(*names: str, **options: Any) -> Argument:
    return Argument(names, options)


@dataclass(frozen=True)
class Command:
    """`ros VERB ACTION`: what it does (run), its help and description and its arguments.
    waits_for says what --timeout (DEFAULT_TIMEOUT_S) waits for; None: no such option, or the
    command's own in `arguments`.
    """

    verb: str
    action: str
    run: Callable[[argparse.Namespace], int]
    help: str
    description: str
    arguments: tuple[Argument, ...] = ()
    waits_for: str | None = None


# verb -> (help, description)
VERBS = {
    'param': (
        "list, get, set, describe or dump a running node's parameters",
        'List, get, set, describe or dump the parameters of a running node through its '
        'rcl_interfaces parameter services.',
    ),
    'topic': (
        'list topics, show one, echo one, measure its rate',
        "List topics, show a topic's endpoints and QoS, print its messages as YAML, or measure "
        'its rate.',
    ),
    'service': (
        'list services, call a Trigger service',
        'List services, or call a std_srvs/Trigger (or Empty) service.',
    ),
    'node': (
        'list nodes, show what one publishes, subscribes and serves',
        "List the nodes on the graph, or show one node's publishers, subscribers and services.",
    ),
    'bag': (
        'describe, record or play a bag',
        'Describe a recorded bag (no DDS), record topics into a bag with balance_recorder, or '
        "play bags with bridge_publisher's replay.",
    ),
}

NODE = arg('node', help='node name, e.g. /balance_calibrator')
NAME = arg('name', help='parameter name, e.g. calibration_bags')
TYPE = arg('type', nargs='?', help='message type (default: the type its publishers offer)')

COMMANDS = (
    Command(
        'param',
        'list',
        param.param_list,
        "names of the node's parameters",
        "Print the names of a node's parameters.",
        (NODE,),
        'the node',
    ),
    Command(
        'param',
        'get',
        param.param_get,
        "one parameter's type and value",
        "Print one parameter's type and value.",
        (NODE, NAME),
        'the node',
    ),
    Command(
        'param',
        'set',
        param.param_set,
        'set one parameter (kept in its current type)',
        'Set one parameter. VALUE is YAML (2.5, true, "[a, b]"); it is converted to the '
        "parameter's current type, so a single path sets a one-element string list.",
        (
            NODE,
            NAME,
            arg('value', help='new value in YAML, e.g. "[bags/campaign_1]" or 1.2'),
        ),
        'the node',
    ),
    Command(
        'param',
        'describe',
        param.param_describe,
        "parameters' type, description and constraints",
        'Print the type, description and constraints (range, read-only) of parameters of a '
        'running node.',
        (NODE, arg('names', nargs='+', metavar='name', help='parameter names')),
        'the node',
    ),
    Command(
        'param',
        'dump',
        param.param_dump,
        "every parameter's value as a params file (YAML)",
        'Print every parameter of a running node as the YAML of a params file '
        '(NODE: ros__parameters: ...), as ros2 param dump does.',
        (NODE,),
        'the node',
    ),
    Command(
        'topic',
        'list',
        topic.topic_list,
        'topics and their types',
        'Print the topics seen on the graph with their types.',
        (),
        'discovery to settle',
    ),
    Command(
        'topic',
        'echo',
        topic.topic_echo,
        'print messages as YAML documents',
        'Print each message of a topic as a YAML document (---) until Ctrl-C or --count messages.',
        (
            arg('topic', help='topic name, e.g. /balance/wrench'),
            TYPE,
            arg(
                '--count',
                type=int,
                default=0,
                help='stop after this many messages (default 0: never)',
            ),
            arg(
                '--once',
                action='store_const',
                const=1,
                dest='count',
                help='one message, then stop',
            ),
        ),
        'the topic and its first message',
    ),
    Command(
        'topic',
        'info',
        topic.topic_info,
        "a topic's type and its publishers and subscriptions",
        "Print a topic's type and how many publishers and subscriptions it has; with -v each "
        'endpoint with its node and QoS profile.',
        (
            arg('topic', help='topic name, e.g. /balance/wrench'),
            arg(
                '-v', '--verbose', action='store_true', help="each endpoint's node and QoS profile"
            ),
        ),
        'the topic and discovery to settle',
    ),
    Command(
        'topic',
        'hz',
        topic.topic_hz,
        'average rate of a topic',
        'Measure the average rate of a topic (arrival times on this machine) over --duration '
        'seconds.',
        (
            arg('topic', help='topic name, e.g. /balance/raw'),
            TYPE,
            arg(
                '--duration',
                type=float,
                default=5.0,
                help='seconds to count messages (default 5)',
            ),
        ),
        'the topic and its first message',
    ),
    Command(
        'service',
        'list',
        service.service_list,
        'services and their types',
        'Print the services seen on the graph with their types.',
        (),
        'discovery to settle',
    ),
    Command(
        'service',
        'call',
        service.service_call,
        'call a std_srvs/srv/Trigger service and print its reply',
        'Call a std_srvs/srv/Trigger (default) or std_srvs/srv/Empty service; exit status 0 '
        'when its reply says success.',
        (
            arg('service', help='e.g. /balance_calibrator/refit or /balance_calibrator/tare'),
            arg(
                'type',
                nargs='?',
                default='std_srvs/srv/Trigger',
                help='std_srvs/srv/Trigger (default) or std_srvs/srv/Empty',
            ),
            arg(
                '--timeout',
                type=float,
                default=300.0,
                help='seconds to wait for the service and its reply (default 300: a refit takes '
                'a while)',
            ),
        ),
    ),
    Command(
        'node',
        'list',
        node.node_list,
        'full names of the nodes on the graph',
        'Print the full names of the nodes on the graph, once discovery has settled.',
        (),
        'discovery to settle',
    ),
    Command(
        'node',
        'info',
        node.node_info,
        "a node's subscribers, publishers and services",
        'Print the topics a node subscribes and publishes and the services it serves, with '
        'their types.',
        (NODE,),
        'the node and discovery to settle',
    ),
    Command(
        'bag',
        'info',
        bag.bag_info,
        'duration, message counts and topic types of a bag',
        "Print a bag's duration, start and end, message count, compression and topics with "
        'types and counts, from its MCAP summaries.',
        (arg('bag', help='rosbag2 directory (metadata.yaml + *.mcap) or a bare .mcap file'),),
    ),
    Command(
        'bag',
        'record',
        bag.bag_record,
        'record topics into a new rosbag2 MCAP bag (balance_recorder)',
        "Record topics into a new rosbag2 MCAP bag directory with the package's "
        'balance_recorder, until Ctrl-C or --duration; the bag is closed (metadata.yaml '
        'written) when it stops.',
        (
            arg('out', help='bag directory to create (it must not exist)'),
            arg(
                'topics',
                nargs='*',
                help='topics to record (default: every topic of docs/interfaces.md)',
            ),
            arg(
                '--duration', type=float, help='stop after this many seconds (default: at Ctrl-C)'
            ),
        ),
    ),
    Command(
        'bag',
        'play',
        bag.bag_play,
        'publish the messages of bags as recorded (bridge_publisher replay)',
        'Publish every message of the bags in receive-time order, header stamps as recorded, '
        'with bridge_publisher in replay mode (node name bag_player); ends when the bags are '
        'played.',
        (
            arg('bags', nargs='+', help='rosbag2 directories or bare .mcap files'),
            arg(
                '--rate',
                type=float,
                default=1.0,
                help='recorded seconds per real second (default 1)',
            ),
            arg('--loop', action='store_true', help='start again at the end, until Ctrl-C'),
            arg(
                '--wait-for-subscribers',
                type=int,
                default=0,
                help='start when /balance/raw has this many subscribers (default 0: at once; '
                'bridge_publisher gives up after its wait_for_subscribers_timeout_s)',
            ),
        ),
    ),
)

DESCRIPTION = (
    'The ros2 CLI verbs a balance_calib user needs (param, topic, service, node, bag '
    'info/record/play), over rclpy, for environments without ros2cli. Same spelling as ros2.'
)
EPILOG = (
    'Examples: ros param set /balance_calibrator calibration_bags "[bags/campaign_1]"; '
    'ros service call /balance_calibrator/refit; ros topic hz /balance/raw; '
    'ros node info /balance_calibrator; ros bag info bags/campaign_1; '
    'ros bag record bags/run2 --duration 10; ros bag play bags/campaign_1'
)


def build_parser(commands=COMMANDS) -> argparse.ArgumentParser:
    """`ros` with one sub-parser per verb and, under it, one per command of the table."""
    parser = argparse.ArgumentParser(prog='ros', description=DESCRIPTION, epilog=EPILOG)
    verbs = parser.add_subparsers(dest='verb', required=True, metavar='VERB', title='verbs')
    actions = {}
    for command in commands:
        if command.verb not in actions:
            help_text, description = VERBS[command.verb]
            verb = verbs.add_parser(command.verb, help=help_text, description=description)
            actions[command.verb] = verb.add_subparsers(
                dest='action', required=True, metavar='ACTION', title='actions'
            )
        sub = actions[command.verb].add_parser(
            command.action, help=command.help, description=command.description
        )
        if command.waits_for:
            sub.add_argument(
                '--timeout',
                type=float,
                default=DEFAULT_TIMEOUT_S,
                help=f'seconds to wait for {command.waits_for} (default {DEFAULT_TIMEOUT_S:g})',
            )
        for argument in command.arguments:
            sub.add_argument(*argument.names, **argument.options)
        sub.set_defaults(func=command.run)
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
