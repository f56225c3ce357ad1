"""Terms the load schedule cannot determine are dropped and listed, never an error unless nothing
is left: a 3-component cell loaded one axis at a time with deadweights,
the screening worked by hand, and `fit` with defaults on `export-table`'s output.
"""

import json

import numpy as np
import pytest
import table_cases as tc

from balance_calib.cli import main
from balance_calib.fit.determinable import screen_terms
from balance_calib.model.terms import parse_terms
from balance_calib.tables.balfit_writer import write_table
from balance_calib.tables.calibrate import calibrate_table, TableCalibrationError


def test_screening_by_hand_hierarchy_zero_columns_and_points():
    # two loads never applied together, both only positive: |A| = A, A*B = 0 and |A|*B needs |A|
    a = np.r_[np.linspace(0.2, 1, 5), np.zeros(5)]
    b = np.r_[np.zeros(5), np.linspace(0.2, 1, 5)]
    terms = parse_terms(['A', 'B', '|A|', 'A^2', 'B^2', 'A*B', '|A|*B'])
    columns = np.column_stack([a, b, np.abs(a), a**2, b**2, a * b, np.abs(a) * b])
    series = np.column_stack([np.r_[np.ones(5), np.zeros(5)], np.r_[np.zeros(5), np.ones(5)]])
    screen = screen_terms(terms, columns, series, min_dof=2)
    assert [t.name for t in screen.kept] == ['A', 'B', 'A^2', 'B^2']
    reasons = dict(screen.dropped)
    assert set(reasons) == {'|A|', 'A*B', '|A|*B'}
    assert 'cannot separate' in reasons['|A|'] and 'never applies' in reasons['A*B']
    assert 'hierarchy' in reasons['|A|*B'] and '|A|' in reasons['|A|*B']
    # 10 points, 2 tares, 5 residual degrees of freedom asked: room for 3 terms, the square of B
    # goes
    screen = screen_terms(terms, columns, series, min_dof=5)
    assert [t.name for t in screen.kept] == ['A', 'B', 'A^2']
    assert 'room for 3 terms' in dict(screen.dropped)['B^2']


def test_three_component_cell_fits_with_defaults_and_lists_the_interactions(tmp_path, capsys):
    table, _ = tc.three_component_cell(np.random.default_rng(11))
    path = write_table(tmp_path / 'cell.csv', table)
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 0
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert (tmp_path / 'out' / 'calibration.yaml').is_file()
    assert not any('*' in t for t in report['terms'])
    for method, dropped in report['terms_dropped'].items():
        names = {d['term'] for d in dropped}
        products = (
            {'rFX*rFY', 'rFX*rFZ', 'rFY*rFZ'}
            if method == 'direct'
            else {'FX*FY', 'FX*FZ', 'FY*FZ'}
        )
        assert products <= names, method
        assert all(d['why'] for d in dropped)
    # every explicit combination fits too (the issue: all but a hand-written linear file failed)
    for method in ('direct', 'iterative'):
        for terms in ('tm663-cubic', 'r091-96'):
            assert calibrate_table(
                table, method=method, terms=terms, statistics=False, force=True
            ).calibration


def test_too_few_points_and_nothing_determinable_say_so_in_one_line(tmp_path):
    table, _ = tc.three_component_cell(np.random.default_rng(12), steps=2)
    # 6 points, 3 tares: one coefficient of room at most, never "does not excite 0 term(s)"
    with pytest.raises(TableCalibrationError) as err:
        calibrate_table(table, method='direct')
    message = str(err.value)
    assert '0 term' not in message and 'cell3' in message and 'none of the' in message
    assert len(message.splitlines()) == 1


def test_export_table_fitted_with_defaults_equals_the_refit_cubic(tmp_path, capsys, campaigns):
    from balance_calib.calibrate.from_bags import RefitSettings, run_refit
    from balance_calib.calibration_file import load_calibration
    from balance_calib.config import load_balance_config

    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=29, recipe='bag')
    cubic = run_refit(
        [bag], 'lmc6522', tmp_path / 'refit', RefitSettings(diagnose=False, plots=False)
    ).calibration.models['cubic']
    table_path = tmp_path / 'campaign.csv'
    assert main(['export-table', str(bag), '--balance', 'lmc6522', '--out', str(table_path)]) == 0
    assert main(['fit', str(table_path), '--out', str(tmp_path / 'fit'), '--no-plots']) == 0
    calibration = load_calibration(tmp_path / 'fit' / 'calibration.yaml')
    report = json.loads((tmp_path / 'fit' / 'report.json').read_text())
    model = calibration.model()
    assert report['method'] == 'direct'
    from balance_calib.tables.balfit_reader import read_table

    outputs = read_table(table_path).bridge_outputs
    tare = (
        np.array([report['series_tares']['1'][s] for s in report['load_symbols']])
        * read_table(table_path).load_factor
    )
    # the loads of every point agree with the refit's cubic to numerical noise
    np.testing.assert_allclose(
        model.loads(outputs) - tare, cubic.loads(outputs), atol=1e-9 * config.capacity.max()
    )
