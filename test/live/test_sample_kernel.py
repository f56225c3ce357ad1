"""The C kernel of the lone sample (live/_sample_kernel.c) against the pure core's batch path.

Bytes in as rclpy serializes them, bytes out read back by rclpy: wrench, uncertainty, flags,
counters, input monitor and overload must be the pure core's, to 1e-12, with a zero, a tare (and
its scatter), an inverted installation and ratiometric inputs; what the kernel declines goes to the
pure core.
"""

from live_cases import calibration_with_covariance, show_run, take
import numpy as np
import pytest
from serialized_messages import serialized, single_through_kernel, six, through_kernel

from balance_calib.calibration_file import load_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.live import _sample_kernel, sample_kernel  # noqa: F401  (an import error must fail)
from balance_calib.live.raw_codec import decode_wrenches, WrenchEncoder
from balance_calib.live.stream import LiveCalibrator, LiveSettings
from balance_calib.model.active_calibration import activate
from balance_calib.tunnel_axes import INVERTED, UPRIGHT

MEMO = load_calibration(CONFIG_DIR / 'lmc6522.yaml')
CAPACITY = MEMO.capacity


@pytest.mark.parametrize('installation, scale', [(INVERTED, 1.0), (UPRIGHT, 2.5)])
def test_kernel_sample_kernels_equal_the_pure_core_after_a_zero_and_a_tare(installation, scale):
    calibration = calibration_with_covariance()
    active = activate(calibration, 'cubic', installation)
    zero, wind_off, wind_on, _ = show_run(installation, samples_per_condition=3, seed=7)
    samples = wind_on.reshape(-1, 6).copy()
    samples[30, 2] = 50.0 * MEMO.rated_output_mv[2]  # saturated: declined, not published
    samples[9, 0] = np.nan  # not finite: declined, not published
    samples[11, 2] = 1.4 * MEMO.rated_output_mv[2]  # beyond the envelope: published, flagged
    lives = []
    for _ in range(2):
        live = LiveCalibrator(active, LiveSettings(overload_fraction=2.0))
        assert take(live, 'zero', zero).ok and take(live, 'tare', wind_off, 10**9).ok
        lives.append(live)
    batch_live, single_live = lives
    stamps = 2 * 10**9 + np.arange(len(samples)) * 10**6
    stamps[20] = stamps[19]  # a duplicate stamp, counted by both
    frames = ['LMC6522'] * len(samples)
    messages = serialized(samples / scale, stamps)
    # another balance's frame
    messages[30] = serialized(samples[30:31] / scale, stamps[30:31], 'B660H')[0]
    frames[30] = 'B660H'
    batch = batch_live.process(samples, stamps, frames, now_s=0.0)
    wrench, uncertainty, by_kernel = single_through_kernel(
        single_live, messages, scale, WrenchEncoder('tunnel')
    )

    published = [k for k, w in enumerate(wrench) if w is not None]
    assert published == batch.indices.tolist() and 30 not in published and 9 not in published
    # the kernel declines the non-finite sample; the saturated bridge (30) raises the overload,
    # held for the rest of the run (1 s), and while it is held the pure core takes every sample
    assert by_kernel == [k != 9 and k < 30 for k in range(len(samples))]
    assert single_live.counters.out_of_envelope == 1 and single_live.overload.active
    fs = np.abs(installation.to_tunnel(CAPACITY))
    np.testing.assert_allclose(
        np.vstack([wrench[k] for k in published]) / fs, batch.wrench / fs, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        np.vstack([uncertainty[k] for k in published]), batch.uncertainty, rtol=1e-12
    )
    assert batch.batch.out_of_envelope[11]
    for name in ('received', 'published', 'rejected_nonfinite', 'saturated', 'out_of_envelope'):
        assert getattr(single_live.counters, name) == getattr(batch_live.counters, name), name
    assert single_live.inputs.problems() == batch_live.inputs.problems()
    assert single_live.inputs.foreign_frames == {'B660H'}
    np.testing.assert_allclose(
        single_live.overload.peak_fraction, batch_live.overload.peak_fraction, rtol=1e-12
    )


def test_kernel_raises_the_overload_and_a_new_tare_reaches_it():
    """An overloading sample through the kernel raises the overload as process() does; while it is
    held, and while a tare window collects, the pure core takes the samples; the new tare then
    reaches the kernel's numbers.
    """
    calibration = calibration_with_covariance()
    active = activate(calibration, 'cubic', UPRIGHT)
    settings = LiveSettings(overload_fraction=0.4, overload_clear_s=0.5)
    kernel_live, core_live = LiveCalibrator(active, settings), LiveCalibrator(active, settings)
    encoder = WrenchEncoder('tunnel')
    rng = np.random.default_rng(3)
    quiet = rng.uniform(-0.1, 0.1, (5, 6)) * MEMO.rated_output_mv
    loud = quiet[:1].copy()
    loud[0, 2] = 0.6 * MEMO.rated_output_mv[2]
    stamps = 10**9 + np.arange(8) * 10**6
    rows = np.vstack([quiet[:2], loud, quiet[2:]])
    changes = []
    for k, row in enumerate(rows):
        data = serialized(row[None, :], stamps[k : k + 1])[0]
        now_s = 0.1 * k
        done = through_kernel(kernel_live, data, now_s, encoder)
        assert (done is None) == (k > 2)  # held overload: the pure core's turn
        core_live.process(row[None, :], stamps[k : k + 1], now_s=now_s)
        changes.append((kernel_live.overload_changed, kernel_live.overload.active))
        assert (kernel_live.overload.active, kernel_live.overload.components) == (
            core_live.overload.active,
            core_live.overload.components,
        )
    assert changes[2] == (True, True) and kernel_live.overload.components == ('FZ',)
    assert kernel_live.overload.active  # 0.2 s inside so far: still held (clear_s 0.5)

    live = LiveCalibrator(active)
    first = serialized(quiet[:1], stamps[:1])[0]
    before = through_kernel(live, first, 0.0, encoder)
    live.start_window('tare', 20)
    window = quiet[:1] + rng.normal(0.0, 1e-4, (20, 6)) * MEMO.rated_output_mv
    collecting = serialized(window[:1], stamps[1:2])[0]
    assert through_kernel(live, collecting, 0.0, encoder) is None  # the window collects
    live.process(window[1:], 2 * 10**9 + np.arange(1, 20) * 10**6, now_s=0.0)
    assert live.finish_window().ok
    after = through_kernel(live, serialized(quiet[:1], stamps[2:3] + 3 * 10**9)[0], 0.0, encoder)
    reference = live.process(quiet[:1], stamps[3:4] + 4 * 10**9, now_s=0.0)
    np.testing.assert_allclose(six(after[0]), reference.wrench[0], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(six(after[1]), reference.uncertainty[0], rtol=1e-12)
    # tared away
    assert np.abs(six(after[0])).max() < 1e-3 * CAPACITY.max() < np.abs(six(before[0])).max()
    assert np.all(six(after[1]) > six(before[1]))  # the tare's scatter added


def test_what_the_kernel_does_not_take():
    encoder = WrenchEncoder('tunnel')
    # the memo's matrices: no covariance
    memo_live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    data = serialized(np.full((1, 6), 0.1), [10**9])[0]
    done = through_kernel(memo_live, data, 0.0, encoder)
    assert done is not None and done[1] is None
    plan = sample_kernel.make_plan(memo_live.active, memo_live.tare, 1.0, encoder.middle)
    big_endian = b'\x00\x00' + data[2:]
    assert sample_kernel.run(plan, big_endian, True, 1.0, np.zeros(6)) is None
    assert sample_kernel.run(plan, data[:-8], True, 1.0, np.zeros(6)) is None
    filtered = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT), LiveSettings(lowpass_hz=10.0))
    assert through_kernel(filtered, data, 0.0, encoder) is None
    with pytest.raises(ValueError, match='covariance'):
        _sample_kernel.plan(
            1.0,
            *[np.zeros(6)] * 5,
            np.arange(6),
            np.ones(6),
            2,
            1,
            np.zeros((2, 1), np.intp),
            np.zeros((6, 2)),
            np.zeros(3),
            np.zeros(6),
            np.zeros(6),
            np.ones(6, np.int64),
            b'',
        )
    plan = sample_kernel.make_plan(memo_live.active, memo_live.tare, 1.0, encoder.middle)
    with pytest.raises(ValueError, match='peak'):
        sample_kernel.run(plan, data, True, 1.0, np.zeros(5))
    with pytest.raises(TypeError):  # read-only: the peak is written in place
        sample_kernel.run(plan, data, True, 1.0, bytes(48))


def test_a_batch_goes_through_the_kernel_until_it_declines_and_the_rest_through_the_pure_core(
    tmp_path, monkeypatch
):
    """CalibratorSession.on_samples: the kernel takes a batch sample by sample; from the first
    sample it declines (here not finite) the pure core takes the rest. Wrenches and uncertainties
    in order, and the counters, must be those of the pure core alone.
    """
    from balance_calib.calibration_file import save_calibration
    from balance_calib.live import session as session_module
    from balance_calib.live.parameters import PARAMETERS

    path = tmp_path / 'calibration.yaml'
    save_calibration(str(path), calibration_with_covariance())
    values = {name: spec.default for name, spec in PARAMETERS.items()}
    values.update(
        calibration_file=str(path), tare_file=str(tmp_path / 'tare.yaml'), installation='inverted'
    )
    rng = np.random.default_rng(21)
    batch = rng.uniform(-0.4, 0.4, (12, 6)) * MEMO.rated_output_mv
    batch[7, 3] = np.nan
    messages = serialized(batch, 10**9 + np.arange(12) * 10**6)

    def run(kernel: bool):
        monkeypatch.setattr(sample_kernel, 'available', kernel)
        session = session_module.CalibratorSession(
            lambda name: values[name], 'test', lambda level, line: None
        )
        out = session.on_samples(messages[:4]), session.on_samples(messages[4:])
        return (
            session,
            [six(w) for o in out for w in o.wrench],
            [six(u) for o in out for u in o.uncertainty()],
        )

    core_session, core_wrench, core_uncertainty = run(False)
    kernel_session, kernel_wrench, kernel_uncertainty = run(True)
    assert len(kernel_wrench) == len(kernel_uncertainty) == 11
    np.testing.assert_allclose(kernel_wrench, core_wrench, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(kernel_uncertainty, core_uncertainty, rtol=1e-12)
    for name in ('received', 'published', 'rejected_nonfinite', 'saturated', 'out_of_envelope'):
        assert getattr(kernel_session.live.counters, name) == getattr(
            core_session.live.counters, name
        ), name
    assert kernel_session.live.counters.rejected_nonfinite == 1


def test_the_in_process_benchmark_runs_both_paths():
    """benchmarks/sample_kernel.py (figures in the README): every case measured for both paths (no
    timing is asserted), and the kernel switched back on afterwards.
    """
    from balance_calib.benchmarks.sample_kernel import BATCHES, measure

    results = measure(30)
    assert len(results) == 2 * (len(BATCHES) + 1) and all(v > 0 for v in results.values())
    assert sample_kernel.available


def test_arbitrary_bytes_never_crash_the_kernel_and_what_it_takes_is_what_the_decoder_reads():
    """The kernel reads bytes off the network: any bytes give None or the numbers the pure core's
    decoder and calibration give for the same bytes (no read outside the message, no silent wrong
    number).
    """
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from balance_calib.live.calibrator_core import compute_wrench

    active = activate(MEMO, 'cubic', UPRIGHT)
    live = LiveCalibrator(active)
    encoder = WrenchEncoder('tunnel')
    plan = sample_kernel.make_plan(active, live.tare, 1.0, encoder.middle)
    valid = serialized(np.full((1, 6), 0.2), [10**9])[0]

    def check(data: bytes) -> None:
        peak = np.zeros(6)
        result = sample_kernel.run(plan, data, True, 1.0, peak)
        if result is None:
            return
        stamps, values, frames = decode_wrenches([data])
        stamp_ns, frame_id, loads, _, _, wrench, _ = result
        assert stamp_ns == int(stamps[0]) and frame_id.decode('utf-8', 'replace') == frames[0]
        core = compute_wrench(active, values)
        assert core.accepted[0]
        np.testing.assert_allclose(
            loads, core.loads_total[0], rtol=1e-12, atol=1e-12 * CAPACITY.max()
        )
        np.testing.assert_allclose(
            six(wrench), core.wrench_tunnel[0], rtol=1e-12, atol=1e-12 * CAPACITY.max()
        )

    @settings(max_examples=300, deadline=None)
    @given(st.binary(max_size=200))
    def any_bytes(data):
        check(data)

    @settings(max_examples=300, deadline=None)
    @given(
        st.lists(st.tuples(st.integers(0, len(valid) - 1), st.integers(0, 255)), max_size=6),
        st.integers(-8, 8),
    )
    def mutated(flips, resize):
        data = bytearray(valid)
        for position, value in flips:
            data[position] = value
        data = bytes(data[: len(data) + resize]) if resize < 0 else bytes(data) + bytes(resize)
        check(data)

    any_bytes()
    mutated()
