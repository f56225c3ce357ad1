"""`reduce` corrects the zero drifting during a run (interfaces.md, "Check loads, and comparing two
calibrations", the zero-drift paragraph): the wind-off offsets interpolated linearly in time
between the wind-off sweeps before and after the wind-on part; `--zero-drift none` keeps the
pre-run ones; report.md gives the shift per component in % FS and warns beyond 2σ.

The simulated run (aero_cases: LMC6522 with the memo's cubic matrix as truth, the Euler replica at
250 N) has the same 12-attitude wind-off sweep before and after its α sweep.
"""

from aero_cases import CALIBRATION, CONFIG, MODEL, readings, simulated_run, START_NS
import numpy as np
import pytest

from balance_calib.aero.bag_io import write_run_bag
from balance_calib.aero.held_points import HoldSettings
from balance_calib.aero.run import sigma_loads_tunnel
from balance_calib.aero.zero_drift import reduce_run_with_drift
from balance_calib.cli import main
from balance_calib.model.inverse import linear_part
from balance_calib.tunnel_axes import UPRIGHT

SIGMA_PCT_FS = np.array([CALIBRATION.sigma_pct_fs[c] for c in CALIBRATION.components])


def body_coefficients(result) -> np.ndarray:
    return np.array([p.reduced.body for p in result.wind_on])


def test_an_axial_force_drift_is_interpolated_away_and_none_leaves_it_as_derived_by_hand():
    # a zero creeping by 2 N/s on the axial force F_X (tunnel axes), nothing else: C_AF = F_X/(q S)
    # alone carries it (the moment transfer about x_r and the deflection do not see F_X)
    profile, raw = simulated_run()
    clean = readings(raw)
    times = profile.times_s
    rate_n_per_s = 2.0
    drifting = clean.copy()
    drifting[:, 0] += rate_n_per_s * times
    sigma = sigma_loads_tunnel(SIGMA_PCT_FS, CALIBRATION.capacity, UPRIGHT)
    args = (profile.support_attitude, profile.q_pa, times, MODEL, HoldSettings(), sigma)
    truth, _ = reduce_run_with_drift(clean, *args, mode='none')
    linear, drift = reduce_run_with_drift(drifting, *args, mode='linear')
    kept, drift_none = reduce_run_with_drift(drifting, *args, mode='none')

    # the sweeps' mean times: 12 holds of 50 samples at 100 Hz each side of 13 wind-on holds
    wind_off = profile.q_pa == 0
    first_on, last_on = np.flatnonzero(~wind_off)[[0, -1]]
    pre_s = times[:first_on].mean() - times[0]
    post_s = times[last_on + 1 :].mean() - times[0]
    assert drift.pre_s == pytest.approx(pre_s, abs=1e-12)
    assert drift.post_s == pytest.approx(post_s, abs=1e-12)
    assert drift.shift == pytest.approx([rate_n_per_s * (post_s - pre_s), 0, 0, 0, 0, 0], abs=1e-9)
    assert drift_none.shift == pytest.approx(drift.shift, abs=1e-9)
    assert drift.corrected and not drift_none.corrected

    # linear: the drift gone entirely (noise-free run)
    assert np.max(np.abs(body_coefficients(linear) - body_coefficients(truth))) < 1e-12
    # none: the pre-run offset is the zero at the pre-run sweep's mean time, so a point at t_i is
    # off by rate (t_i - t_pre) / (q S) in C_AF and nowhere else
    point_s = (
        np.array([times[p.first_sample : p.first_sample + p.samples].mean() for p in kept.wind_on])
        - times[0]
    )
    q = np.array([p.q_pa for p in kept.wind_on])
    expected = rate_n_per_s * (point_s - pre_s) / (q * MODEL.reference_area_m2)
    error = body_coefficients(kept) - body_coefficients(truth)
    assert error[:, 0] == pytest.approx(expected, rel=1e-9)
    assert np.max(expected) > 5e-3  # a drift that matters: ~ 15 u of C_AF at the last point
    assert np.max(np.abs(error[:, 1:])) < 1e-12


def _bag(path, *, noise_pct_fs, seed, drift_mv_per_s=0.0, keep=None):
    """A run bag with a zero drifting linearly in time on every bridge output (mV/s)."""
    profile, raw = simulated_run(noise_pct_fs=noise_pct_fs, seed=seed)
    raw = raw + drift_mv_per_s * (profile.times_s - profile.times_s[0])[:, None]
    keep = np.ones(len(raw), bool) if keep is None else keep(profile)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(
        path,
        stamps[keep],
        raw[keep],
        profile.support_attitude[keep],
        profile.q_pa[keep],
        truth_body=profile.body_coefficients[keep],
        truth_wind=profile.wind_coefficients[keep],
    )
    return profile


def _reduce(bag, out, *extra):
    return main(
        [
            'reduce',
            str(bag),
            '--calibration',
            'lmc6522',
            '--model',
            'euler_replica_lmc6522',
            '--out',
            str(out),
            *extra,
        ]
    )


def _errors_in_u(bag, zero_drift):
    from balance_calib.aero.pipeline import reduce_bags, ReduceOptions
    from balance_calib.aero.report import point_uncertainties, point_values, truth_by_point

    reduction = reduce_bags(
        [bag], 'lmc6522', 'euler_replica_lmc6522', ReduceOptions(zero_drift=zero_drift)
    )
    points = reduction.main.result.wind_on
    values = np.array([point_values(p) for p in points])
    u = np.array([point_uncertainties(p) for p in points])
    return np.abs(values - truth_by_point(reduction)) / u, reduction


def test_a_drift_in_the_bridge_outputs_is_corrected_to_the_noise_and_warned(tmp_path, capsys):
    # every bridge's zero creeps by 1 µV/s (12.5 µV over the 12.5 s between the sweeps); a held
    # point's noise is the calibration's own σ, so an error within ~4 u is the noise
    rate_mv_per_s = 1e-3
    profile = _bag(
        tmp_path / 'run', noise_pct_fs=SIGMA_PCT_FS, seed=5, drift_mv_per_s=rate_mv_per_s
    )
    linear_ratio, reduction = _errors_in_u(tmp_path / 'run', 'linear')
    none_ratio, _ = _errors_in_u(tmp_path / 'run', 'none')
    assert np.max(linear_ratio) < 4.5, linear_ratio.max(axis=0)
    assert np.mean(linear_ratio**2) == pytest.approx(1.0, abs=0.6)
    assert np.max(none_ratio) > 10, none_ratio.max(axis=0)  # the drift shows without it

    # by hand: with the model's weight alone on it, the balance reads a zero shift through the
    # matrix's linear part (N or N·m per mV), the balance's axes; % FS of its capacity
    drift = reduction.main.zero_drift
    shift_mv = np.full(6, rate_mv_per_s * (drift.post_s - drift.pre_s))
    expected_pct = 100 * (linear_part(CONFIG.matrices['cubic']) @ shift_mv) / CONFIG.capacity
    shift_pct = reduction.main.zero_shift_pct_fs
    with capsys.disabled():  # the figures docs/guide/reduce-windon.md quotes (pytest -s)
        print(f'\nshift % FS {np.round(shift_pct, 4)}, by hand {np.round(expected_pct, 4)}')
        print(f'largest error/u: linear {linear_ratio.max():.2f}, none {none_ratio.max():.2f}')
    assert np.all(
        np.abs(shift_pct - expected_pct)
        <= 3 * SIGMA_PCT_FS * np.sqrt(2 / 12) + 0.03 * np.abs(expected_pct)
    )
    beyond = np.abs(expected_pct) > 3 * SIGMA_PCT_FS  # clearly beyond 2σ whatever the noise
    assert beyond.sum() >= 3

    capsys.readouterr()
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    console = capsys.readouterr().out
    assert 'zero drift (cubic): shift post − pre % FS' in console
    warning = next(line for line in console.splitlines() if 'the zero drifted' in line)
    for component in np.array(CALIBRATION.components)[beyond]:
        assert f' {component} ' in warning
    assert 'interpolated linearly in time' in warning
    report = (tmp_path / 'out' / 'report.md').read_text()
    section = report.split('## Zero drift during the run')[1].split('## Warnings')[0]
    assert 'interpolated linearly in time' in section
    for component, value in zip(CALIBRATION.components, shift_pct):
        assert f'{component} {value:+.4f}' in section
    assert warning[len('warning: ') :] in report.split('## Warnings')[1]
    del profile


def test_a_run_without_drift_gives_a_shift_within_the_noise_and_no_warning(tmp_path, capsys):
    _bag(tmp_path / 'run', noise_pct_fs=SIGMA_PCT_FS, seed=8)
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    console = capsys.readouterr().out
    assert 'warning' not in console
    _, reduction = _errors_in_u(tmp_path / 'run', 'linear')
    drift = reduction.main.zero_drift
    # the shift of two 12-hold means with the point noise σ: σ √(2/12) per component (in load
    # space the fit weighs the holds alike); within 4 of those, and below the 2σ warning
    shift_pct = reduction.main.zero_shift_pct_fs
    assert np.all(np.abs(shift_pct) < 4 * SIGMA_PCT_FS * np.sqrt(2 / 12)), shift_pct
    assert drift.sigma is not None


def test_a_run_without_a_post_run_hold_is_reduced_as_before_and_says_so(tmp_path, capsys):
    def before_the_post_run_sweep(profile):
        last_on = np.flatnonzero(profile.q_pa > 0)[-1]
        return np.arange(len(profile.q_pa)) <= last_on

    _bag(
        tmp_path / 'run',
        noise_pct_fs=0.0,
        seed=0,
        drift_mv_per_s=3e-4,
        keep=before_the_post_run_sweep,
    )
    assert _reduce(tmp_path / 'run', tmp_path / 'linear') == 0
    console = capsys.readouterr().out
    assert (
        'zero drift: not corrected: the run has no wind-off hold after its wind-on part' in console
    )
    assert 'warning' not in console
    assert _reduce(tmp_path / 'run', tmp_path / 'none', '--zero-drift', 'none') == 0
    capsys.readouterr()
    linear_csv = (tmp_path / 'linear' / 'coefficients.csv').read_text()
    assert linear_csv == (tmp_path / 'none' / 'coefficients.csv').read_text()
    report = (tmp_path / 'linear' / 'report.md').read_text()
    assert (
        'cubic: the drift of the zero was not corrected: the run has no wind-off hold after'
        in (report.split('## Zero drift during the run')[1])
    )


def test_an_unknown_zero_drift_mode_is_one_line(tmp_path, capsys):
    _bag(tmp_path / 'run', noise_pct_fs=0.0, seed=0)
    with pytest.raises(SystemExit) as exit_info:
        _reduce(tmp_path / 'run', tmp_path / 'out', '--zero-drift', 'quadratic')
    assert exit_info.value.code == 2
    assert "--zero-drift: invalid choice: 'quadratic'" in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()
