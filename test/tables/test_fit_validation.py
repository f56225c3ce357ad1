"""Honest validation of table calibrations: validation series the calibration
lacks get their own tares with the model held fixed; loads beyond the calibrated range or in a
sign never calibrated, and a coverage of ±1.96 u below 90 %, are warned; the console line shows
in-sample, cross-validated and validation σ.
"""

import json

import numpy as np
import table_cases as tc

from balance_calib.cli import main
from balance_calib.tables.balfit_writer import write_table


def _campaign(tmp_path, seed, **validation):
    """A 3-component cell (4 orientations per axis: 12 series of 6 points) and a validation run
    in other orientations (series 21-...), both from one physical cell (same random structure).
    """
    cal, _, cal_tares = tc.three_component_cell(
        np.random.default_rng(seed), series_per_axis=4, steps=6, knee=0.0, return_tares=True
    )
    val, _, val_tares = tc.three_component_cell(
        np.random.default_rng(seed),
        series_per_axis=4,
        steps=6,
        knee=0.0,
        first_series=21,
        return_tares=True,
        **validation,
    )
    return (
        write_table(tmp_path / 'cal.csv', cal),
        write_table(tmp_path / 'val.csv', val),
        val_tares,
        cal_tares,
    )


def _fit(tmp_path, capsys, cal, val):
    out = tmp_path / 'out'
    assert main(['fit', str(cal), '--validate', str(val), '--out', str(out), '--no-plots']) == 0, (
        capsys.readouterr().err
    )
    return json.loads((out / 'report.json').read_text()), capsys.readouterr().out


def test_other_setups_get_their_own_tares_within_their_standard_errors(tmp_path, capsys):
    cal, val, val_tares, _ = _campaign(tmp_path, 41, span=(0.3, 0.9))
    report, out = _fit(tmp_path, capsys, cal, val)
    own = report['validation_series_tares']
    sigma = report['validation_series_tares_sigma']
    assert set(own) == {str(s) for s in val_tares}
    # the cell and its tares are the same in both runs (same seed): tare = truth within 4 standard
    # errors plus what the model's own error adds (its cross-validated σ)
    for s, truth in val_tares.items():
        for k, symbol in enumerate(('FX', 'FY', 'FZ')):
            capacity = report['capacities'][symbol]
            allowed = (
                4 * sigma[str(s)][symbol]
                + 3 * report['sigma_pct_capacity']['crossval'][symbol] * capacity / 100
            )
            assert abs(own[str(s)][symbol] - truth[k]) <= allowed, (s, symbol)
    assert any('not in the calibration' in w for w in report['warnings'])
    assert not any('extrapolation' in w for w in report['warnings'])
    validation = report['sigma_pct_capacity']['validation']
    assert all(v < 3 * report['sigma_pct_capacity']['crossval'][s] for s, v in validation.items())
    line = next(line for line in out.splitlines() if line.startswith('σ % capacity'))
    assert 'in-sample' in line and 'cross-validated' in line and 'validation' in line


def test_loads_beyond_the_calibrated_range_are_warned(tmp_path, capsys):
    cal, val, *_ = _campaign(tmp_path, 42, span=(0.4, 2.0), sign=-1.0)
    report, _ = _fit(tmp_path, capsys, cal, val)
    warnings = ' | '.join(report['warnings'])
    # series_per_axis=4 alternates the sign: the calibration has both signs up to 100 %
    for symbol in ('FX', 'FY', 'FZ'):
        assert f'validation loads {symbol} positive to 2.00x' in warnings
        assert f'validation loads {symbol} negative to 2.00x' in warnings
    coverage = report['methods_compared'][report['method']]['validation_coverage_1.96u']
    assert coverage >= 0.9 and 'within ±1.96 u' not in warnings  # the cell extrapolates well


def test_a_coverage_below_ninety_percent_is_warned(tmp_path, capsys):
    # the validation run read through a DAQ five times noisier than the calibration's
    cal, val, *_ = _campaign(tmp_path, 44, span=(0.3, 0.9), noise_mvv=1e-3)
    report, _ = _fit(tmp_path, capsys, cal, val)
    coverage = report['methods_compared'][report['method']]['validation_coverage_1.96u']
    warnings = ' | '.join(report['warnings'])
    assert coverage < 0.9 and '% of the validation loads lie within ±1.96 u' in warnings


def test_a_sign_never_calibrated_is_named(tmp_path, capsys):
    # the calibration: positive loads only (series_per_axis=1); validation: negative
    cal, _, _ = tc.three_component_cell(
        np.random.default_rng(43), series_per_axis=1, steps=6, knee=0.0, return_tares=True
    )
    val, _, _ = tc.three_component_cell(
        np.random.default_rng(43),
        series_per_axis=1,
        steps=6,
        knee=0.0,
        sign=-1.0,
        first_series=7,
        return_tares=True,
    )
    report, _ = _fit(
        tmp_path,
        capsys,
        write_table(tmp_path / 'cal.csv', cal),
        write_table(tmp_path / 'val.csv', val),
    )
    warnings = ' | '.join(report['warnings'])
    for symbol in ('FX', 'FY', 'FZ'):
        assert f'validation applies {symbol} negative' in warnings and 'never applied' in warnings
