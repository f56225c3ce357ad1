"""A 3-component calibration (a cell measuring F_Z, M_X, M_Y) and a 5-component one (no axial
force), fitted from small tables by `fit --axes`, run by the live calibrator's pure core and its
C kernel: the components from their bridges, the absent ones published as 0 with their
uncertainty NaN, the envelope, saturation and overload checks blind to the absent ones,
/diagnostics naming them.
"""

from live_cases import take
import numpy as np
from partial_cells import (
    ABSENT,
    CAPACITY,
    fit_cell,
    FIVE,
    K_MV,
    raw_samples,
    SIGMA_LOAD,
    SLOTS,
    THREE,
)
import pytest
from serialized_messages import serialized, single_through_kernel

from balance_calib.calibration_file import load_calibration
from balance_calib.live.diagnostics_status import diagnostics, InputCounters, LiveState, OK
from balance_calib.live.raw_codec import WrenchEncoder
from balance_calib.live.stream import LiveCalibrator, LiveSettings
from balance_calib.model.active_calibration import activate
from balance_calib.tunnel_axes import INVERTED, UPRIGHT


@pytest.fixture(scope='module')
def calibration(tmp_path_factory):
    return load_calibration(fit_cell(tmp_path_factory.mktemp('cell')))


def test_the_fitted_file_is_a_three_component_calibration(calibration):
    assert calibration.components == THREE.axes
    assert calibration.bridge_outputs == ('FZV', 'MXV', 'MYV')
    np.testing.assert_allclose(calibration.capacity, CAPACITY)
    # the linear coefficients are the cell's K⁻¹, to the noise (relative 1e-5 of the outputs' span)
    np.testing.assert_allclose(
        calibration.model().coefficients,
        np.linalg.inv(K_MV),
        rtol=2e-3,
        atol=2e-3 * np.abs(np.linalg.inv(K_MV)).max(),
    )


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_three_components_from_their_bridges_the_absent_ones_zero_with_nan_uncertainty(
    calibration, installation
):
    rng = np.random.default_rng(8)
    loads = rng.uniform(-0.9, 0.9, (25, 3)) * CAPACITY
    live = LiveCalibrator(activate(calibration, 'adopted', installation))
    published = live.process(raw_samples(rng, loads), np.arange(1, 26) * 1_000_000, now_s=0.0)
    assert published.indices.tolist() == list(range(25))
    expected = np.zeros((25, 6))
    expected[:, SLOTS] = loads  # hand-computed: K⁻¹ · (K · L) = L
    expected = installation.to_tunnel(expected)
    absent_slots = [0, 1, 5]
    assert np.all(published.wrench[:, absent_slots] == 0.0)
    assert np.all(np.abs(published.wrench[:, SLOTS] - expected[:, SLOTS]) < 5 * SIGMA_LOAD)
    u = published.uncertainty
    assert np.all(np.isnan(u[:, absent_slots]))
    # the present components' uncertainty is the noise carried to the loads (σ estimated from
    # 42 points: within ±40 %), and the points' leverage adds little
    ratio = u[:, SLOTS] / SIGMA_LOAD
    assert np.all((ratio > 0.6) & (ratio < 1.4)), ratio
    assert not published.batch.out_of_envelope.any() and not live.overload.active


def test_envelope_saturation_and_overload_ignore_the_absent_components(calibration):
    rng = np.random.default_rng(9)
    live = LiveCalibrator(
        activate(calibration, 'adopted', UPRIGHT), LiveSettings(overload_fraction=1.2)
    )
    assert live.active.absent_components == ABSENT
    assert np.isinf(live.active.envelope[[0, 1, 5]]).all()
    assert np.isinf(live.active.output_range_mv[[0, 1, 5]]).all()
    calm = raw_samples(rng, np.array([[100.0, 5.0, -10.0]] * 3))
    calm[:, [0, 1, 5]] = [1e4, -1e4, 1e5]  # wild numbers on unused inputs: not a saturation
    published = live.process(calm, np.arange(1, 4) * 1_000_000, now_s=0.0)
    assert published.indices.tolist() == [0, 1, 2] and not published.batch.out_of_envelope.any()
    assert not live.overload.active
    # F_Z at 1.3 x capacity: beyond the envelope (1.1) and the overload limit (1.2), named
    beyond = raw_samples(rng, np.array([[1.3 * CAPACITY[0], 0.0, 0.0]]))
    published = live.process(beyond, np.array([5_000_000]), now_s=0.1)
    assert published.batch.out_of_envelope.all() and live.overload.active
    assert live.overload.components == ('FZ',)
    # the FZ bridge beyond its range (2 x rated output) is a saturated sample: not published
    saturated = raw_samples(rng, np.zeros((1, 3)))
    saturated[0, 2] = 3.0 * calibration.rated_output_mv[0]
    assert len(live.process(saturated, np.array([6_000_000]), now_s=0.2).indices) == 0


def test_a_tare_on_the_three_components_and_the_absent_ones_stay_zero(calibration):
    rng = np.random.default_rng(10)
    live = LiveCalibrator(activate(calibration, 'adopted', UPRIGHT))
    weight = np.array([-20.0, 0.4, 1.5])
    wind_off = raw_samples(rng, weight + rng.normal(0, 0.001, (30, 3)) * CAPACITY)
    tare = take(live, 'tare', wind_off)
    assert tare.ok, tare.message
    np.testing.assert_allclose(live.tare.tare_load[SLOTS], weight, atol=3e-3 * CAPACITY.max())
    assert np.all(live.tare.tare_load[[0, 1, 5]] == 0.0)
    aero = np.array([[50.0, -2.0, 3.0]])
    published = live.process(raw_samples(rng, weight + aero), np.array([10**9]), now_s=1.0)
    wrench = published.wrench[0]
    np.testing.assert_allclose(
        wrench[SLOTS],
        UPRIGHT.to_tunnel(np.r_[0, 0, aero[0], 0])[SLOTS],
        atol=3e-3 * CAPACITY.max(),
    )
    assert np.all(wrench[[0, 1, 5]] == 0.0)
    assert np.all(np.isnan(published.uncertainty[0, [0, 1, 5]]))


def test_diagnostics_name_the_absent_components(calibration):
    active = activate(calibration, 'adopted', UPRIGHT)
    state = LiveState(
        period_s=1.0,
        counters=InputCounters(received=10, period_received=10),
        last_sample_age_s=0.01,
        stale_after_s=1.0,
        temperature_age_s=None,
        fallback_reason='',
        tare_zero_mv=None,
    )
    reports = diagnostics(active, state)
    status = reports[1]
    values = dict(status.values)
    assert status.level == OK
    assert values['components'] == 'FZ, MX, MY' and values['absent_components'] == 'FX, FY, MZ'
    said = '3-component calibration: FX, FY, MZ absent (published as 0, uncertainty NaN)'
    assert said in status.message
    six = activate(load_calibration('lmc6522'), 'cubic', UPRIGHT)
    assert dict(diagnostics(six, state)[1].values)['absent_components'] == 'none'
    assert 'absent' not in diagnostics(six, state)[1].message


def test_the_c_kernel_gives_the_pure_cores_wrench_and_nan_uncertainty(calibration):
    rng = np.random.default_rng(11)
    active = activate(calibration, 'adopted', INVERTED)
    loads = rng.uniform(-0.9, 0.9, (12, 3)) * CAPACITY
    samples = raw_samples(rng, loads)
    stamps = 10**9 + np.arange(12) * 10**6
    batch_live, single_live = LiveCalibrator(active), LiveCalibrator(active)
    batch = batch_live.process(samples, stamps, ['cell-3'] * 12, now_s=0.0)
    messages = serialized(samples, stamps, 'cell-3')
    wrench, uncertainty, by_kernel = single_through_kernel(
        single_live, messages, 1.0, WrenchEncoder('tunnel')
    )
    assert all(by_kernel)  # a linear direct model of the bridges: the kernel's case
    np.testing.assert_allclose(
        np.vstack(wrench), batch.wrench, rtol=0, atol=1e-12 * CAPACITY.max()
    )
    # NaN where the pure core has NaN (assert_allclose holds NaN equal to NaN)
    np.testing.assert_allclose(np.vstack(uncertainty), batch.uncertainty, rtol=1e-12)
    assert np.isnan(np.vstack(uncertainty)[:, [0, 1, 5]]).all()
    assert np.all(np.vstack(wrench)[:, [0, 1, 5]] == 0.0)


def test_a_five_component_calibration_publishes_fx_as_0_and_names_it(tmp_path):
    calibration = load_calibration(fit_cell(tmp_path, seed=6, cell=FIVE))
    assert calibration.components == FIVE.axes
    np.testing.assert_allclose(calibration.capacity, FIVE.capacity)  # N-mm read as 1e-3 N·m
    rng = np.random.default_rng(12)
    loads = rng.uniform(-0.9, 0.9, (20, 5)) * FIVE.capacity
    live = LiveCalibrator(activate(calibration, 'adopted', UPRIGHT))
    published = live.process(
        raw_samples(rng, loads, FIVE), np.arange(1, 21) * 1_000_000, now_s=0.0
    )
    expected = np.zeros((20, 6))
    expected[:, FIVE.slots] = loads
    expected = UPRIGHT.to_tunnel(expected)
    assert np.all(published.wrench[:, 0] == 0.0) and np.all(np.isnan(published.uncertainty[:, 0]))
    error = np.abs(published.wrench[:, FIVE.slots] - expected[:, FIVE.slots])
    assert np.all(error < 5 * FIVE.sigma_load), error / FIVE.sigma_load
    ratio = published.uncertainty[:, FIVE.slots] / FIVE.sigma_load
    assert np.all((ratio > 0.6) & (ratio < 1.4)), ratio
    state = LiveState(
        period_s=1.0,
        counters=InputCounters(),
        last_sample_age_s=0.01,
        stale_after_s=1.0,
        temperature_age_s=None,
        fallback_reason='',
        tare_zero_mv=None,
    )
    status = diagnostics(live.active, state)[1]
    assert dict(status.values)['absent_components'] == 'FX'
    assert '5-component calibration: FX absent' in status.message


def test_nan_on_a_channel_the_calibration_does_not_read_changes_nothing(calibration):
    """A DAQ of three bridges may fill the other three slots of balance/raw with NaN: those samples
    are published as if the slots held numbers (batch, lone sample, kernel declining to the pure
    core), a zero taken then is finite; a NaN on a bridge the calibration reads is rejected.
    """
    rng = np.random.default_rng(13)
    loads = rng.uniform(-0.5, 0.5, (6, 3)) * CAPACITY
    finite = raw_samples(rng, loads)
    holes = finite.copy()
    holes[:, [0, 1, 5]] = np.nan
    holes[5, 2] = np.nan  # FZV: read by the calibration
    active = activate(calibration, 'adopted', UPRIGHT)
    reference = LiveCalibrator(active).process(finite, np.arange(1, 7) * 10**6, now_s=0.0)
    published = LiveCalibrator(active).process(holes, np.arange(1, 7) * 10**6, now_s=0.0)
    assert published.indices.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(published.wrench, reference.wrench[:5])
    np.testing.assert_allclose(published.uncertainty, reference.uncertainty[:5], rtol=1e-12)
    lone, kernel = LiveCalibrator(active), LiveCalibrator(active)
    for k in range(5):
        one = lone.process(holes[k : k + 1], np.array([(k + 1) * 10**6]), now_s=0.0)
        np.testing.assert_allclose(one.wrench, reference.wrench[k : k + 1], rtol=1e-12)
    assert lone.counters.published == 5 and lone.counters.rejected_nonfinite == 0
    stamps = np.arange(1, 7) * 10**6
    wrench, uncertainty, by_kernel = single_through_kernel(
        kernel, serialized(holes, stamps), 1.0, WrenchEncoder('tunnel')
    )
    assert not any(by_kernel) and wrench[5] is None  # the kernel declines, the pure core takes
    np.testing.assert_allclose(np.vstack(wrench[:5]), reference.wrench[:5], rtol=1e-12)
    assert kernel.counters.rejected_nonfinite == 1
    zeroing = LiveCalibrator(active)
    window = np.tile(holes[0], (10, 1))
    assert take(zeroing, 'zero', window).ok
    assert np.all(np.isfinite(zeroing.tare.zero_mv))
    assert np.all(zeroing.tare.zero_mv[[0, 1, 5]] == 0)
    np.testing.assert_allclose(zeroing.tare.zero_mv[SLOTS], holes[0, SLOTS])
