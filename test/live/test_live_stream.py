"""The live calibrator's state without ROS: tare in load space, zero in output space, steadiness,
overload, low-pass, input health, saturation, persistence, parameters, and the fast path's bytes.
"""

import os
import re

from live_cases import (
    calibration_with_covariance,
    CAPACITY,
    ELECTRICAL_ZERO_MV,
    MEMO,
    model_weight_tunnel,
    NOISE_MV,
    show_run,
    take,
)
import numpy as np
import pytest

from balance_calib.calibration_file import ConfigError, load_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.diagnostics_status import ERROR, OK, STALE
from balance_calib.live.parameters import check_parameter, load_calibration_checked, PARAMETERS
from balance_calib.live.stream import (
    InputMonitor,
    LiveCalibrator,
    LiveSettings,
    LowPass,
    OverloadMonitor,
)
from balance_calib.live.tare_store import load_tare, save_tare, tare_file_for, TareState
from balance_calib.live.tare_window import check_steady
from balance_calib.model.active_calibration import activate
from balance_calib.nodes._messages import set_wrench
from balance_calib.tunnel_axes import INVERTED, UPRIGHT


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_a_load_space_tare_reads_wind_on_loads_within_0_1_pct_fs_an_output_space_one_not(
    installation,
):
    zero, wind_off, wind_on, aero = show_run(installation)
    live = LiveCalibrator(activate(MEMO, 'cubic', installation))
    assert take(live, 'zero', zero).ok
    tare = take(live, 'tare', wind_off, 10**9)
    assert tare.ok, tare.message
    full_scale = np.abs(installation.to_tunnel(CAPACITY))
    # the reply states the load it subtracted, in N and N·m: the model weight
    stated = float(re.search(r'FZ=([-+0-9.]+) N', tare.message).group(1))
    assert abs(stated - model_weight_tunnel()[2]) < 0.001 * CAPACITY[2] and 'N·m' in tare.message
    read = np.array(
        [
            live.process(c, 2 * 10**9 + np.arange(len(c)) * 10**6, now_s=0.0).wrench.mean(axis=0)
            for c in wind_on
        ]
    )
    error_pct = np.abs(read - aero) / full_scale * 100
    # noise 0.03 % FS per sample, 50 samples a condition and 100 in each window: σ of the error ≈
    # 0.006 % FS
    assert error_pct.max() < 0.1, error_pct.max(axis=0)

    # the tare taken in output space, as the node did before: the cubic model on V - V_wind_off
    output_space = np.array(
        [
            compute_wrench(live.active, c, zero_mv=wind_off.mean(axis=0)).wrench_tunnel.mean(
                axis=0
            )
            for c in wind_on
        ]
    )
    wrong_pct = np.abs(output_space - aero) / full_scale * 100
    assert wrong_pct.max() > 0.3  # measured 0.36 (upright) and 0.53 % FS (inverted), on F_X


def test_steadiness_refuses_a_ramp_and_a_step_and_accepts_noise():
    rng = np.random.default_rng(3)
    names, units, scale = ('FX', 'FZ'), ('N', 'N'), np.array([980.0, 9800.0])
    # white noise of any size: the halves differ by 2σ/√n = 0.2σ at n = 100, far below 4σ
    refused = [
        not check_steady(rng.normal(0, s, (100, 2)), names, units, scale, 4.0).steady
        for s in rng.uniform(0.01, 50.0, 200)
    ]
    assert sum(refused) == 0
    ramp = rng.normal(0, 1.0, (100, 2))
    # 20 N over the window, noise 1 N: the halves differ by 10σ
    ramp[:, 1] += np.linspace(0.0, 20.0, 100)
    verdict = check_steady(ramp, names, units, scale, 4.0)
    assert (
        not verdict.steady
        and verdict.reason.startswith('FZ moved by +')
        and 'ramp' in verdict.reason
    )
    step = rng.normal(0, 1.0, (100, 2))
    step[70:, 0] += 1996.0  # the mid-campaign call of the issue
    assert not check_steady(step, names, units, scale, 4.0).steady
    # noise-free and constant
    assert check_steady(np.full((20, 2), 3.0), names, units, scale, 4.0).steady


def test_tare_refused_on_a_ramp_keeps_the_previous_tare_and_says_why():
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    zero, wind_off, _, _ = show_run(UPRIGHT)
    assert take(live, 'tare', wind_off).ok
    before = live.tare.tare_load.copy()
    ramp = wind_off + np.linspace(0, 0.2, len(wind_off))[:, None] * np.array([0, 0, 1.0, 0, 0, 0])
    refused = take(live, 'tare', ramp, 10**9)
    assert not refused.ok and 'not steady' in refused.message and 'FZ moved' in refused.message
    assert 'previous tare stays' in refused.message
    np.testing.assert_array_equal(live.tare.tare_load, before)
    assert 'tare load removed' in live.clear_tare() and live.tare.tare_load is None


def test_zero_clears_the_tare_load_taken_above_the_old_zero():
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    zero, wind_off, _, _ = show_run(UPRIGHT)
    assert take(live, 'tare', wind_off).ok
    result = take(live, 'zero', zero, 10**9)
    assert (
        result.ok and 'FXV=+0.04' in result.message and 'tare load was cleared' in result.message
    )
    assert live.tare.tare_load is None
    np.testing.assert_allclose(live.tare.zero_mv, ELECTRICAL_ZERO_MV, atol=3 * NOISE_MV.max() / 10)


def test_saturated_and_overflowing_outputs_are_never_published_as_numbers():
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    outputs = np.array(
        [
            [0.1] * 6,
            [1e103, 0, 0, 0, 0, 0],
            [0, 0, 1.7e308, 0, 0, 0],
            [0.1] * 6,
            # 5 mV on F_YV: 2.2x its rated 2.258 mV
            [0, 5.0, 0, 0, 0, 0],
            [np.nan] * 6,
        ]
    )
    published = live.process(outputs, np.arange(1, 7) * 10**6, now_s=0.0)
    assert published.indices.tolist() == [0, 3] and np.all(np.isfinite(published.wrench))
    # one sample at a time (the live path at low rates): the same
    for k, row in enumerate(outputs):
        alone = compute_wrench(live.active, row[None, :])
        assert (alone.accepted[0], alone.saturated[0]) == (
            published.batch.accepted[k],
            published.batch.saturated[k],
        )
        np.testing.assert_allclose(
            alone.wrench_tunnel[0], published.batch.wrench_tunnel[k], rtol=1e-12
        )
    assert live.counters.saturated == 3 and live.counters.rejected_nonfinite == 1
    assert live.overload.active and 'saturated bridge' in live.overload.components
    reports = live.report(
        period_s=1.0,
        last_sample_age_s=0.0,
        temperature_age_s=None,
        refit_running=False,
        tare_source='',
        node_name='n',
    )
    assert reports[0].level == ERROR and '3 samples saturated' in reports[0].message
    assert reports[2].level == ERROR and 'OVERLOAD' in reports[2].message


def test_overload_is_raised_at_once_and_cleared_after_the_loads_stay_inside():
    monitor = OverloadMonitor(CAPACITY, 0.9, clear_s=1.0)
    inside, over = np.zeros((1, 6)), np.zeros((1, 6))
    over[0, 4] = 0.95 * CAPACITY[4]  # M_Y at 0.95 of rated, limit 0.9
    no = np.zeros(1, bool)
    assert not monitor.update(inside, no, 0.0) and not monitor.active
    assert monitor.update(over, no, 1.0) and monitor.active and monitor.components == ('MY',)
    assert not monitor.update(inside, no, 1.5)  # inside since 1.5 s
    assert not monitor.update(over, no, 2.0)  # again over: the clock restarts
    assert (
        not monitor.update(inside, no, 2.1)
        and not monitor.update(inside, no, 3.0)
        and monitor.active
    )
    assert monitor.update(inside, no, 3.1) and not monitor.active  # 1.0 s inside since 2.1 s


def test_lowpass_is_the_first_order_filter_carried_across_batches_and_reset_by_a_tare():
    filt = LowPass(10.0)
    dt = 1e-3
    a = 1 - np.exp(-2 * np.pi * 10.0 * dt)
    x = np.zeros((200, 6))
    x[100:] = 1.0
    y = np.vstack(
        [
            filt.apply(x[:1], dt),
            filt.apply(x[1:120], dt),
            filt.apply(x[120:121], dt),
            filt.apply(x[121:], dt),
        ]
    )
    k = np.arange(200) - 99
    # step response of y += a (x - y)
    expected = np.where(k > 0, 1 - (1 - a) ** np.maximum(k, 0), 0.0)
    np.testing.assert_allclose(y[:, 2], expected, atol=1e-12)
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT), LiveSettings(lowpass_hz=5.0))
    stamps = np.arange(1, 101) * 10**6
    live.process(np.full((100, 6), 0.1), stamps, now_s=0.0)
    assert live.lowpass.state is not None
    zero, wind_off, _, _ = show_run(UPRIGHT)
    take(live, 'tare', wind_off, 10**9)
    assert live.lowpass.state is None


def test_input_monitor_counts_bad_stamps_foreign_frames_and_gaps():
    monitor = InputMonitor('LMC6522')
    stamps = np.arange(1, 1001) * 1_000_000  # 1 kHz
    monitor.update(stamps[:500], ['LMC6522'] * 500)
    kept = np.concatenate([stamps[500:600], stamps[900:]])  # 300 samples lost in a burst
    # one old, one repeated, one zero
    disorder = np.concatenate([kept[:10], [kept[5], kept[9], 0], kept[10:]])
    monitor.update(disorder, ['lmc6522'] * 200 + ['B660H'] * (len(disorder) - 200))
    totals = monitor.total
    assert totals['samples lost (gaps in the stamps)'] == 300
    assert (
        totals['stamps out of order'] == 1
        and totals['duplicate stamps'] == 1
        and totals['zero stamps'] == 1
    )
    assert totals['samples from another balance'] == len(
        disorder
    ) - 200 and monitor.foreign_frames == {'B660H'}


def test_diagnostics_say_stale_and_show_the_zero_and_the_tare(tmp_path):
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    report = dict(
        zip(
            ('input', 'calibration', 'overload'),
            live.report(
                period_s=1.0,
                last_sample_age_s=None,
                temperature_age_s=None,
                refit_running=False,
                tare_source='',
                node_name='n',
            ),
        )
    )
    assert report['input'].level == STALE and report['overload'].level == OK
    zero, wind_off, _, _ = show_run(UPRIGHT)
    take(live, 'zero', zero)
    take(live, 'tare', wind_off, 10**9)
    values = dict(
        live.report(
            period_s=1.0,
            last_sample_age_s=5.0,
            temperature_age_s=None,
            refit_running=False,
            tare_source='x.tare.yaml',
            node_name='n',
        )[1].values
    )
    assert values['zero_mv'].startswith('FXV=+0.04') and 'FZ=-29' in values['tare_load']
    assert values['tare_file'] == 'x.tare.yaml'


def test_zero_and_tare_survive_a_save_and_load_and_belong_to_one_balance(tmp_path):
    state = TareState(
        'LMC6522', ELECTRICAL_ZERO_MV, 21.5, np.ones(6), 't0', model_weight_tunnel(), 't1'
    )
    path = tare_file_for(str(tmp_path / 'calibration.yaml'), '/left/balance_calibrator', False)
    assert path == tmp_path / 'calibration.left.balance_calibrator.tare.yaml'
    assert (
        tare_file_for(str(tmp_path / 'calibration.yaml'), '/balance_calibrator', False)
        == tmp_path / 'calibration.tare.yaml'
    )
    assert tare_file_for(str(CONFIG_DIR / 'lmc6522.yaml'), '/balance_calibrator', True) is None
    save_tare(path, state)
    back = load_tare(path, 'lmc6522')
    np.testing.assert_array_equal(back.zero_mv, state.zero_mv)
    np.testing.assert_array_equal(back.tare_load, state.tare_load)
    assert back.zero_temperature_c == 21.5 and back.tare_taken_at == 't1'
    with pytest.raises(ValueError, match='not of'):
        load_tare(path, 'B660H')
    assert load_tare(tmp_path / 'none.yaml', 'LMC6522') is None


BAD_VALUES = [
    ('tare_timeout_s', float('inf')),
    ('diagnostics_period_s', float('inf')),
    ('diagnostics_period_s', 0.0),
    ('diagnostics_period_s', -1.0),
    ('tare_samples', 0),
    ('tare_samples', -5),
    ('envelope_margin', 1e-9),
    ('envelope_margin', float('nan')),
    ('overload_fraction', float('nan')),
    ('lowpass_hz', -1.0),
    ('stale_after_s', float('nan')),
    ('tare_samples', 2.5),
    ('input_depth', 0),
]


@pytest.mark.parametrize('name,value', BAD_VALUES)
def test_bad_parameter_values_are_refused_naming_the_parameter_and_its_range(name, value):
    with pytest.raises(ValueError, match=f'parameter {name} must be'):
        check_parameter(name, value)


def test_every_parameter_has_a_description_and_numbers_have_a_range():
    for name, spec in PARAMETERS.items():
        assert len(spec.description) > 10, name
        if isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool):
            assert spec.low is not None and spec.low <= spec.default <= spec.high, name
            check_parameter(name, spec.default)


def test_calibration_files_that_never_end_or_block_are_refused(tmp_path):
    fifo = tmp_path / 'calibration.fifo'
    os.mkfifo(fifo)
    for path in (fifo, '/dev/zero', tmp_path):
        with pytest.raises(ConfigError, match='not a calibration file|is a'):
            load_calibration_checked(path, 5.0)
        with pytest.raises(ValueError):
            check_parameter('calibration_file', str(path))
    capacity_nan = CONFIG_DIR.joinpath('lmc6522.yaml').read_text().replace('FX: 980', 'FX: .nan')
    bad = tmp_path / 'nan_capacity.yaml'
    bad.write_text(capacity_nan)
    with pytest.raises(ConfigError, match='capacity must be positive finite'):
        activate(load_calibration(bad), 'cubic', 'upright')


def test_fast_path_bytes_carry_exactly_the_pure_cores_wrench():
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message

    from balance_calib.live.raw_codec import decode_wrenches, WrenchEncoder

    rng = np.random.default_rng(5)
    outputs = rng.uniform(-1.0, 1.0, (50, 6))
    messages = []
    for k, row in enumerate(outputs):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1700000000 + k, 999_999_000 - k
        msg.header.frame_id = 'LMC6522' if k != 7 else 'B660H-other'  # one of another length
        set_wrench(msg.wrench, row.tolist())
        messages.append(serialize_message(msg))
    stamps, values, frames = decode_wrenches(messages)
    np.testing.assert_array_equal(values, outputs)
    singles = [decode_wrenches([m]) for m in messages]  # the one-message path
    np.testing.assert_array_equal(np.vstack([v for _, v, _ in singles]), values)
    assert [int(t[0]) for t, _, _ in singles] == stamps.tolist() and [
        f[0] for _, _, f in singles
    ] == frames
    assert frames[7] == 'B660H-other' and frames[8] == 'LMC6522'
    assert stamps[3] == (1700000003 * 10**9 + 999_999_000 - 3)
    active = activate(MEMO, 'cubic', INVERTED)
    live = LiveCalibrator(active)
    published = live.process(values, stamps, frames, now_s=0.0)
    encoder = WrenchEncoder('tunnel')
    encoded = encoder.encode(stamps[published.indices], published.wrench)
    assert [
        encoder.encode(stamps[k : k + 1], published.wrench[k : k + 1])[0] for k in range(3)
    ] == encoded[:3]
    back = [deserialize_message(b, WrenchStamped) for b in encoded]
    wrench = np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for m in back
        ]
    )
    core = np.vstack([compute_wrench(active, row[None, :]).wrench_tunnel for row in outputs])
    np.testing.assert_allclose(wrench, core, rtol=1e-12, atol=1e-12)
    assert back[3].header.stamp.nanosec == 999_999_000 - 3 and back[0].header.frame_id == 'tunnel'
    assert len(encoded[0]) == len(serialize_message(back[0]))


def test_published_uncertainty_is_the_calibrations_own_with_the_tare_scatter_added():
    from balance_calib.model.uncertainty import load_standard_uncertainty

    calibration = calibration_with_covariance()
    active = activate(calibration, 'cubic', INVERTED)
    live = LiveCalibrator(active)
    rng = np.random.default_rng(12)
    outputs = rng.uniform(-0.5, 0.5, (40, 6)) * MEMO.rated_output_mv
    batch = live.process(outputs, np.arange(1, 41) * 10**6, now_s=0.0)
    singles = np.vstack(
        [
            live.process(row[None, :], np.array([10**9 + k * 10**6]), now_s=0.0).uncertainty
            for k, row in enumerate(outputs)
        ]
    )
    direct = load_standard_uncertainty(active.model, outputs)  # balance axes, FX..MZ
    np.testing.assert_allclose(batch.uncertainty, np.abs(INVERTED.to_tunnel(direct)), rtol=1e-12)
    np.testing.assert_allclose(singles, batch.uncertainty, rtol=1e-12)
    assert np.all(batch.uncertainty > 0)
    _, wind_off, _, _ = show_run(INVERTED)
    assert take(live, 'tare', wind_off, 2 * 10**9).ok
    sigma = live.tare.tare_sigma
    np.testing.assert_allclose(
        sigma,
        np.std(compute_wrench(active, wind_off).loads_total, axis=0, ddof=1) / 10.0,
        rtol=1e-12,
    )  # scatter / √100
    after = live.process(outputs, 3 * 10**9 + np.arange(40) * 10**6, now_s=0.0).uncertainty
    np.testing.assert_allclose(
        after, np.sqrt(batch.uncertainty**2 + np.abs(INVERTED.to_tunnel(sigma)) ** 2), rtol=1e-12
    )
    assert (
        LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
        .process(outputs, np.arange(1, 41), now_s=0.0)
        .uncertainty
        is None
    )  # the memo's matrices: no covariance


def test_sample_kernels_after_a_zero_and_a_tare_equal_the_batch_path_wrench_and_uncertainty():
    """At 1 kHz every sample comes alone and takes the one-sample path (design row reused for the
    uncertainty); it must give the batch path's numbers, flags and counts, with zero and tare
    applied.
    """
    calibration = calibration_with_covariance()
    active = activate(calibration, 'cubic', INVERTED)
    zero, wind_off, wind_on, _ = show_run(INVERTED, samples_per_condition=3, seed=4)
    samples = wind_on.reshape(-1, 6)
    samples[5, 2] = 50.0 * MEMO.rated_output_mv[2]  # saturated: not published on either path
    samples[9, 0] = np.nan  # not finite: not published either
    samples[11, 2] = 1.4 * MEMO.rated_output_mv[2]  # beyond the envelope: published, flagged
    lives = []
    for _ in range(2):
        live = LiveCalibrator(active)
        assert take(live, 'zero', zero).ok and take(live, 'tare', wind_off, 10**9).ok
        lives.append(live)
    batch_live, single_live = lives
    stamps = 2 * 10**9 + np.arange(len(samples)) * 10**6
    batch = batch_live.process(samples, stamps, now_s=0.0)
    lone = [
        single_live.process(samples[k : k + 1], stamps[k : k + 1], now_s=0.0)
        for k in range(len(samples))
    ]
    published = [k for k in range(len(samples)) if len(lone[k].indices)]
    assert published == batch.indices.tolist() and 5 not in published and 9 not in published
    np.testing.assert_allclose(
        np.vstack([lone[k].wrench for k in published]), batch.wrench, rtol=1e-12, atol=1e-9
    )
    np.testing.assert_allclose(
        np.vstack([lone[k].uncertainty for k in published]), batch.uncertainty, rtol=1e-12
    )
    assert [
        bool(lone[k].batch.out_of_envelope[0]) for k in range(len(samples))
    ] == batch.batch.out_of_envelope.tolist() and batch.batch.out_of_envelope[11]
    assert lone[0].batch.design_row is not None  # the one-sample path was taken
    for name in ('received', 'published', 'rejected_nonfinite', 'saturated', 'out_of_envelope'):
        assert getattr(single_live.counters, name) == getattr(batch_live.counters, name), name
    assert single_live.overload.active == batch_live.overload.active
    np.testing.assert_allclose(
        single_live.overload.peak_fraction, batch_live.overload.peak_fraction, rtol=1e-12
    )


def test_a_deferred_uncertainty_is_that_of_its_own_batch_even_after_a_new_tare():
    """The node publishes the wrenches first and computes their uncertainty after: it must be the
    batch's own (its calibration, zero and tare), whatever the service thread changed meanwhile.
    """
    active = activate(calibration_with_covariance(), 'cubic', UPRIGHT)
    zero, wind_off, wind_on, _ = show_run(UPRIGHT, samples_per_condition=2, seed=6)
    live, reference = LiveCalibrator(active), LiveCalibrator(active)
    for calibrator in (live, reference):
        assert take(calibrator, 'zero', zero).ok and take(calibrator, 'tare', wind_off, 10**9).ok
    samples = wind_on.reshape(-1, 6)
    stamps = 2 * 10**9 + np.arange(len(samples)) * 10**6
    deferred = live.process(samples, stamps, now_s=0.0, defer_uncertainty=True)
    lone = live.process(samples[:1], stamps[:1] + 10**8, now_s=0.0, defer_uncertainty=True)
    assert deferred.uncertainty is None and lone.uncertainty is None
    # meanwhile, in the service thread
    assert live.clear_tare().startswith('clear_tare: tare load removed')
    now = reference.process(samples, stamps, now_s=0.0)
    np.testing.assert_allclose(deferred.uncertainty_later(), now.uncertainty, rtol=1e-12)
    np.testing.assert_allclose(lone.uncertainty_later(), now.uncertainty[:1], rtol=1e-12)
    without_tare = live.process(samples, stamps + 10**9, now_s=0.0).uncertainty
    assert np.all(without_tare < now.uncertainty)  # the tare's own scatter is no longer added
