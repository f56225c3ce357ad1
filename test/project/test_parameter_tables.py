"""One parameter table per node: its check refuses a bad value in one line naming the parameter,
`NODE --help` lists every entry, docs/parameters.md is what the tables generate, and every node
executable has a table, importable without rclpy.
"""

import array
import ast
import math
from pathlib import Path
import re
import subprocess
import sys

import pytest
import yaml

from balance_calib import node_parameters
from balance_calib.node_parameters import TABLES
from balance_calib.parameter_table import (
    BOOL,
    check_value,
    DOUBLE,
    DOUBLE_ARRAY,
    INTEGER,
    ParameterError,
    problems,
    show_default,
    Spec,
    STRING,
    STRING_ARRAY,
)

ROOT = Path(__file__).resolve().parents[2]
ENTRIES = [(node, name, spec) for node, table in TABLES.items() for name, spec in table.items()]
IDS = [f'{node}.{name}' for node, name, _ in ENTRIES]


def refused(name: str, spec: Spec, value) -> str:
    with pytest.raises(ParameterError) as caught:
        check_value(name, spec, value)
    message = str(caught.value)
    assert '\n' not in message and message.startswith(f'parameter {name} '), message
    return message


def node_executables() -> set[str]:
    """setup.py's console scripts that run a module of balance_calib/nodes."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    scripts = next(
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Dict)
        and any(getattr(k, 'value', None) == 'console_scripts' for k in node.keys)
    )
    entries = ast.literal_eval(scripts.values[0])
    targets = dict(re.match(r'\s*([\w-]+)\s*=\s*([\w.]+):', entry).groups() for entry in entries)
    return {name for name, module in targets.items() if module.startswith('balance_calib.nodes.')}


def test_every_node_has_a_table_and_nothing_else_does():
    assert set(TABLES) == node_executables()
    # any other rclpy node in nodes/ would need one too (simulation/thrust_stand.py is a pure
    # simulator that bridge_publisher's thrust_stand mode runs: its parameters are
    # bridge_publisher's)
    with_a_node = {
        path.stem
        for path in (ROOT / 'balance_calib' / 'nodes').glob('*.py')
        if re.search(r'^class \w+\(Node\):', path.read_text(), re.M)
    }
    assert with_a_node == set(TABLES)


@pytest.mark.parametrize('node', TABLES)
def test_each_table_is_consistent(node):
    assert problems(TABLES[node]) == []


def test_a_table_with_a_default_outside_its_range_is_reported():
    assert problems(
        {
            'period_s': Spec(0.0, 'a period, s', 0.0, low_open=True),
            'label': Spec('x', 'a label of a thing', 0.0, 1.0),
        }
    ) == [
        'period_s: parameter period_s must be in (0, inf), not 0',
        'label: a range on a string parameter',
    ]


def test_the_tables_import_without_rclpy():
    probe = (
        'import sys, balance_calib.node_parameters; assert not [m for m in sys.modules '
        'if m.split(".")[0] in ("rclpy", "rcl_interfaces")]'
    )
    done = subprocess.run(
        [sys.executable, '-c', probe], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr


# --- the check, on hand-made entries -----------------------------------------------------------
PERIOD = Spec(1.0, 'a period, s', 0.0, low_open=True)
SAMPLES = Spec(100, 'samples in a window', 10, 1_000_000)


def test_numbers_in_and_out_of_their_range():
    assert check_value('period_s', PERIOD, 1e-300) == 1e-300
    held = check_value('period_s', PERIOD, 5)  # an int for a double is that double
    assert held == 5.0 and type(held) is float
    assert refused('period_s', PERIOD, 0.0) == 'parameter period_s must be in (0, inf), not 0'
    assert refused('period_s', PERIOD, -2.5) == 'parameter period_s must be in (0, inf), not -2.5'
    assert check_value('tare_samples', SAMPLES, 10) == 10  # both ends are inside
    assert check_value('tare_samples', SAMPLES, 1_000_000) == 1_000_000
    assert (
        refused('tare_samples', SAMPLES, 9)
        == 'parameter tare_samples must be in [10, 1e+06], not 9'
    )
    assert refused('tare_samples', SAMPLES, 1_000_001).endswith('not 1e+06')  # %g of 1000001
    assert 'must be an integer' in refused('tare_samples', SAMPLES, 10.0)
    assert 'must be an integer' in refused('tare_samples', SAMPLES, 2.5)
    closed_low = Spec(0.0, 'a time that may be zero', 0.0)
    assert check_value('delay_s', closed_low, 0.0) == 0.0
    anything = Spec(-1.0, 'any finite number at all')
    assert check_value('offset', anything, -1e300) == -1e300


@pytest.mark.parametrize('value', [math.nan, math.inf, -math.inf])
def test_nan_and_inf_are_refused_with_or_without_a_range(value):
    assert (
        refused('period_s', PERIOD, value)
        == f'parameter period_s must be a finite number in (0, inf), not {value}'
    )
    assert (
        refused('offset', Spec(0.0, 'any finite number'), value)
        == f'parameter offset must be a finite number, not {value}'
    )


def test_types_are_held_to_the_default():
    assert (
        refused('loop', Spec(False, 'start again at the end'), 1)
        == 'parameter loop must be true or false, not 1'
    )
    assert refused('period_s', PERIOD, True) == 'parameter period_s must be a number, not True'
    assert refused('period_s', PERIOD, 'fast') == "parameter period_s must be a number, not 'fast'"
    assert (
        refused('frame_id', Spec('tunnel', 'frame of the wrench'), 5)
        == 'parameter frame_id must be a string, not 5'
    )


def test_choices_are_exact():
    units = Spec('mV', 'unit of the outputs', choices=('mV', 'mV/V', 'microV/V'))
    assert check_value('input_units', units, 'mV/V') == 'mV/V'
    assert (
        refused('input_units', units, 'mv')
        == "parameter input_units must be one of mV, mV/V, microV/V (input_units = 'mv' given)"
    )


def test_lists():
    topics = Spec(['/a', '/b'], 'topics to record')
    assert topics.kind == STRING_ARRAY and check_value('topics', topics, ['/c']) == ['/c']
    assert (
        refused('topics', topics, '/c') == "parameter topics must be a list of strings, not '/c'"
    )
    assert 'list of strings' in refused('topics', topics, [1])
    no_default = Spec(STRING_ARRAY, 'bags that a refit fits')
    assert not no_default.has_default and check_value('bags', no_default, None) is None
    cg = Spec([0.0, 0.0, 0.0], 'a centre of gravity, m')
    assert cg.kind == DOUBLE_ARRAY
    held = check_value('model_cg_m', cg, [0, 1, 2.5])
    assert held == [0.0, 1.0, 2.5] and all(type(v) is float for v in held)
    assert check_value('model_cg_m', cg, array.array('d', [1.0])) == [1.0]  # as rclpy gives it
    assert 'finite numbers' in refused('model_cg_m', cg, [0.0, math.nan])
    assert 'finite numbers' in refused('model_cg_m', cg, ['x'])


# --- the check, on every entry of every node's table -------------------------------------------
WRONG_TYPE = {
    BOOL: 'yes',
    INTEGER: 'many',
    DOUBLE: 'fast',
    STRING: 5,
    STRING_ARRAY: 5,
    DOUBLE_ARRAY: 'x',
}


@pytest.mark.parametrize('node,name,spec', ENTRIES, ids=IDS)
def test_every_parameter_takes_its_default_and_refuses_the_wrong_type(node, name, spec):
    if spec.has_default:
        assert check_value(name, spec, spec.default) == spec.default
    refused(name, spec, WRONG_TYPE[spec.kind])
    if spec.kind in (INTEGER, DOUBLE):
        if spec.kind == DOUBLE:
            refused(name, spec, math.nan)
            refused(name, spec, math.inf)
        if spec.low is not None:
            below = (
                spec.low
                if spec.low_open
                else spec.low - (1 if spec.kind == INTEGER else max(abs(spec.low), 1.0) * 1e-9)
            )
            assert 'must be in' in refused(name, spec, below)
        if spec.high is not None:
            above = spec.high + (1 if spec.kind == INTEGER else max(abs(spec.high), 1.0) * 1e-9)
            assert 'must be in' in refused(name, spec, above)
    if spec.choices:
        assert 'must be one of' in refused(name, spec, spec.choices[0] + '_not')


def test_the_shipped_params_file_passes_every_nodes_check():
    """config/graph_params.yaml is what the graph starts with: no range may refuse it."""
    params = yaml.safe_load((ROOT / 'config' / 'graph_params.yaml').read_text())
    checked = 0
    for node, section in params.items():
        for name, value in section['ros__parameters'].items():
            check_value(name, TABLES[node][name], value)
            checked += 1
    assert checked > 40


# --- --help and docs/parameters.md ---------------------------------------------------------------
@pytest.mark.parametrize('node', TABLES)
def test_help_lists_every_entry_of_the_table(node):
    import importlib

    from balance_calib.nodes import _help

    module = importlib.import_module(f'balance_calib.nodes.{node}')
    lines = _help.help_text(module.__name__).splitlines()
    for name, spec in TABLES[node].items():
        head = [i for i, line in enumerate(lines) if line.startswith(f'  {name} = ')]
        assert len(head) == 1, (node, name)
        entry = lines[head[0]]
        assert entry.startswith(f'  {name} = {show_default(spec)}  ({spec.kind}'), entry
        assert entry.endswith(', read-only)') == spec.read_only, entry
        following = []
        for line in lines[head[0] + 1 :]:
            if not line.startswith(' ' * 6):
                break
            following.append(line.strip())
        assert ' '.join(following) == spec.description, (node, name)


def test_help_shows_range_and_choices():
    from balance_calib.nodes import _help

    lines = _help.parameter_lines('balance_calibrator')
    assert '  tare_samples = 100  (integer, [10, 1e+06])' in lines
    assert "  input_reliability = 'reliable'  (string, read-only)" in lines
    assert "  input_units = 'mV'  (string, one of mV, mV/V, microV/V)" in lines
    assert '  calibration_bags = (none: a string list)  (string_array)' in lines
    assert (
        "  mode = 'calibration'  (string, one of calibration, wind_on, replay, thrust_stand, "
        'read-only)' in _help.parameter_lines('bridge_publisher')
    )


def test_docs_table_is_what_the_tables_generate():
    committed = (ROOT / 'docs' / 'parameters.md').read_text(encoding='utf-8')
    assert committed == node_parameters.markdown(), (
        f'docs/parameters.md is out of date: run `{node_parameters.REGENERATE}`'
    )


def test_docs_table_has_a_row_for_every_entry():
    text = node_parameters.markdown()
    for node, name, spec in ENTRIES:
        section = text.split(f'\n## {node}\n', 1)[1].split('\n## ', 1)[0]
        rows = [line for line in section.splitlines() if line.startswith(f'| `{name}` |')]
        assert len(rows) == 1, (node, name)
        cells = [cell.strip() for cell in re.split(r'(?<!\\)\|', rows[0])[1:-1]]
        assert cells[1] == spec.kind and cells[4] == ('yes' if spec.read_only else ''), rows[0]
        assert cells[5].replace('\\|', '|') == spec.description
