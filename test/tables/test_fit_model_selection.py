"""`fit --method auto --terms auto` chooses form and terms by what the data support:
truth tables written out here (a loads-from-outputs polynomial with |x| terms, an
outputs-from-loads R-091 polynomial) must get their generating form and term set and validate
within 1.05x the floor the injected noise sets; an 8-channel sensor on 60 poses must not get a
model that cross-validates worse than the linear one.
"""

import json

import numpy as np
import pytest
import table_cases as tc

from balance_calib.cli import main
from balance_calib.tables.balfit_writer import write_table

LOADS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
UNITS = ('N', 'N', 'N', 'N-m', 'N-m', 'N-m')
CAPACITY = np.array([400.0, 300.0, 1200.0, 60.0, 90.0, 50.0])
RATED = np.array([2.0, 1.5, 2.5, 1.8, 2.2, 1.6])  # mV/V at capacity


def _pair(tmp_path, rng, make, single, pair, v_single, v_pair):
    """Calibration and validation tables of one campaign: the same series, the same tares."""
    fractions, series = tc.support_fractions(rng, single, pair)
    tare = {s: rng.uniform(-0.03, 0.03, 6) for s in np.unique(series)}
    v_fractions, v_series = tc.support_fractions(rng, v_single, v_pair)
    tables = []
    for name, f, s in (('cal', fractions, series), ('val', v_fractions, v_series)):
        applied, raw = make(f, np.array([tare[k] for k in s]))
        tables.append(
            write_table(
                tmp_path / f'{name}.csv',
                tc.table(
                    'truth',
                    LOADS,
                    ('r1', 'r2', 'r3', 'r4', 'r5', 'r6'),
                    UNITS,
                    ('mV/V',) * 6,
                    CAPACITY,
                    applied,
                    raw,
                    s,
                    output_capacity=RATED,
                ),
            )
        )
    return tables


def _fit(tmp_path, capsys, *tables):
    out = tmp_path / 'fit'
    assert (
        main(
            ['fit', str(tables[0]), '--validate', str(tables[1]), '--out', str(out), '--no-plots']
        )
        == 0
    ), capsys.readouterr().err
    return json.loads((out / 'report.json').read_text())


@pytest.mark.slow
def test_loads_from_outputs_with_abs_terms_auto_picks_direct_96_at_the_noise_floor(
    tmp_path, capsys
):
    rng = np.random.default_rng(2020)
    noise = 1e-4  # 0.01 % of capacity on every load
    mixing = np.eye(6) + rng.uniform(-0.02, 0.02, (6, 6))
    features = tc.r091_features(np.zeros((1, 6))).shape[1]
    weights = rng.uniform(-0.004, 0.004, (6, features))  # each non-linear shape up to 0.4 %
    linear = [6 * k for k in range(6)]  # the u columns of r091_features
    weights[:, linear] = np.linalg.inv(mixing)

    seen = []

    def make(fractions, tare):
        u = (fractions + tare) @ mixing.T  # outputs / rated
        seen.append(u)
        total = (tc.r091_features(u) @ weights.T) * CAPACITY
        applied = total - tare * CAPACITY + rng.normal(0, noise, u.shape) * CAPACITY
        return applied, u * RATED

    tables = _pair(tmp_path, rng, make, 21, 150, 15, 200)
    report = _fit(tmp_path, capsys, *tables)
    assert (report['method'], report['term_set']) == ('direct', 'r091-96'), report['method_choice']
    validation = np.array([report['sigma_pct_capacity']['validation'][s] for s in LOADS])
    # the floor: the load noise, and what the generating model's coefficients and tares, estimated
    # by least squares from the calibration points, add at the validation points: σ² (1 + h), h =
    # z (ZᵀZ)⁻¹ zᵀ with Z, z the true terms (written out in table_cases) and each point's series
    from balance_calib.tables.balfit_reader import read_table

    cal, val = (read_table(t) for t in tables)
    labels = np.unique(cal.series)
    design = [
        np.hstack([tc.r091_features(u), -(t.series[:, None] == labels[None, :]).astype(float)])
        for u, t in zip(seen, (cal, val))
    ]
    h = np.einsum('ij,jk,ik->i', design[1], np.linalg.pinv(design[0].T @ design[0]), design[1])
    floor = noise * 100 * np.sqrt(1 + np.mean(h))
    assert np.all(validation <= 1.05 * floor) and np.all(validation >= 0.95 * floor), (
        validation / floor
    )
    compared = {(c['method'], c['term_set']) for c in report['model_selection']['candidates']}
    assert compared == {
        (m, t)
        for m in ('direct', 'iterative')
        for t in ('linear', 'tm663-quadratic', 'tm663-cubic', 'r091-96')
    }


@pytest.mark.slow
def test_outputs_from_loads_r091_auto_picks_iterative_96_at_the_noise_floor(tmp_path, capsys):
    rng = np.random.default_rng(2021)
    noise = 2e-4  # of the rated output, on every bridge
    mixing = np.eye(6) + rng.uniform(-0.02, 0.02, (6, 6))
    features = tc.r091_features(np.zeros((1, 6))).shape[1]
    weights = rng.uniform(-0.004, 0.004, (6, features))
    weights[:, [6 * k for k in range(6)]] = mixing

    def response(x):
        return tc.r091_features(x) @ weights.T  # outputs / rated from loads / capacity

    def make(fractions, tare):
        raw = response(fractions + tare) + rng.normal(0, noise, fractions.shape)
        return fractions * CAPACITY, raw * RATED

    tables = _pair(tmp_path, rng, make, 21, 150, 11, 40)
    report = _fit(tmp_path, capsys, *tables)
    assert (report['method'], report['term_set']) == ('iterative', 'r091-96'), report[
        'method_choice'
    ]
    # the floor: output noise through the inverse of the true response (central differences at
    # each validation point's total load), RMS over the validation points
    from balance_calib.tables.balfit_reader import read_table

    val = read_table(tables[1])
    tares = {
        int(s): np.array([report['series_tares'][s][k] for k in LOADS])
        for s in report['series_tares']
    }
    x = (val.applied_loads + np.array([tares[int(s)] for s in val.series])) / CAPACITY
    step = 1e-6
    jac = np.stack(
        [
            (response(x + step * np.eye(6)[v]) - response(x - step * np.eye(6)[v])) / (2 * step)
            for v in range(6)
        ],
        axis=2,
    )  # (N, outputs, loads)
    inverse = np.linalg.inv(jac)
    floor = np.sqrt(np.mean(np.sum(inverse**2, axis=2), axis=0)) * noise * 100
    validation = np.array([report['sigma_pct_capacity']['validation'][s] for s in LOADS])
    assert np.all(validation <= 1.05 * floor) and np.all(validation >= 0.95 * floor), (
        validation / floor
    )


def test_eight_channel_sensor_never_gets_a_model_worse_than_linear(tmp_path, capsys):
    table, _ = tc.eight_channel_sensor(np.random.default_rng(3))
    path = write_table(tmp_path / 'sensor.csv', table)
    assert main(['fit', str(path), '--out', str(tmp_path / 'out'), '--no-plots']) == 0, (
        capsys.readouterr().err
    )
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert report['method'] == 'direct' and 'outputs and loads differ' in report['method_choice']
    linear = next(c for c in report['model_selection']['candidates'] if c['term_set'] == 'linear')
    adopted = report['sigma_pct_capacity']['crossval']
    assert all(adopted[s] <= linear['crossval'][s] for s in table.load_symbols)
    assert {g['name']: g['passed'] for g in report['gates']}['overfit']
    assert report['sigma_pct_capacity']['crossval'] == report['sigma_pct_fs_crossval']['after']
