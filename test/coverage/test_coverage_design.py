"""Coverage of a run and design of calibration points (interfaces.md "Coverage of a run,
and design of calibration points"): the predicted u is honest on simulated campaigns with a
known truth, a designed schedule reads a sting-mounted model's loads to 0.03 % FS, the commands
refuse bad input with one line, and a campaign runs and refits on a designed schedule.
"""

import json
from pathlib import Path
import re

import numpy as np
import pytest
from sting_envelope import envelope

from balance_calib.calibration_file import load_calibration
from balance_calib.calibration_settings import CalibrationSettings
from balance_calib.cli import main
from balance_calib.config import ConfigError, load_balance_config
from balance_calib.coverage.design import (
    design_points,
    rig_loading,
    schedule_total_loads,
    schedule_with,
)
from balance_calib.coverage.run import run_coverage
from balance_calib.coverage.support import outside_support, ScheduleSupport
from balance_calib.live.stream import wrench_uncertainty
from balance_calib.model.active_calibration import activate
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.refit.pipeline import calibrate_points, campaign_points
from balance_calib.schedule_file import read_schedule_csv, schedule_csv_text
from balance_calib.simulation.balance_sim import (
    noise_mv_for_load_sigma,
    simulate_campaign,
    SimulationSettings,
    table17_noise,
)

LMC = load_balance_config('lmc6522')
DATA = Path(__file__).resolve().parents[3] / 'shared' / 'data'
ISSUE_SIGMA_PCT_FS = 0.025  # the contract's "clean campaign": its calibration quotes 0.025 % FS


def refit(schedule, seed, noise, config=LMC):
    campaign = simulate_campaign(
        config, schedule=schedule, settings=SimulationSettings(seed=seed, noise_sigma_pct_fs=noise)
    )
    return calibrate_points(
        campaign_points(campaign), config, settings=CalibrationSettings(diagnose=False)
    ).calibration


def write_loads(path, loads):
    np.savetxt(path, loads, delimiter=',', header='FX,FY,FZ,MX,MY,MZ', comments='')
    return path


# --- schedules as files -------------------------------------------------------------------------
def test_a_schedule_written_as_csv_reads_back_as_the_same_schedule(tmp_path):
    path = tmp_path / 'schedule.csv'
    path.write_text(schedule_csv_text(LMC.schedule))
    again = read_schedule_csv(path)
    np.testing.assert_array_equal(again.point, LMC.schedule.point)
    np.testing.assert_array_equal(again.orientation, LMC.schedule.orientation)
    np.testing.assert_allclose(again.loads, LMC.schedule.loads, rtol=1e-9, atol=1e-9)
    assert again.byproduct == LMC.schedule.byproduct


def test_the_memo_schedule_csv_reads_as_the_config_schedule():
    path = DATA / 'lmc6522_schedule.csv'  # the memo's sheet, rows without a number skipped
    if not path.exists():
        pytest.skip('the shared data directory is not beside this checkout')
    schedule = read_schedule_csv(path)
    np.testing.assert_array_equal(schedule.point, LMC.schedule.point)
    np.testing.assert_array_equal(schedule.orientation, LMC.schedule.orientation)
    np.testing.assert_allclose(schedule.loads, LMC.schedule.loads, rtol=1e-12)
    assert schedule.byproduct == LMC.schedule.byproduct


@pytest.mark.parametrize(
    'row, message',
    [
        ('3,1,2,x,0,0,0,0,0,', 'row 2: column FX_kgf'),
        ('3,1,9,0,0,0,0,0,0,', 'row 2: I_g = 9'),
        ('1,1,2,1,0,0,0,0,0,', 'point number(s) 1 appear more than once'),
        ('3,1,2,nan,0,0,0,0,0,', 'row 2: loads must be finite'),
    ],
)
def test_a_bad_schedule_row_is_named(tmp_path, row, message):
    path = tmp_path / 's.csv'
    path.write_text(
        'point,executed,Ig,FX_kgf,FY_kgf,FZ_kgf,MX_kgfm,MY_kgfm,MZ_kgfm,paren_cols\n'
        '1,1,2,0,0,0,0,0,0,\n' + row + '\n'
    )
    with pytest.raises(ConfigError, match=re.escape(message)):
        read_schedule_csv(path)


# --- support ------------------------------------------------------------------------------------
def test_support_flags_a_component_beyond_its_range_and_every_component_beyond_the_leverage():
    support = ScheduleSupport(
        ('A', 'B'),
        np.array([10.0, 10.0]),
        np.array([-5.0, -10.0]),
        np.array([5.0, 10.0]),
        0.5,
        'cubic',
    )
    loads = np.array(
        [
            [5.1, 0.0],  # within 2 % FS of the range: inside
            [5.3, 0.0],  # A beyond its range: only A outside
            [0.0, 0.0],
        ]
    )  # in range, but leverage 0.6 > 1.1 x 0.5: both outside
    outside = outside_support(support, loads, np.array([0.1, 0.54, 0.6]))
    assert outside.tolist() == [[False, False], [True, False], [True, True]]
    assert outside_support(support, loads[:1], np.array([np.nan])).all()  # unknown is not inside


# --- the predicted u --------------------------------------------------------------------------
def test_coverage_u_is_the_live_nodes_wrench_uncertainty_at_the_same_outputs():
    calibration = refit(None, 3, table17_noise(LMC))
    loads = envelope(LMC.capacity, 50, 5)
    coverage = run_coverage(calibration, loads)
    active = activate(calibration)
    outputs = outputs_for_loads(active.model, loads)  # the wind-on model the node applies
    live = wrench_uncertainty(active, outputs, None)  # tunnel axes, magnitudes
    np.testing.assert_allclose(
        active.installation.to_tunnel(coverage.uncertainty),
        live * np.sign(active.installation.to_tunnel(np.ones(6))),
        rtol=1e-9,
    )
    np.testing.assert_allclose(coverage.loads, loads)


@pytest.mark.parametrize('designed', [False, True], ids=['memo schedule', 'designed schedule'])
@pytest.mark.parametrize('balance', ['lmc6522', 'b660h'])
def test_predicted_u_is_honest_at_envelope_loads(balance, designed, capsys):
    """RMS error (truth load vs the calibration's reading of the truth outputs + reading noise) at
    held-out envelope loads, over seeds, is 0.5-2x the RMS predicted u of each component.
    """
    config = load_balance_config(balance)
    capacity = config.capacity
    noise = table17_noise(config)
    truth = config.matrices['cubic'].without_constant()
    held = envelope(capacity, 300, 2)
    true_outputs = outputs_for_loads(truth, held)
    reading_noise_mv = noise_mv_for_load_sigma(truth, capacity, noise)
    schedule = design_points(config, envelope(capacity, 400, 1), 12).schedule if designed else None
    errors, predicted = [], []
    for seed in range(10):
        calibration = refit(schedule, 100 + seed, noise, config)
        rng = np.random.default_rng(seed)
        read = activate(calibration).model.loads(
            true_outputs + rng.normal(size=true_outputs.shape) * reading_noise_mv
        )
        errors.append(read - held)
        predicted.append(run_coverage(calibration, held).uncertainty)
    rms_error = np.sqrt(np.mean(np.concatenate(errors) ** 2, axis=0)) / capacity * 100
    rms_u = np.sqrt(np.mean(np.concatenate(predicted) ** 2, axis=0)) / capacity * 100
    with capsys.disabled():
        print(
            f'\n{config.name}, {"designed" if designed else "memo"} schedule, % FS: RMS error '
            f'{np.round(rms_error, 4)}, RMS predicted u {np.round(rms_u, 4)}, ratio '
            f'{np.round(rms_error / rms_u, 2)}'
        )
    assert np.all(rms_error / rms_u > 0.5) and np.all(rms_error / rms_u < 2.0)


# --- the design ---------------------------------------------------------------------------------
def worst_read_error(calibration, held, true_outputs):
    """Largest |reading of the true outputs - truth| over held-out loads and components, % FS."""
    read = activate(calibration).model.loads(true_outputs)
    return float(np.max(np.abs(read - held) / LMC.capacity * 100))


def test_a_designed_schedule_reads_held_out_tunnel_loads_within_0_03_pct_fs(capsys):
    """The clean campaign (σ 0.025 % FS): the memo schedule misses the sting envelope by
    ~0.4 % FS worst; 12 designed points bring it within 0.03 % FS on the median over seeds, and the
    design beats 12 random envelope loads on that median.
    """
    design_envelope = envelope(LMC.capacity, 400, 1)
    held = envelope(LMC.capacity, 300, 2)
    true_outputs = outputs_for_loads(LMC.matrices['cubic'].without_constant(), held)
    design = design_points(LMC, design_envelope, 12)
    added = design.summary()['added']
    assert added <= 12
    feasible = rig_loading(LMC, design_envelope)[0]
    rows = {'memo schedule': [], f'designed (+{added})': [], f'random (+{added})': []}
    for seed in range(6):
        rng = np.random.default_rng(1000 + seed)
        picks = design_envelope[rng.choice(np.flatnonzero(feasible), added, replace=False)]
        for label, schedule in zip(rows, (None, design.schedule, schedule_with(LMC, picks))):
            calibration = refit(schedule, seed, ISSUE_SIGMA_PCT_FS)
            rows[label].append(worst_read_error(calibration, held, true_outputs))
    median = {label: float(np.median(v)) for label, v in rows.items()}
    with capsys.disabled():
        print(
            '\nworst |error| at 300 held-out sting loads, % FS, 6 seeds (σ 0.025 % FS campaigns):'
        )
        for label, values in rows.items():
            print(
                f'  {label:16s} median {median[label]:.4f}  '
                + ' '.join(f'{v:.4f}' for v in values)
            )
        # for the record, not asserted: Table 17's own noise (FX 0.08 % FS, the others 0.02-0.04)
        for label, schedule in (('memo, Table 17', None), ('designed, T. 17', design.schedule)):
            values = [
                worst_read_error(refit(schedule, seed, table17_noise(LMC)), held, true_outputs)
                for seed in range(6)
            ]
            print(
                f'  {label:16s} median {np.median(values):.4f}  '
                + ' '.join(f'{v:.4f}' for v in values)
            )
    memo, designed, random = median.values()
    assert memo > 0.2  # the problem the issue measured (0.42 % FS)
    assert designed <= 0.03
    assert designed < random


def test_the_design_keeps_the_schedule_and_brackets_added_blocks_with_zero_points():
    design = design_points(LMC, envelope(LMC.capacity, 200, 4), 9)
    schedule, base = design.schedule, LMC.schedule
    n = len(base)
    np.testing.assert_array_equal(schedule.point[:n], base.point)
    np.testing.assert_array_equal(schedule.loads[:n], base.loads)
    added = slice(n, None)
    zero = np.all(schedule.loads[added] == 0.0, axis=1)
    assert 1 <= int((~zero).sum()) <= 9
    assert zero[0] and zero[-1]
    orientation = schedule.orientation[added]
    for start in np.flatnonzero(zero)[::2]:  # blocks: zero, loads of one I_g, zero
        end = start + 1 + np.flatnonzero(zero[start + 1 :])[0]
        assert len(set(orientation[start : end + 1])) == 1
    total = schedule_total_loads(LMC, schedule)[added][~zero]
    assert np.all(np.abs(schedule.loads[added]) <= LMC.capacity)
    assert np.all(np.abs(total) <= LMC.capacity)
    summary = design.summary()
    predicted = summary['predicted_u_pct_fs']
    assert all(predicted['after'][c] < predicted['before'][c] for c in LMC.components)


# --- the commands -------------------------------------------------------------------------------
def test_design_and_coverage_commands_write_the_interface_files(tmp_path, capsys):
    env = write_loads(tmp_path / 'env.csv', envelope(LMC.capacity, 200, 1))
    assert (
        main(
            [
                'design',
                '--balance',
                'lmc6522',
                '--envelope',
                str(env),
                '--points',
                '8',
                '--out',
                str(tmp_path / 'd'),
            ]
        )
        == 0
    )
    summary = json.loads((tmp_path / 'd' / 'design.json').read_text())
    assert set(summary) == {'added', 'predicted_u_pct_fs', 'worst_component'}
    assert set(summary['predicted_u_pct_fs']) == {'before', 'after'}
    assert set(summary['predicted_u_pct_fs']['after']) == set(LMC.components)
    header = (tmp_path / 'd' / 'schedule.csv').read_text().splitlines()[0]
    assert header.startswith('point,executed,Ig,FX_kgf,FY_kgf,FZ_kgf,MX_kgfm,MY_kgfm,MZ_kgfm')
    schedule = read_schedule_csv(tmp_path / 'd' / 'schedule.csv')
    assert len(schedule) > len(LMC.schedule)

    # the campaign on it: simulate --schedule writes the bag, refit --schedule fits it
    schedule_file = str(tmp_path / 'd' / 'schedule.csv')
    assert (
        main(
            [
                'simulate',
                '--balance',
                'lmc6522',
                '--schedule',
                schedule_file,
                '--no-diagnosis',
                '--bag',
                str(tmp_path / 'bag'),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                'refit',
                str(tmp_path / 'bag'),
                '--balance',
                'lmc6522',
                '--schedule',
                schedule_file,
                '--no-diagnosis',
                '--out',
                str(tmp_path / 'r'),
            ]
        )
        == 0
    )
    report = json.loads((tmp_path / 'r' / 'report.json').read_text())
    assert report['points'] == len(schedule)
    calibration = load_calibration(tmp_path / 'r' / 'calibration.yaml')
    assert 'support' in calibration.extra

    # design for that calibration (its base model and σ); one of another balance is refused
    assert (
        main(
            [
                'design',
                '--balance',
                'lmc6522',
                '--envelope',
                str(env),
                '--points',
                '3',
                '--calibration',
                str(tmp_path / 'r' / 'calibration.yaml'),
                '--out',
                str(tmp_path / 'd2'),
            ]
        )
        == 0
    )
    again = json.loads((tmp_path / 'd2' / 'design.json').read_text())['predicted_u_pct_fs']
    sigma = calibration.sigma_pct_fs
    assert all(sigma[c] < again['after'][c] < again['before'][c] for c in LMC.components)
    capsys.readouterr()
    assert (
        main(
            [
                'design',
                '--balance',
                'b660h',
                '--envelope',
                str(env),
                '--points',
                '3',
                '--calibration',
                str(tmp_path / 'r' / 'calibration.yaml'),
                '--out',
                str(tmp_path / 'd3'),
            ]
        )
        == 2
    )
    assert 'a calibration of LMC6522, not of B660H' in capsys.readouterr().err

    assert (
        main(
            [
                'coverage',
                str(tmp_path / 'r' / 'calibration.yaml'),
                str(env),
                '--out',
                str(tmp_path / 'c'),
            ]
        )
        == 0
    )
    coverage = json.loads((tmp_path / 'c' / 'coverage.json').read_text())
    for key in (
        'points',
        'predicted_u_pct_fs',
        'worst_u_pct_fs',
        'outside_support_fraction',
        'sigma_pct_fs',
    ):
        assert key in coverage
    assert coverage['points'] == 200
    assert set(coverage['predicted_u_pct_fs']) == set(LMC.components)
    assert (tmp_path / 'c' / 'coverage.png').stat().st_size > 10_000
    assert 'outside support' in capsys.readouterr().out


def test_coverage_of_a_memo_campaign_says_the_tunnel_run_is_outside_its_support(tmp_path):
    calibration = refit(None, 4, table17_noise(LMC))
    coverage = run_coverage(calibration, envelope(LMC.capacity, 200, 1)).summary()
    schedule_points = run_coverage(calibration, schedule_total_loads(LMC, LMC.schedule)).summary()
    for c in LMC.components:
        assert coverage['outside_support_fraction'][c] > 0.5
        assert schedule_points['outside_support_fraction'][c] == 0.0
        assert coverage['predicted_u_pct_fs'][c] > 2 * coverage['sigma_pct_fs'][c]


def test_coverage_reads_the_wrenches_of_a_bag_in_tunnel_axes(tmp_path, capsys):
    from balance_calib.bags.messages import RELIABLE_QOS, wrench_cdr
    from balance_calib.bags.writer import BagWriter, qos_profiles_yaml
    from balance_calib.tunnel_axes import parse_installation

    calibration = refit(None, 5, table17_noise(LMC))
    path = tmp_path / 'cal.yaml'
    from balance_calib.calibration_file import save_calibration

    save_calibration(path, calibration)
    loads = envelope(LMC.capacity, 40, 6)
    tunnel = parse_installation('upright').to_tunnel(loads)
    with BagWriter(tmp_path / 'run') as writer:
        writer.add_topic(
            '/balance/wrench', 'geometry_msgs/msg/WrenchStamped', qos_profiles_yaml(RELIABLE_QOS)
        )
        for i, values in enumerate(tunnel):
            ns = 1_700_000_000 * 10**9 + i * 10**7
            writer.write('/balance/wrench', ns, wrench_cdr(ns, 'tunnel', values))
    assert main(['coverage', str(path), str(tmp_path / 'run'), '--out', str(tmp_path / 'b')]) == 0
    assert (
        main(
            [
                'coverage',
                str(path),
                str(write_loads(tmp_path / 'l.csv', loads)),
                '--out',
                str(tmp_path / 'c'),
            ]
        )
        == 0
    )
    from_bag = json.loads((tmp_path / 'b' / 'coverage.json').read_text())
    from_csv = json.loads((tmp_path / 'c' / 'coverage.json').read_text())
    assert from_bag['points'] == 40
    for c in LMC.components:
        assert from_bag['predicted_u_pct_fs'][c] == pytest.approx(
            from_csv['predicted_u_pct_fs'][c], rel=1e-6
        )


@pytest.mark.parametrize(
    'case', ['beyond capacity', 'header only', 'empty file', 'no points', 'negative points']
)
def test_design_refuses_with_one_line_and_writes_nothing(tmp_path, capsys, case):
    loads = envelope(LMC.capacity, 20, 1)
    points = {'no points': '0', 'negative points': '-3'}.get(case, '4')
    env = tmp_path / 'env.csv'
    if case == 'beyond capacity':
        loads[7, 2] = 1.2 * LMC.capacity[2]
        write_loads(env, loads)
    elif case == 'header only':
        env.write_text('FX,FY,FZ,MX,MY,MZ\n')
    elif case == 'empty file':
        env.write_text('')
    else:
        write_loads(env, loads)
    status = main(
        [
            'design',
            '--balance',
            'lmc6522',
            '--envelope',
            str(env),
            '--points',
            points,
            '--out',
            str(tmp_path / 'd'),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert len(err.splitlines()) == 1 and 'Traceback' not in err
    expected = {
        'beyond capacity': 'row 8: FZ',
        'header only': 'no loads',
        'empty file': 'no loads',
        'no points': 'at least 1',
        'negative points': 'at least 1',
    }[case]
    assert expected in err
    assert not (tmp_path / 'd' / 'schedule.csv').exists()


def test_coverage_of_a_bag_without_wrenches_reads_its_raw_outputs_and_says_so(tmp_path, capsys):
    from balance_calib.simulation.campaign_bag import write_campaign_bag
    from balance_calib.simulation.timeline import select_points

    calibration_path = tmp_path / 'cal.yaml'
    from balance_calib.calibration_file import save_calibration

    save_calibration(calibration_path, refit(None, 6, table17_noise(LMC)))
    campaign = simulate_campaign(LMC, schedule=select_points(LMC.schedule, '1-14'))
    write_campaign_bag(campaign, tmp_path / 'bag')
    status = main(['coverage', str(calibration_path), str(tmp_path / 'bag')])
    captured = capsys.readouterr()
    err = captured.err.strip()
    # a run recorded without a calibrator (launchless_scripts/windon): its /balance/raw, said
    assert status == 0 and len(err.splitlines()) == 1
    assert 'no /balance/wrench' in err and '/balance/raw' in err
    # the 14 points' samples, each read through the calibration
    assert f'{len(campaign.raw_mv)} loads' in captured.out


def test_coverage_refuses_a_calibration_without_covariance(tmp_path, capsys):
    env = write_loads(tmp_path / 'env.csv', envelope(LMC.capacity, 5, 1))
    assert main(['coverage', 'lmc6522', str(env)]) == 2  # the memo's matrices: no covariance
    assert 'covariance' in capsys.readouterr().err


def test_reduce_report_carries_the_coverage_of_its_run(tmp_path):
    from aero_cases import run_bag

    from balance_calib.calibration_file import save_calibration

    run_bag(tmp_path / 'run')
    save_calibration(tmp_path / 'cal.yaml', refit(None, 7, table17_noise(LMC)))
    out = tmp_path / 'out'
    assert (
        main(
            [
                'reduce',
                str(tmp_path / 'run'),
                '--calibration',
                str(tmp_path / 'cal.yaml'),
                '--model',
                'euler_replica_lmc6522',
                '--out',
                str(out),
            ]
        )
        == 0
    )
    section = (out / 'report.md').read_text().split('## Coverage of this run')[1].split('\n## ')[0]
    from balance_calib.aero.bag_io import read_run

    samples = read_run([tmp_path / 'run'])
    calibration = load_calibration(tmp_path / 'cal.yaml')
    expected = run_coverage(calibration, outputs_mv=samples.raw_mv).summary()
    assert f'{len(samples.raw_mv)} loads, model cubic' in section
    assert f'{expected["predicted_u_pct_fs"]["FZ"]:.4f}' in section.split('predicted u RMS')[1]
    assert (out / 'coverage.png').exists()
    # the memo's matrices have no covariance: the section says so instead of a number
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
                str(tmp_path / 'memo'),
            ]
        )
        == 0
    )
    assert 'carries no coefficient covariance' in (tmp_path / 'memo' / 'report.md').read_text()


def test_simulate_and_refit_refuse_a_bad_schedule_with_one_line(tmp_path, capsys):
    bad = tmp_path / 'schedule.csv'
    bad.write_text(
        'point,executed,Ig,FX_kgf,FY_kgf,FZ_kgf,MX_kgfm,MY_kgfm,MZ_kgfm,paren_cols\n'
        '1,1,2,0,0,0,0,0,0,\n2,1,2,150,0,0,0,0,0,\n'
    )  # 150 kgf: beyond 980 N
    cases = [
        (['simulate', '--schedule', str(bad)], 'exactly one --balance'),
        (
            ['simulate', '--balance', 'lmc6522', '--schedule', str(bad)],
            f'{bad}: point 2: FX 1471 beyond the capacity 980',
        ),
        (
            [
                'refit',
                str(tmp_path / 'no-bag'),
                '--balance',
                'lmc6522',
                '--schedule',
                str(bad),
                '--out',
                str(tmp_path / 'r'),
            ],
            f'{bad}: point 2: FX',
        ),
    ]
    for argv, expected in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and expected in err, err
    assert not (tmp_path / 'r').exists()
