"""What a laboratory signs and the odd component named with its points,
with a term of its own channel offered when it removes the structure.
"""

import json

import numpy as np
import pytest
import table_cases as tc

from balance_calib import __version__
from balance_calib.cli import main
from balance_calib.tables.balfit_writer import write_table


def test_report_carries_identification_residual_ids_coefficients_and_sensitivities(
    tmp_path, capsys
):
    table, _ = tc.six_component_balance(np.random.default_rng(5))
    path = write_table(tmp_path / 'b6.csv', table)
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 0
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    ident = report['identification']
    assert (ident['balance_name'], ident['description'], ident['package_version']) == (
        'balance6',
        'generated for the fit tests',
        __version__,
    )
    assert report['rated_loads']['FZ'] == {'capacity': 1200.0, 'unit': 'N'}
    for symbol, entry in report['largest_residual']['calibration'].items():
        i = table.point_id.index(entry['point_id'])
        assert (
            abs(entry['residual_pct_capacity'])
            >= report['sigma_pct_capacity']['calibration'][symbol]
        )
        assert int(table.series[i]) == entry['series']
    coefficients = report['coefficients']
    assert coefficients['terms'] == report['terms']
    assert all(se > 0 for row in coefficients['standard_errors'].values() for se in row)
    # the response at capacity of each load on its own bridge: rated x (1 + 0.002 + 0.0005
    # tanh(10)), the generator's square and knee at x = 1, within its 2 % cross-talk of the
    # diagonal
    per_load = coefficients and report['sensitivities']['per_load']
    rated = table.output_capacity
    for k, symbol in enumerate(table.load_symbols):
        assert abs(per_load[symbol][k] / rated[k] - 1.0025) < 0.025
    text = (tmp_path / 'out' / 'report.md').read_text()
    assert '## Identification' in text and '## Coefficients of the adopted' in text
    assert '## Acceptance gates' in text and '## Models compared' in text
    headline = next(line for line in text.splitlines() if line.startswith('**σ % capacity'))
    assert 'in-sample' in headline and 'cross-validated' in headline


@pytest.mark.parametrize('series_per_axis, offered', [(1, False), (3, True)])
def test_a_knee_at_low_load_fits_and_names_the_component_and_its_first_steps(
    tmp_path, capsys, series_per_axis, offered
):
    # a lab's cell: one axis at a time, a series of 5 deadweight steps from 0 % per fixture
    # orientation (3 or 9 series, a tare each); FZ's bridge has a tanh knee of 2 % of rated
    # output near zero, a shape no term set holds. Loaded in one sign only (3 series) no term of
    # FZ's own channel can tell the knee from the line: unexplained. In both signs (orientations
    # alternate) x|x| of its bridge, odd like the knee, takes most of it: offered, not adopted
    table, _ = tc.three_component_cell(
        np.random.default_rng(11), series_per_axis=series_per_axis, steps=5, span=(0.0, 1.0)
    )
    path = write_table(tmp_path / 'cell.csv', table)
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 0, (
        capsys.readouterr().err
    )
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    # the interactions (never applied together) are dropped and listed with their reason
    for method, dropped in report['terms_dropped'].items():
        listed = {d['term'] for d in dropped}
        products = (
            {'rFX*rFY', 'rFX*rFZ', 'rFY*rFZ'}
            if method == 'direct'
            else {'FX*FY', 'FX*FZ', 'FY*FZ'}
        )
        assert products <= listed and all(d['why'] for d in dropped), method
    assert not any('*' in t for t in report['terms'])
    # never a model that cross-validates worse than the form's linear one on any load
    linear = next(
        c
        for c in report['model_selection']['candidates']
        if c['method'] == report['method'] and c['term_set'] == 'linear'
    )
    assert all(
        v <= linear['crossval'][s] for s, v in report['sigma_pct_capacity']['crossval'].items()
    )
    # FZ's points are no outliers: the gate passes (whatever points of FZ stand out alike there
    # it calls structure, and no other load's)
    gate = {g['name']: g for g in report['gates']}['outliers']
    assert gate['passed'] and set(gate['structure']) <= {'FZ'}
    assert not gate['structure'] or 'structure' in gate['reason']
    named = report['effects'] + report['unexplained']
    assert [e['components'] for e in named] == [['FZ']]
    entry = named[0]
    fz_series = {int(s) for s, row in zip(table.series, table.applied_loads) if row[2] != 0}
    # the points named are FZ's: its low-load steps (step 1 or 2 of a FZ series)
    assert all(int(p.split('-')[0][1:]) in fz_series for p in entry['points'][:3])
    assert any(p.endswith('-1') or p.endswith('-2') for p in entry['points'][:3])
    assert bool(report['effects']) is offered
    if offered:
        effect = report['effects'][0]
        assert effect['sigma_after_pct_fs']['FZ'] <= 0.9 * effect['sigma_before_pct_fs']['FZ']
        assert effect['terms'] == ['rFZ*|rFZ|'] and effect['name'] == 'bidirectional'
        assert effect['terms'][0] not in report['terms'] and effect['adopted'] is False
        assert (
            effect['sigma_before_pct_fs']['FZ'] == report['sigma_pct_capacity']['crossval']['FZ']
        )
    else:
        assert 'no square' in entry['evidence'] and entry['tracks']


def test_a_typed_load_is_still_an_outlier_on_the_cell(tmp_path, capsys):
    # the same cell without the knee, one deadweight written 10 % light: refused, that point named
    from dataclasses import replace

    table, _ = tc.three_component_cell(
        np.random.default_rng(11), series_per_axis=3, steps=5, knee=0.0
    )
    applied = table.applied_loads.copy()
    i = int(np.argmax(applied[:, 1]))
    applied[i, 1] *= 0.9
    path = write_table(tmp_path / 'cell.csv', replace(table, applied_loads=applied))
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 2
    err = capsys.readouterr().err
    assert 'acceptance gate outliers' in err and f'point {table.point_id[i]}' in err, err
    assert not (tmp_path / 'out').exists()


def test_clean_tables_name_no_component():
    from balance_calib.tables.calibrate import calibrate_table

    for seed in (3, 7):
        report = calibrate_table(tc.six_component_balance(np.random.default_rng(seed))[0]).report
        assert report['effects'] == [] and report['unexplained'] == []
