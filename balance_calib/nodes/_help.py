"""`NODE --help` for the node executables, without starting rclpy or DDS.

Each node's main() calls `exit_if_help(__name__, args)` first. With `-h` or `--help` among the
arguments before `--ros-args` it prints the node's module docstring, its parameters (name, default
and description: from the module's PARAMETERS table, its inline comments, or the
declare_parameter calls in its source) and how to set them, then exits 0. Otherwise it returns
and the node starts as usual.
"""
from __future__ import annotations

import ast
import inspect
import re
import sys
import textwrap
from typing import Sequence

ROS_USAGE = """\
Setting parameters, remapping topics (standard ROS 2 arguments, after --ros-args):
  {name} --ros-args -p NAME:=VALUE [-p NAME:=VALUE ...]
  {name} --ros-args --params-file config/graph_params.yaml
  {name} --ros-args -r balance/raw:=/other/raw -r __ns:=/balance2
While it runs: launchless_scripts/ros param list|get|set /{name} ..., and
launchless_scripts/ros topic echo|hz TOPIC (no ros2 CLI needed)."""


# Words for parameters whose node declares them without a description (PARAMETERS without comments).
DESCRIPTIONS = {
    'bridge_publisher': {
        'mode': 'calibration, wind_on, replay or thrust_stand (see above)',
        'balance': 'balance config: lmc6522, b660h or a path',
        'truth_model': 'which of the config\'s matrices the simulated balance obeys: linear, quadratic or cubic',
        'rate_hz': 'bridge samples per second on /balance/raw',
        'effects': 'effects the simulated balance has, e.g. "temperature:sensitivity_per_k=0.0045|0|0|0|0|0"',
        'seed': 'random seed of the simulated noise',
        'point_duration_s': 'calibration: seconds of samples at each load point',
        'transition_s': 'calibration: seconds between points (applied_load all NaN, weights being changed)',
        'installation': 'wind_on: upright or inverted (TM-663 §10.2), as balance_calibrator is set',
        'alpha_start_deg': 'wind_on sweep: first angle of attack, degrees',
        'alpha_end_deg': 'wind_on sweep: last angle of attack, degrees',
        'alpha_step_deg': 'wind_on sweep: angle-of-attack step, degrees',
        'model_weight_n': 'wind_on: weight of the model on the balance, N',
        'temperature_rate_hz': '/balance/temperature messages per second',
        'loop': 'start again from the beginning when the schedule, sweep or bag ends',
        'exit_when_done': 'end the node when the schedule, sweep or bag ends (exit status 0)',
    },
}


def wants_help(args: Sequence[str] | None) -> bool:
    argv = list(sys.argv[1:] if args is None else args[1:] if args and not str(args[0]).startswith('-') else args)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    return '-h' in argv or '--help' in argv


def _inline_comments(source: str) -> dict[str, str]:
    """'name': default,   # comment  -> {name: comment} (continuation comment lines appended)."""
    comments, last = {}, None
    for line in source.splitlines():
        match = re.match(r"\s*'(\w+)'\s*:\s*[^#]*#\s*(.*)$", line)
        if match:
            last = match.group(1)
            comments[last] = match.group(2).strip()
            continue
        continuation = re.match(r'\s*#\s*(.*)$', line)
        if continuation and last is not None:
            comments[last] += ' ' + continuation.group(1).strip()
        else:
            last = None
    return comments


def _show(default) -> str:
    if default == 'string_array':               # live/parameters.py's marker of a string list without default
        return '[] (string list)'
    kind = getattr(default, 'name', None)      # rclpy Parameter.Type: a typed empty default
    if isinstance(kind, str) and kind.endswith('_ARRAY'):
        return f'[] ({kind[:-6].lower()} list)'
    return repr(default)


def parameter_table(module) -> list[tuple[str, str, str]]:
    """(name, default, description) for every parameter the node declares."""
    rows = []
    table = getattr(module, 'PARAMETERS', None)
    try:
        source = inspect.getsource(module)
    except (OSError, TypeError):
        source = ''
    if isinstance(table, dict):
        comments = _inline_comments(source)
        for name, value in table.items():
            if isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], str):
                default, description = value
            elif hasattr(value, 'default') and isinstance(getattr(value, 'description', None), str):
                default, description = value.default, value.description      # a Spec(default, description, ...)
            else:
                default = value
                fallback = DESCRIPTIONS.get(module.__name__.rsplit('.', 1)[-1], {})
                description = comments.get(name) or fallback.get(name, '')
            rows.append((name, _show(default), description))
        return rows
    for node in ast.walk(ast.parse(source)) if source else ():
        if (isinstance(node, ast.Call) and getattr(node.func, 'attr', '') == 'declare_parameter' and node.args
                and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            default = ast.unparse(node.args[1]) if len(node.args) > 1 else ''
            rows.append((node.args[0].value, default, ''))
    return rows


def help_text(module_name: str) -> str:
    module = sys.modules[module_name]
    spec = getattr(module, '__spec__', None)        # python -m balance_calib.nodes.NAME: __name__ is __main__
    name = (spec.name if spec is not None and module_name == '__main__' else module_name).rsplit('.', 1)[-1]
    doc = inspect.getdoc(module) or name
    lines = [f'usage: {name} [--ros-args ...]', '', doc, '']
    rows = parameter_table(module)
    if rows and 'Parameters:' not in doc:
        lines.append('Parameters (name, default):')
        for parameter, default, description in rows:
            lines.append(f'  {parameter} = {default}')
            if description:
                lines += textwrap.wrap(description, 96, initial_indent=' ' * 6, subsequent_indent=' ' * 6)
        lines.append('')
    lines.append(ROS_USAGE.format(name=name))
    return '\n'.join(lines)


def exit_if_help(module_name: str, args: Sequence[str] | None = None) -> None:
    """Print the node's help and exit 0 when -h/--help is given; otherwise return."""
    if wants_help(args):
        try:
            print(help_text(module_name))
            sys.stdout.flush()
        except BrokenPipeError:     # `NODE --help | head`: the reader is gone
            from ..closed_pipe import stdout_closed
            stdout_closed()
        sys.exit(0)
