"""Every node's parameter table, by executable name, and the docs table made from them.

docs/parameters.md is this module's output (test/project/test_parameter_tables.py checks that
it is):

    python -m balance_calib.node_parameters > docs/parameters.md
"""

from __future__ import annotations

import sys
from typing import Mapping

from .aero.live_parameters import PARAMETERS as AERO_COEFFICIENTS
from .bags.recorder_parameters import PARAMETERS as BALANCE_RECORDER
from .daq.parameters import PARAMETERS as BALANCE_DAQ
from .live.parameters import PARAMETERS as BALANCE_CALIBRATOR
from .parameter_table import range_text, show_default, Spec
from .simulation.publisher_parameters import PARAMETERS as BRIDGE_PUBLISHER
from .thrust_stand.analyzer_parameters import PARAMETERS as THRUST_ANALYZER

TABLES: dict[str, Mapping[str, Spec]] = {
    'bridge_publisher': BRIDGE_PUBLISHER,
    'balance_calibrator': BALANCE_CALIBRATOR,
    'balance_recorder': BALANCE_RECORDER,
    'thrust_analyzer': THRUST_ANALYZER,
    'aero_coefficients': AERO_COEFFICIENTS,
    'balance_daq': BALANCE_DAQ,
}

REGENERATE = 'python -m balance_calib.node_parameters > docs/parameters.md'
INTRO = """\
# Node parameters

Generated from each node's parameter table (`balance_calib/parameter_table.py`, the tables named
in `balance_calib/node_parameters.py`); do not edit, regenerate with

    {regenerate}

Every node declares its parameters with these descriptions and ranges (`ros2 param describe` shows
them) and refuses a value of the wrong type, outside its range, NaN or infinite, with one line
naming the parameter. Ranges: `[a, b]` inclusive, `(a, ...` a itself refused, `inf` unbounded.
Read-only parameters are read once, at start-up (`--ros-args -p NAME:=VALUE` or `--params-file`);
the others can be set while the node runs too (`launchless_scripts/ros param set`). `NODE --help`
prints the same table. The simulated thrust stand (`bridge_publisher` with `mode` thrust_stand,
simulation/thrust_stand.py) is not a node of its own: it takes bridge_publisher's parameters."""


def _cell(text: str) -> str:
    return text.replace('|', '\\|')


def markdown_table(table: Mapping[str, Spec]) -> list[str]:
    """The lines of one node's table: name, type, default, range, read-only, description."""
    lines = [
        '| name | type | default | range | read-only | description |',
        '|---|---|---|---|---|---|',
    ]
    for name, spec in table.items():
        span = range_text(spec)
        lines.append(
            f'| `{name}` | {spec.kind} | `{_cell(show_default(spec))}` | '
            f'{_cell(span)} | {"yes" if spec.read_only else ""} | '
            f'{_cell(spec.description)} |'
        )
    return lines


def markdown() -> str:
    """docs/parameters.md: every node's table."""
    lines = INTRO.format(regenerate=REGENERATE).splitlines()
    for node, table in TABLES.items():
        lines += ['', f'## {node}', ''] + markdown_table(table)
    return '\n'.join(lines) + '\n'


def main() -> int:
    sys.stdout.write(markdown())
    return 0


if __name__ == '__main__':
    sys.exit(main())
