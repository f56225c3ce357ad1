"""Acceptance gates of `fit`: every bad table is refused with exit 2, one
line naming the gate and nothing written; --force writes it anyway and report.json says so.
"""

from dataclasses import replace
import json

import numpy as np
import pytest
import table_cases as tc

from balance_calib.cli import main
from balance_calib.gates.fit_quality import condition_gate, overfit_gate
from balance_calib.tables.balfit_writer import write_table


def _balance(seed=7):
    return tc.six_component_balance(np.random.default_rng(seed))[0]


def _without_column(table, k):
    keep = [i for i in range(len(table.output_symbols)) if i != k]
    return replace(
        table,
        output_symbols=tuple(table.output_symbols[i] for i in keep),
        output_units=tuple(table.output_units[i] for i in keep),
        output_capacity=table.output_capacity[keep],
        zero_outputs=table.zero_outputs[:, keep],
        outputs=table.outputs[:, keep],
    )


def _constant_column(table, k):
    outputs = table.outputs.copy()
    outputs[:, k] = 0.0123
    return replace(table, outputs=outputs)


def _typo(table):
    applied = table.applied_loads.copy()
    i = int(np.argmax(applied[:, 2]))  # the largest FZ: 1200 N written as 1080 N
    applied[i, 2] *= 0.9
    return replace(table, applied_loads=applied), table.point_id[i]


def _kgf_as_newtons(table):
    return replace(table, applied_loads=table.applied_loads / 9.80665)


def _refused(tmp_path, capsys, table, *extra):
    path = write_table(tmp_path / 'bad.csv', table)
    out = tmp_path / 'out'
    code = main(['fit', str(path), '--out', str(out), '--no-plots', *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and 'bad.csv' in err, err
    assert not out.exists()
    return err


def test_a_good_table_passes_every_gate(tmp_path, capsys):
    path = write_table(tmp_path / 'good.csv', _balance())
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 0
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    names = [g['name'] for g in report['gates']]
    assert names == ['channels', 'sensitivity', 'outliers', 'overfit', 'condition']
    assert all(g['passed'] and g['reason'] for g in report['gates']) and report['forced'] is False


@pytest.mark.parametrize(
    'case, gate, words',
    [
        ('deleted', 'channels', 'missing'),
        ('constant', 'channels', 'rMZ constant'),
        ('typo', 'outliers', None),
        ('kgf', 'sensitivity', 'rated output'),
    ],
)
def test_bad_tables_are_refused_and_forced_ones_say_so(tmp_path, capsys, case, gate, words):
    table = _balance()
    point = None
    if case == 'deleted':
        bad = _without_column(table, 5)
    elif case == 'constant':
        bad = _constant_column(table, 5)
    elif case == 'typo':
        bad, point = _typo(table)
        words = point
    else:
        bad = _kgf_as_newtons(table)
    err = _refused(tmp_path, capsys, bad)
    assert f'acceptance gate {gate}' in err and words in err, err
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'bad.csv'),
                '--out',
                str(tmp_path / 'forced'),
                '--no-plots',
                '--force',
                '--method',
                'direct',
            ]
        )
        == 0
    )
    report = json.loads((tmp_path / 'forced' / 'report.json').read_text())
    entry = {g['name']: g for g in report['gates']}[gate]
    assert report['forced'] is True and entry['passed'] is False and entry['reason']
    assert 'written with --force' in capsys.readouterr().err
    if point is not None:
        assert entry['points'][0]['point_id'] == point and entry['points'][0]['component'] == 'FZ'


def test_fifty_term_model_on_sixty_poses_is_refused_as_overfit(tmp_path, capsys):
    table, _ = tc.eight_channel_sensor(np.random.default_rng(3))
    err = _refused(tmp_path, capsys, table, '--method', 'direct', '--terms', 'tm663-cubic')
    assert 'acceptance gate overfit' in err and 'cross-validated' in err


def test_overfit_and_condition_limits_by_hand():
    # 20 points, 10 coefficients: an honest model's ratio is about 20 / 10 = 2, the limit 2 x 2
    assert overfit_gate({'F': 1.0}, {'F': 3.9}, 20, 10, 'm').passed
    assert not overfit_gate({'F': 1.0}, {'F': 4.1}, 20, 10, 'm').passed
    assert condition_gate(1e7, 'm').passed and not condition_gate(1e9, 'm').passed


def test_overfit_gate_judges_the_ratio_only_above_round_off():
    from balance_calib.gates.fit_quality import OVERFIT_FLOOR_PCT, overfit_gate

    # a noise-free table: both σ round to 0 % capacity; the ratio of round-offs is no overfit
    zero = {'FX': 0.0, 'FY': 0.0}
    assert overfit_gate(zero, zero, 516, 117, 'iterative model').passed
    # 60 points, 47 coefficients: honest ratio about 60/13 = 4.6, limit 9.2; 20 % against 0.5 %
    gate = overfit_gate({'FX': 0.5, 'FY': 0.4}, {'FX': 20.0, 'FY': 0.9}, 60, 47, 'direct model')
    assert not gate.passed and 'FX 20 %' in gate.reason and 'FY' not in gate.reason.split(':')[1]
    # just above the floor the ratio counts again
    tiny = {'FX': OVERFIT_FLOOR_PCT / 100}
    assert not overfit_gate(tiny, {'FX': 2 * OVERFIT_FLOOR_PCT}, 60, 47, 'direct model').passed
