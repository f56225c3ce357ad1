"""check and compare (interfaces.md, "Check loads, and comparing two calibrations") on a balance
whose F_X bridge became 1 % more sensitive, on a clean re-calibration, and on check loads beyond
the calibrated range.

The change is injected into the simulated bridge outputs (the F_X bridge's output x 1.01, after
the truth matrix of TM-663 Table 12 made them), not into any model the code fits. The expected
differences are derived by hand from the truth matrix: a calibration B fitted to the changed
balance reads outputs V as the truth reads (V_FX / 1.01, the rest), so to first order

    L_B(V) - L_A(V) = -C[:, FX] · V_FX · (1 - 1/1.01)

with C the truth's linear part and V_FX the F_X output of the load; on the F_X sweep of a check
table the F_X reading is off by +1 % of the F_X load.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.stats

from balance_calib.calibration_file import save_calibration
from balance_calib.calibration_settings import CalibrationSettings
from balance_calib.checks.check_loads import bag_readings, CheckReadings, judge, table_readings
from balance_calib.checks.compare import compare_calibrations
from balance_calib.model.inverse import linear_part, outputs_for_loads
from balance_calib.refit.pipeline import calibrate_points, campaign_points
from balance_calib.simulation.balance_sim import noise_mv_for_load_sigma, table17_noise
from balance_calib.tables.balfit_writer import write_table
from balance_calib.tables.export import corrected_table
from balance_calib.tare.calibration_body import tare_loads

GAIN = 1.01  # the F_X bridge's output after the change
CHECK_KEYS = {'points', 'k', 'verdict', 'worst_ratio', 'components', 'failed'}
COMPARE_KEYS = {'components', 'sensitivity_change_pct', 'changed'}


def changed(campaign, gain: float = GAIN):
    """The campaign with its F_X bridge's output (electrical zero and noise included) x gain."""
    raw = np.array(campaign.raw_mv)
    raw[:, 0] *= gain
    return dataclasses.replace(campaign, raw_mv=raw)


def _calibration(config, campaign):
    return calibrate_points(
        campaign_points(campaign), config, settings=CalibrationSettings(diagnose=False)
    ).calibration


@pytest.fixture(scope='module')
def calibrations(campaigns, lmc6522):
    """A (seed 0), a clean re-calibration (seed 1) and one of the changed balance (seed 2)."""
    return {
        'a': _calibration(lmc6522, campaigns.campaign(seed=0)),
        'clean': _calibration(lmc6522, campaigns.campaign(seed=1)),
        'changed': _calibration(lmc6522, changed(campaigns.campaign(seed=2))),
    }


def _cli(*args):
    return subprocess.run(
        [sys.executable, '-m', 'balance_calib.cli', *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
    )


def _schedule_total_loads(config):
    schedule = config.schedule
    gravity = np.array([config.gravity(i) for i in schedule.orientation])
    loads = schedule.loads + tare_loads(config.calibration_body, gravity)
    return loads[~schedule.is_zero_point]


def test_compare_finds_the_changed_bridge_by_the_amount_derived_by_hand(calibrations, lmc6522):
    truth = lmc6522.matrices['cubic'].without_constant()
    matrix = linear_part(truth)
    outputs = outputs_for_loads(truth, _schedule_total_loads(lmc6522))
    expected = -np.outer(outputs[:, 0] * (1.0 - 1.0 / GAIN), matrix[:, 0])
    expected_rms = np.sqrt(np.mean((expected / lmc6522.capacity * 100.0) ** 2, axis=0))
    assert expected_rms[0] == pytest.approx(0.40, abs=0.01)  # about 1 % of an RMS F_X load
    assert np.all(expected_rms[1:] < 2e-4)  # the F_X column's interactions are tiny

    summary = compare_calibrations(calibrations['a'], calibrations['changed']).summary()
    assert COMPARE_KEYS <= set(summary)
    assert summary['changed'] == ['FX']
    fx = summary['components']['FX']
    assert fx['changed'] is True
    # both fits' own noise adds in quadrature (RMS ~0.06 % FS between two clean fits)
    assert fx['rms_difference_pct_fs'] == pytest.approx(expected_rms[0], rel=0.06)
    assert fx['rms_difference_pct_fs'] > 2 * fx['combined_u_pct_fs']
    change = summary['sensitivity_change_pct']
    # S_B / S_A = 1.01; the zero-load slope of a cubic fit scatters ~0.1 % between seeds
    assert change['FXV'] == pytest.approx(100.0 * (GAIN - 1.0), abs=0.3)
    assert all(abs(change[v]) < 0.3 for v in ('FYV', 'FZV', 'MXV', 'MYV', 'MZV'))


def test_compare_finds_an_added_interaction_by_the_amount_derived_by_hand(
    calibrations, campaigns, lmc6522
):
    # F_Y gains 13 N per mV of the F_X bridge: B - A = 13 N/mV x V_FX at A's outputs
    interaction = 13.0
    b = _calibration(
        lmc6522, campaigns.campaign(seed=3, effects=f'cross_terms:FY.FXV={interaction}')
    )
    truth = lmc6522.matrices['cubic'].without_constant()
    outputs = outputs_for_loads(truth, _schedule_total_loads(lmc6522))
    expected = interaction * outputs[:, 0] / lmc6522.capacity[1] * 100.0
    summary = compare_calibrations(calibrations['a'], b).summary()
    assert summary['changed'] == ['FY']
    fy = summary['components']['FY']
    assert fy['rms_difference_pct_fs'] == pytest.approx(np.sqrt(np.mean(expected**2)), rel=0.06)
    assert fy['worst_difference_pct_fs'] == pytest.approx(
        expected[np.argmax(np.abs(expected))], abs=0.03
    )
    # an interaction is no change of a bridge's own sensitivity
    assert all(abs(v) < 0.3 for v in summary['sensitivity_change_pct'].values())


def test_compare_of_a_clean_recalibration_finds_nothing_changed(calibrations):
    summary = compare_calibrations(calibrations['a'], calibrations['clean']).summary()
    assert summary['changed'] == []
    for entry in summary['components'].values():
        assert entry['changed'] is False
        assert entry['rms_difference_pct_fs'] < 2 * entry['combined_u_pct_fs']
    assert all(abs(s) < 0.3 for s in summary['sensitivity_change_pct'].values())


def _bag_like(campaign):
    """The campaign's load points and each point's scatter (variance of its mean, mV²), as a
    bag's cut gives them.
    """
    return campaign_points(campaign), campaign.point_scatter()[0]


def test_check_on_the_changed_balance_fails_on_fx(calibrations, campaigns):
    points, scatter = _bag_like(changed(campaigns.campaign(seed=3, recipe='bag')))
    result = judge(bag_readings(calibrations['a'], points, scatter, 'changed balance'), 2.0)
    assert result.verdict == 'fail'
    failed = result.failed.sum(axis=0)
    n = result.failed.shape[0]
    # F_X fails wherever 1 % of its load exceeds 2u (loads beyond ~25 % FS), the others by chance
    big = np.abs(result.readings.applied[:, 0]) > 0.3 * result.readings.capacity[0]
    assert failed[0] >= 0.9 * big.sum()
    assert np.all(failed[1:] <= scipy.stats.binom.ppf(0.999, n, 0.0455))


@pytest.mark.parametrize('recipe', ['bag', 'memo'])
def test_check_of_a_clean_balance_fails_at_the_rate_chance_allows(calibrations, campaigns, recipe):
    # 'memo': one sample a point, so each point's own scatter comes from the zero points' repeats
    points, scatter = _bag_like(campaigns.campaign(seed=4, recipe=recipe))
    if recipe == 'memo':
        scatter = None
    result = judge(bag_readings(calibrations['a'], points, scatter, 'clean balance'), 2.0)
    n = result.failed.size
    # k = 2: P(|error| > 2u) = 4.55 % for a normal error with u its standard deviation; u is
    # the prediction's (a fresh point's noise included), so at most that rate, bounded at 99.9 %
    assert result.failed.sum() <= scipy.stats.binom.ppf(0.999, n, 0.0455)
    assert result.failed.sum() >= 1  # a u much too large would pass everything
    summary = result.summary()
    assert summary['outside_support'] == []


def _check_table(path, config, loads, outputs, series):
    """A BALFIT-style check table in N, N·m and mV, natural zeros 0."""
    shaped = dataclasses.make_dataclass('Points', ['loads', 'bridge_outputs_mv'])
    table = corrected_table(config, shaped(loads, outputs), name=str(path))
    table = dataclasses.replace(table, series=np.asarray(series, int))
    return write_table(path, table)


def _noisy_outputs(config, loads, gain: float, seed: int):
    truth = config.matrices['cubic'].without_constant()
    outputs = outputs_for_loads(truth, loads)
    noise = noise_mv_for_load_sigma(truth, config.capacity, table17_noise(config))
    outputs = outputs + np.random.default_rng(seed).normal(size=outputs.shape) * noise
    outputs[:, 0] *= gain
    return outputs


def _sweeps(config, fraction=1.0):
    """Series 1: F_X from -fraction to +fraction of rated; series 2: F_Z likewise; 11 points."""
    levels = np.linspace(-fraction, fraction, 11)
    loads = np.zeros((22, 6))
    loads[:11, 0] = levels * config.capacity[0]
    loads[11:, 2] = levels * config.capacity[2]
    return loads, np.repeat([1, 2], 11)


def test_check_table_of_the_changed_balance_exits_3_naming_fx(calibrations, lmc6522, tmp_path):
    calibration = tmp_path / 'a.yaml'
    save_calibration(calibration, calibrations['a'])
    loads, series = _sweeps(lmc6522)
    table = _check_table(
        tmp_path / 'check.csv', lmc6522, loads, _noisy_outputs(lmc6522, loads, GAIN, 5), series
    )
    done = _cli('check', calibration, table, '--out', tmp_path / 'out')
    assert done.returncode == 3, done.stderr
    failed_lines = [line for line in done.stdout.splitlines() if line.startswith('FAILED')]
    assert len(failed_lines) == 1 and failed_lines[0].startswith('FAILED FX: ')
    assert 'verdict: fail' in done.stdout
    summary = json.loads((tmp_path / 'out' / 'check.json').read_text())
    assert CHECK_KEYS <= set(summary) and summary['verdict'] == 'fail'
    # the record's file: report.json of check carries `record` (interfaces.md)
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert report == summary and report['record']['balance']
    # the F_X series' tare is its mean error, 0 for a symmetric sweep: the F_X reading is off by
    # 1 % of the F_X load (slope 1 % FS per FS; 11 points of σ 0.08 % FS give it to ±0.04)
    readings = table_readings(calibrations['a'], _read(table))
    fx = slice(0, 11)
    load_fs = readings.applied[fx, 0] / lmc6522.capacity[0]
    error_pct_fs = readings.error[fx, 0] / lmc6522.capacity[0] * 100.0
    assert np.polyfit(load_fs, error_pct_fs, 1)[0] == pytest.approx(100.0 * (GAIN - 1.0), abs=0.15)
    assert (tmp_path / 'out' / 'check.png').stat().st_size > 10_000
    text = (tmp_path / 'out' / 'check.md').read_text()
    assert text.startswith('# Check loads') and 'Approved by' in text.rstrip().splitlines()[-1]


def test_check_loads_beyond_the_calibrated_range_are_said(calibrations, lmc6522, tmp_path):
    loads, series = _sweeps(lmc6522, fraction=1.6)
    readings = table_readings(
        calibrations['a'],
        _read(
            _check_table(
                tmp_path / 'c.csv', lmc6522, loads, _noisy_outputs(lmc6522, loads, 1.0, 6), series
            )
        ),
    )
    beyond_fx = np.abs(loads[:, 0]) > 1.1 * lmc6522.capacity[0]
    assert beyond_fx.sum() == 4
    assert np.all(readings.outside[beyond_fx, 0])
    calibration = tmp_path / 'a.yaml'
    save_calibration(calibration, calibrations['a'])
    done = _cli('check', calibration, tmp_path / 'c.csv', '--out', tmp_path / 'out')
    assert done.returncode in (0, 3), done.stderr
    assert 'outside the calibrated range' in done.stdout
    summary = json.loads((tmp_path / 'out' / 'check.json').read_text())
    flagged = {o['point'] for o in summary['outside_support'] if 'FX' in o['components']}
    assert {f'P-{i + 1:04d}' for i in np.flatnonzero(beyond_fx)} <= flagged
    assert any('outside the calibrated range' in w for w in summary['warnings'])


def _read(path):
    from balance_calib.tables.balfit_reader import read_tables

    return read_tables([path])


def test_check_bag_of_the_changed_balance_exits_3(calibrations, campaigns, tmp_path):
    from balance_calib.simulation.campaign_bag import write_campaign_bag

    bag = write_campaign_bag(changed(campaigns.campaign(seed=7, recipe='bag')), tmp_path / 'bag')
    calibration = tmp_path / 'a.yaml'
    save_calibration(calibration, calibrations['a'])
    done = _cli('check', calibration, bag, '--out', tmp_path / 'out', '--operator', 'K. Sato')
    assert done.returncode == 3, done.stderr
    summary = json.loads((tmp_path / 'out' / 'check.json').read_text())
    assert summary['verdict'] == 'fail'
    fails = {c: e['failed'] for c, e in summary['components'].items()}
    assert fails['FX'] == max(fails.values()) and fails['FX'] > 100
    assert summary['points'] == int((~campaigns.campaign(seed=7).is_zero_point).sum())
    assert summary['record']['operator'] == 'K. Sato'


def test_compare_command_exit_codes_and_refusal(calibrations, tmp_path):
    paths = {}
    for name, calibration in calibrations.items():
        paths[name] = tmp_path / f'{name}.yaml'
        save_calibration(paths[name], calibration)
    done = _cli('compare', paths['a'], paths['clean'])
    assert done.returncode == 0, done.stderr
    assert 'verdict: unchanged' in done.stdout
    done = _cli('compare', paths['a'], paths['changed'], '--out', tmp_path / 'out')
    assert done.returncode == 3, done.stderr
    assert done.stdout.splitlines()[0].startswith('CHANGED FX:')
    summary = json.loads((tmp_path / 'out' / 'compare.json').read_text())
    assert COMPARE_KEYS <= set(summary) and summary['changed'] == ['FX']
    assert (tmp_path / 'out' / 'compare.png').exists()
    other = tmp_path / 'other.yaml'
    save_calibration(other, dataclasses.replace(calibrations['clean'], balance='B660H'))
    done = _cli('compare', paths['a'], other)
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and 'balance' in done.stderr


def _readings(error, u, outside=None) -> CheckReadings:
    error = np.asarray(error, float)
    return CheckReadings(
        'hand',
        tuple(f'P-{i:04d}' for i in range(len(error))),
        ('FX',),
        np.array([100.0]),
        np.zeros_like(error),
        error,
        np.asarray(u, float),
        np.zeros(error.shape, bool) if outside is None else outside,
        'hand',
        'cubic',
    )


def test_verdict_rules_of_the_contract():
    u = np.ones((40, 1))
    assert judge(_readings(np.full((40, 1), 1.99), u)).verdict == 'pass'
    # 2 of 40 = 5 % fail, each within 1.5·k·u: marginal; 3 of 40: fail
    two = np.zeros((40, 1))
    two[:2] = 2.9
    assert judge(_readings(two, u)).verdict == 'marginal'
    three = two.copy()
    three[2] = 2.9
    assert judge(_readings(three, u)).verdict == 'fail'
    # one beyond 1.5·k·u: fail
    far = np.zeros((40, 1))
    far[0] = 3.1
    assert judge(_readings(far, u)).verdict == 'fail'
    # a reading without an uncertainty is never passed silently
    unknown = np.ones((40, 1))
    unknown[5] = np.nan
    result = judge(_readings(np.zeros((40, 1)), unknown))
    assert result.failed[5, 0] and result.summary()['failed'][0]['limit_pct_fs'] is None
