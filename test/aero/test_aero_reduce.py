"""`balance-calib reduce` over wind-on bags (interfaces.md, "Wind-tunnel data reduction"): held
attitudes found and averaged, coefficients.csv column for column, the compared models, report and
figures, and one clear line on bad input. Bags written from the simulated run (LMC6522, memo cubic
matrix as truth).
"""

import csv

from aero_cases import CALIBRATION, CONFIG, run_bag, simulated_run, START_NS
import numpy as np
import pytest

from balance_calib.aero.bag_io import write_run_bag
from balance_calib.cli import main
from balance_calib.tunnel_axes import INVERTED, UPRIGHT

COEFFICIENTS = ['CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn', 'CD', 'CL']


def read_csv(path):
    with open(path, newline='') as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array(rows[1:], dtype=float)


def truth_rows(profile):
    """True coefficients of each wind-on hold (constant within a hold in the simulation)."""
    holds = [
        c for c in np.unique(profile.condition) if profile.q_pa[profile.condition == c][0] > 0
    ]
    first = np.array([np.flatnonzero(profile.condition == c)[0] for c in holds])
    return np.column_stack(
        [profile.body_coefficients[first], profile.wind_coefficients[first][:, [0, 2]]]
    ), first


def test_reduce_writes_the_interface_columns_and_recovers_the_truth_through_the_true_model(
    tmp_path,
):
    profile = run_bag(tmp_path / 'run')
    out = tmp_path / 'out'
    assert (
        main(
            [
                'reduce',
                str(tmp_path / 'run'),
                '--calibration',
                'lmc6522',
                '--model',
                'euler_replica_lmc6522',
                '--out',
                str(out),
                '--compare',
                'linear,quadratic,cubic',
            ]
        )
        == 0
    )
    header, values = read_csv(out / 'coefficients.csv')
    # main group (adopted = cubic), then one group per other compared model, names suffixed
    assert header == ['alpha_deg', 'beta_deg', 'q_pa'] + COEFFICIENTS + [
        f'{c}_linear' for c in COEFFICIENTS
    ] + [f'{c}_quadratic' for c in COEFFICIENTS]
    truth, first = truth_rows(profile)
    assert len(values) == 13  # one row per held wind-on α; wind-off holds are not rows
    # deflection-corrected α
    assert np.allclose(values[:, 0], np.degrees(profile.attitude[first, 1]), atol=1e-10)
    assert np.allclose(values[:, 2], 50e3)
    # the cubic matrix is the balance's truth and there is no noise: exact
    assert np.max(np.abs(values[:, 3:11] - truth)) < 1e-9
    # the linear matrix departs in C_AF, most at high α (TM-663 §10.3, Fig. 12.1)
    linear_caf_error = np.abs(values[:, 11] - truth[:, 0])
    assert linear_caf_error[-1] > 1e-4 and linear_caf_error[-1] > 10 * linear_caf_error[0]
    figures = sorted(p.name for p in out.glob('*.png'))
    assert figures == sorted(f'coefficient_{c}.png' for c in COEFFICIENTS)
    report = (out / 'report.md').read_text()
    assert 'euler_replica_lmc6522' in report and 'q∞ 50000 … 50000 Pa' in report
    section = report.split('## Coefficients per α')[1].split('\n## ')[0]
    rows = [
        line
        for line in section.splitlines()
        if line.startswith('| ') and not line.startswith('| α')
    ]
    assert len(rows) == 13 and rows[-1].startswith(
        f'| {np.degrees(profile.attitude[first[-1], 1]):.3f} |'
    )


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_noisy_run_with_estimated_weight_is_within_its_propagated_uncertainty(
    tmp_path, installation
):
    # noise of a held point's mean load = the calibration's own σ (Table 17, cubic row), so the
    # error of each coefficient is N(0, u²) with u from that σ and the tare covariance; 4.5 u over
    # 104 values
    sigma = np.array([CALIBRATION.sigma_pct_fs[c] for c in CALIBRATION.components])
    profile, raw = simulated_run(noise_pct_fs=sigma, seed=11)
    if installation is INVERTED:  # the same loads on a balance mounted rolled 180° in the model
        from balance_calib.simulation.balance_sim import noise_mv_for_load_sigma
        from balance_calib.simulation.wind_on import wind_on_outputs

        truth_model = CONFIG.matrices['cubic']
        noise_mv = noise_mv_for_load_sigma(
            truth_model.without_constant(), CONFIG.capacity, sigma
        ) * np.sqrt(50)
        raw = wind_on_outputs(
            truth_model,
            INVERTED.from_tunnel(profile.loads_tunnel),
            electrical_zero_mv=0.0,
            noise_mv=noise_mv,
            seed=11,
        )
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(tmp_path / 'run', stamps, raw, profile.support_attitude, profile.q_pa)
    out = tmp_path / 'out'
    assert (
        main(
            [
                'reduce',
                str(tmp_path / 'run'),
                '--calibration',
                'lmc6522',
                '--model',
                'euler_replica_lmc6522',
                '--out',
                str(out),
                '--estimate-weight',
                '--installation',
                installation.name,
            ]
        )
        == 0
    )
    header, values = read_csv(out / 'coefficients.csv')
    from balance_calib.aero.pipeline import reduce_bags, ReduceOptions

    reduction = reduce_bags(
        [tmp_path / 'run'],
        'lmc6522',
        'euler_replica_lmc6522',
        ReduceOptions(estimate_weight=True, installation=installation.name),
    )
    u = np.array(
        [
            np.concatenate([p.uncertainty_body, p.uncertainty_wind[[0, 2]]])
            for p in reduction.main.result.wind_on
        ]
    )
    truth, _ = truth_rows(profile)
    ratio = np.abs(values[:, 3:11] - truth) / u
    assert np.max(ratio) < 4.5, ratio.max(axis=0)
    # u is the size of the error, not a loose bound
    assert np.mean(ratio**2) == pytest.approx(1.0, abs=0.5)
    assert reduction.main.result.tares[0].source == 'estimated'


def test_samples_without_a_current_attitude_or_q_are_left_out_and_counted(tmp_path):
    from balance_calib.aero.bag_io import read_run

    profile, raw = simulated_run()
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(tmp_path / 'run', stamps, raw, profile.support_attitude, profile.q_pa)
    samples = read_run([tmp_path / 'run'], max_input_age_s=0.5)
    assert samples.stale == 0 and len(samples.q_pa) == len(profile.q_pa)
    # q∞ NaN for 0.8 s: those samples are stale, never numbers
    q = profile.q_pa.copy()
    window = (profile.times_s > 8.9) & (profile.times_s < 9.7)
    q[window] = np.nan
    write_run_bag(tmp_path / 'nan_q', stamps, raw, profile.support_attitude, q)
    samples = read_run([tmp_path / 'nan_q'])
    assert samples.stale == int(window.sum()) > 0 and np.all(np.isfinite(samples.q_pa))
    # the attitude stream pauses for 0.8 s: samples more than 0.5 s after its last message are
    # stale
    keep = ~window
    from balance_calib.aero.bag_io import match_latest

    matched, ok = match_latest(stamps, stamps[keep], profile.support_attitude[keep], 0.5)
    late = (profile.times_s > 8.9 + 0.5) & window
    assert np.array_equal(~ok, late) and np.all(np.isnan(matched[late]))


def test_bad_inputs_give_one_line_and_write_nothing(tmp_path, capsys):
    profile, raw = simulated_run()
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    out = tmp_path / 'out'
    status = main(
        [
            'reduce',
            str(tmp_path / 'missing'),
            '--calibration',
            'lmc6522',
            '--model',
            'euler_replica',
            '--out',
            str(out),
        ]
    )
    error = capsys.readouterr().err.strip()
    assert status == 2 and '\n' not in error and 'missing' in error
    write_run_bag(tmp_path / 'run', stamps, raw, profile.support_attitude, profile.q_pa)
    for args, expected in (
        (['--model', 'no_such_model'], 'no_such_model: no such model file'),
        (['--model', 'euler_replica', '--compare', 'quartic'], "no 'quartic' model"),
        (['--model', 'euler_replica', '--installation', 'sideways'], "installation 'sideways'"),
    ):
        status = main(
            ['reduce', str(tmp_path / 'run'), '--calibration', 'lmc6522', '--out', str(out)] + args
        )
        error = capsys.readouterr().err.strip()
        assert status == 2 and '\n' not in error and expected in error, error
    assert not out.exists() or not any(out.iterdir())


def test_an_electrical_zero_is_taken_in_output_space_before_the_calibration(tmp_path):
    # 0.04 mV on every bridge with nothing on the balance: the load-space offsets of the wind-off
    # sweep absorb it only approximately for the cubic balance; given as --electrical-zero-mv it is
    # exact again
    from balance_calib.simulation.wind_on import wind_on_outputs

    profile, _ = simulated_run()
    raw = wind_on_outputs(CONFIG.matrices['cubic'], profile.loads_balance, electrical_zero_mv=0.04)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(tmp_path / 'run', stamps, raw, profile.support_attitude, profile.q_pa)
    truth, _ = truth_rows(profile)
    errors = {}
    for zero in ('', '0.04,0.04,0.04,0.04,0.04,0.04'):
        out = tmp_path / f'out{len(zero)}'
        assert (
            main(
                [
                    'reduce',
                    str(tmp_path / 'run'),
                    '--calibration',
                    'lmc6522',
                    '--model',
                    'euler_replica_lmc6522',
                    '--out',
                    str(out),
                    '--electrical-zero-mv',
                    zero,
                ]
            )
            == 0
        )
        errors[zero] = np.max(np.abs(read_csv(out / 'coefficients.csv')[1][:, 3:11] - truth))
    assert errors[''] > 1e-4 and errors['0.04,0.04,0.04,0.04,0.04,0.04'] < 1e-9
    assert (
        main(
            [
                'reduce',
                str(tmp_path / 'run'),
                '--calibration',
                'lmc6522',
                '--model',
                'euler_replica_lmc6522',
                '--out',
                str(tmp_path / 'bad'),
                '--electrical-zero-mv',
                '0.04,0.04',
            ]
        )
        == 2
    )


def _zeroed_run_bag(path, electrical_zero_mv, **truth):
    from balance_calib.simulation.wind_on import wind_on_outputs

    profile, _ = simulated_run()
    raw = wind_on_outputs(
        CONFIG.matrices['cubic'], profile.loads_balance, electrical_zero_mv=electrical_zero_mv
    )
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(path, stamps, raw, profile.support_attitude, profile.q_pa, **truth)
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


@pytest.mark.filterwarnings('error::RuntimeWarning')
def test_offsets_beyond_one_percent_of_capacity_are_a_console_and_report_warning(tmp_path, capsys):
    from balance_calib.model.inverse import linear_part

    _zeroed_run_bag(tmp_path / 'run', 0.04)
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    console = capsys.readouterr().out
    # 0.04 mV on every bridge through the calibration's linear part (N per mV) is ~ +313 N of the
    # balance's F_Z, -F_Z of the tunnel upright (§10.2.1); the wind-off sweep's offset takes it
    expected_fz = -(linear_part(CONFIG.matrices['cubic']) @ np.full(6, 0.04))[2]
    assert abs(expected_fz) / 9800 > 0.01
    warning = next(
        line
        for line in console.splitlines()
        if line.startswith('warning: cubic: wind-off offsets')
    )
    value = float(warning.split('F_Z ')[1].split(' N')[0])
    assert value == pytest.approx(expected_fz, rel=0.02)
    assert f'{100 * abs(value) / 9800:.1f} % of its rated load 9800 N' in warning
    assert '--electrical-zero-mv' in warning
    report = (tmp_path / 'out' / 'report.md').read_text()
    assert warning[len('warning: ') :] in report.split('## Warnings')[1]
    # the zero given: no offset beyond 1 %, no warning
    zero = ','.join(['0.04'] * 6)
    assert _reduce(tmp_path / 'run', tmp_path / 'zeroed', '--electrical-zero-mv', zero) == 0
    assert 'warning' not in capsys.readouterr().out
    assert '## Warnings\n\n- none' in (tmp_path / 'zeroed' / 'report.md').read_text()


@pytest.mark.filterwarnings('error::RuntimeWarning')
def test_an_electrical_zero_below_one_percent_of_capacity_is_no_warning(tmp_path, capsys):
    _zeroed_run_bag(tmp_path / 'run', 0.004)  # ~31 N on F_Z: 0.3 % of 9800 N
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    assert 'warning' not in capsys.readouterr().out


@pytest.mark.filterwarnings('error::RuntimeWarning')
def test_a_truth_without_its_wind_axis_part_says_so_instead_of_nan(tmp_path, capsys):
    profile, _ = simulated_run()  # deterministic: the profile the bag is written from
    _zeroed_run_bag(tmp_path / 'run', 0.0, truth_body=profile.body_coefficients)  # no truth_wind
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    capsys.readouterr()
    report = (tmp_path / 'out' / 'report.md').read_text()
    section = report.split('## Against the simulation')[1].split('\n## ')[0]
    row = next(line for line in section.splitlines() if line.startswith('| cubic |'))
    cells = [c.strip() for c in row.strip('|').split('|')][1:]
    assert cells[6:] == ['no truth', 'no truth'] and all(' u)' in c for c in cells[:6]), row
    assert 'nan' not in section.lower()
    assert 'C_D, C_L (the bag has no /aero/truth_wind)' in section


@pytest.mark.filterwarnings('error::RuntimeWarning')
def test_a_raw_sample_of_minus_1e300_is_left_out_and_said_not_spread_as_nan(tmp_path, capsys):
    profile, raw = simulated_run()  # noise-free: a hold's samples are equal
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(tmp_path / 'clean', stamps, raw, profile.support_attitude, profile.q_pa)
    flipped = raw.copy()
    flipped[500, 2] = -1e300  # a flipped exponent bit in one F_Z sample
    write_run_bag(tmp_path / 'run', stamps, flipped, profile.support_attitude, profile.q_pa)
    assert _reduce(tmp_path / 'clean', tmp_path / 'clean_out') == 0
    capsys.readouterr()
    assert _reduce(tmp_path / 'run', tmp_path / 'out') == 0
    console = capsys.readouterr().out
    assert (
        'warning: 1 raw sample(s) with a bridge output beyond 1000x its rated output left out '
        '(first: FZV -1e+300 mV)'
    ) in console
    _, values = read_csv(tmp_path / 'out' / 'coefficients.csv')
    _, clean = read_csv(tmp_path / 'clean_out' / 'coefficients.csv')
    assert np.all(np.isfinite(values)) and np.allclose(values, clean, rtol=0, atol=1e-9)
