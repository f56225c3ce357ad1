"""The simulated thrust stand that bridge_publisher runs in its thrust_stand mode."""

import numpy as np
import pytest

from balance_calib.simulation.thrust_stand import SignalNoise, StandBuild, ThrustStandSimulator
from balance_calib.thrust_stand.nozzle import Nozzle


def test_steady_firing_thrust_is_efficiency_times_eq5():
    simulator = ThrustStandSimulator(stand=StandBuild(efficiency=0.7), seed=1)
    ideal = Nozzle().performance(0.5e6 + 101325.0, 101325.0).thrust_n
    assert simulator.firing_thrust_n == pytest.approx(0.7 * ideal, rel=1e-12)
    start, end = simulator.firing_windows()[0]
    force = simulator.true_force_n(np.linspace(start + 0.5, end, 50))
    # p_c still settling at 1e-5
    np.testing.assert_allclose(force, simulator.firing_thrust_n, rtol=1e-4)


def test_signals_follow_the_manuals_sequence():
    simulator = ThrustStandSimulator(
        seed=2, noise=SignalNoise(strain_noise_mv=0.0, gauge_noise_pa=0.0, ambient_noise_pa=0.0)
    )
    kinds = [s.kind for s in simulator.segments]
    assert kinds[:5] == ['idle', 'firing', 'idle', 'firing', 'idle']
    assert kinds.index('loaded') > kinds.index('firing')  # calibration after firing (fn. 12)
    assert kinds.count('loaded') == kinds.count('unloaded') == 6  # 0 ... 5 weights
    idle = simulator.sample(1.0)
    assert idle.chamber_gauge_pa == pytest.approx(0.0, abs=500.0)
    assert idle.ambient_pa == 101325.0
    loaded_five = [s for s in simulator.segments if s.kind == 'loaded'][-1]
    steady = simulator.sample(loaded_five.end_s - 0.1)
    # calibrated pressurised (§4.2)
    assert steady.chamber_gauge_pa == pytest.approx(0.5e6, rel=1e-6)
    expected_mv = loaded_five.applied_load_n / simulator.calibration_slope_n_per_mv
    assert steady.strain_mv - simulator.zero_offset_mv > expected_mv  # plus the accumulated set
    assert steady.bridge_outputs_mv().tolist()[1:] == [0.0] * 5


def test_residual_zero_after_unloading_grows_with_the_loads():
    readings = ThrustStandSimulator(seed=3).calibration_readings()
    residual = readings.unloaded_mv
    assert np.all(np.diff(residual) > 0)
    assert readings.corrected_mv == pytest.approx(readings.loaded_mv - readings.unloaded_mv)


def test_applied_load_events_bracket_each_point_with_nan():
    simulator = ThrustStandSimulator()
    events = simulator.applied_load_events()
    assert len(events) == 24
    assert np.isnan(events[0][1]) and events[1][1] == pytest.approx(0.015 * 9.80665)
    assert events[3][1] == 0.0  # the unloaded step is a zero point
    times = [t for t, _ in events]
    assert times == sorted(times) and times[-1] < simulator.duration_s


def test_cycle_repeats():
    simulator = ThrustStandSimulator(
        noise=SignalNoise(strain_noise_mv=0.0, gauge_noise_pa=0.0, ambient_noise_pa=0.0)
    )
    t = np.array([3.3, 17.2, 30.1])
    first = simulator.sample(t)
    again = simulator.sample(t + simulator.duration_s)
    np.testing.assert_allclose(first.strain_mv, again.strain_mv, rtol=1e-12)
    np.testing.assert_allclose(first.chamber_gauge_pa, again.chamber_gauge_pa, rtol=1e-9)
