"""`NODE --help` for the node executables, without starting rclpy or DDS.

Each node's main() calls `exit_if_help(__name__, args)` first. With `-h` or `--help` among the
arguments before `--ros-args` it prints the node's module docstring, its parameter table (name,
default, type, range, read-only, description: node_parameters.TABLES, the table the node declares)
and how to set them, then exits 0. Otherwise it returns and the node starts as usual.
"""

from __future__ import annotations

import inspect
import sys
import textwrap
from typing import Sequence

from balance_calib.node_parameters import TABLES
from balance_calib.parameter_table import range_text, show_default

ROS_USAGE = """\
Setting parameters, remapping topics (standard ROS 2 arguments, after --ros-args):
  {name} --ros-args -p NAME:=VALUE [-p NAME:=VALUE ...]
  {name} --ros-args --params-file config/graph_params.yaml
  {name} --ros-args -r balance/raw:=/other/raw -r __ns:=/balance2
While it runs: launchless_scripts/ros param list|get|set /{name} ..., and
launchless_scripts/ros topic echo|hz TOPIC (no ros2 CLI needed)."""


def wants_help(args: Sequence[str] | None) -> bool:
    argv = list(
        sys.argv[1:]
        if args is None
        else args[1:]
        if args and not str(args[0]).startswith('-')
        else args
    )
    if '--ros-args' in argv:
        argv = argv[: argv.index('--ros-args')]
    return '-h' in argv or '--help' in argv


def node_name(module) -> str:
    """The executable's name of a node module (also when run as python -m ...: __main__)."""
    spec = getattr(module, '__spec__', None)
    name = spec.name if spec is not None and module.__name__ == '__main__' else module.__name__
    return name.rsplit('.', 1)[-1]


def parameter_table(module) -> list[tuple[str, str, str]]:
    """(name, default, description) for every parameter the node declares: its table's."""
    return [
        (name, show_default(spec), spec.description)
        for name, spec in TABLES.get(node_name(module), {}).items()
    ]


def parameter_lines(node: str) -> list[str]:
    """The help's parameter section: a line `NAME = DEFAULT  (type, range, read-only)` and the
    description under it, for every entry of the node's table.
    """
    table = TABLES.get(node, {})
    if not table:
        return []
    lines = [
        'Parameters (NAME = default  (type, range, read-only); docs/parameters.md has the '
        'same table):'
    ]
    for name, spec in table.items():
        facts = ', '.join(
            fact
            for fact in (spec.kind, range_text(spec), 'read-only' if spec.read_only else '')
            if fact
        )
        lines.append(f'  {name} = {show_default(spec)}  ({facts})')
        lines += textwrap.wrap(
            spec.description,
            96,
            initial_indent=' ' * 6,
            subsequent_indent=' ' * 6,
            break_on_hyphens=False,
            break_long_words=False,
        )
    if any(spec.read_only for spec in table.values()):
        lines.append('  (read-only: set at start-up only, with -p or --params-file)')
    return lines + ['']


def help_text(module_name: str) -> str:
    module = sys.modules[module_name]
    name = node_name(module)
    doc = inspect.getdoc(module) or name
    lines = [f'usage: {name} [--ros-args ...]', '', doc, ''] + parameter_lines(name)
    lines.append(ROS_USAGE.format(name=name))
    return '\n'.join(lines)


def exit_if_help(module_name: str, args: Sequence[str] | None = None) -> None:
    """Print the node's help and exit 0 when -h/--help is given; otherwise return."""
    if wants_help(args):
        try:
            print(help_text(module_name))
            sys.stdout.flush()
        except BrokenPipeError:  # `NODE --help | head`: the reader is gone
            from ..broken_pipe import stdout_closed

            stdout_closed()
        sys.exit(0)
