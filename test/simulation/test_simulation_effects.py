"""The simulator's alternative effect shapes, checked against hand-worked cases."""

import numpy as np
import pytest

from balance_calib.simulation import effects as E


def _ctx(
    outputs, times=None, loads=None, capacity=None, gravity=None, settled=None, direction=None
):
    outputs = np.asarray(outputs, float)
    n = len(outputs)
    times = np.arange(n, dtype=float) * 10.0 if times is None else np.asarray(times, float)
    if direction is None:
        direction = np.ones_like(outputs)
        for i in range(1, n):
            step = outputs[i] - outputs[i - 1]
            direction[i] = np.where(step != 0, np.sign(step), direction[i - 1])
    return E.SampleContext(
        times,
        np.full(n, 20.0),
        outputs if loads is None else np.asarray(loads, float),
        outputs,
        direction,
        np.full(outputs.shape[1], 2.0),
        20.0,
        np.full(outputs.shape[1], 100.0) if capacity is None else capacity,
        np.tile([0.0, 0.0, 1.0], (n, 1)) if gravity is None else gravity,
        times if settled is None else settled,
    )


def test_play_hysteresis_ramps_from_the_turning_point_and_saturates():
    # rated 2 mV, half-width 0.25 x 2 = 0.5 mV, h = 0.01 -> offset ±0.02 mV once 1 mV past a turn
    v = np.array([0.0, 0.25, 0.5, 1.0, 2.0, 1.75, 1.5, 1.0, 0.0])[:, None] * np.ones((1, 6))
    out = E.PlayHysteresis(fraction_of_rated=0.01, width_fraction=0.25).outputs(v.copy(), _ctx(v))
    offset = (out - v)[:, 0] / 0.02
    assert offset == pytest.approx([0.0, 0.5, 1.0, 1.0, 1.0, 0.5, 0.0, -1.0, -1.0])


def test_creep_relaxes_after_each_step_with_its_time_constants():
    # one step of 1 mV at t = 0, samples at 0, 40, 400 s: V - c (0.6 e^{-t/40} + 0.4 e^{-t/400})
    v = np.array([[0.0], [1.0], [1.0], [1.0]]) * np.ones((1, 6))
    times = np.array([-10.0, 0.0, 40.0, 400.0])
    out = E.Creep(fraction=0.01).outputs(v.copy(), _ctx(v, times=times))
    expected = [0.0] + [
        1.0 - 0.01 * (0.6 * np.exp(-t / 40) + 0.4 * np.exp(-t / 400)) for t in (0.0, 40.0, 400.0)
    ]
    assert out[:, 0] == pytest.approx(expected)


def test_supply_drift_scales_every_bridge_by_one_common_gain():
    v = np.array([[1.0, -2.0, 0.5, 0.0, 3.0, -1.0]] * 3)
    times = np.array([0.0, 3600.0, 7200.0])
    out = E.SupplyDrift(gain_per_hour=1e-3, steps=((5000.0, 2e-3),)).outputs(
        v.copy(), _ctx(v, times=times)
    )
    gain = np.array([0.0, 1e-3, 2e-3 + 2e-3])
    assert out == pytest.approx(v * (1 + gain[:, None]))


def test_load_sign_bidirectional_follows_the_load_not_the_output():
    v = np.zeros((2, 6))
    loads = np.zeros((2, 6))
    loads[:, 2] = [50.0, -50.0]  # F_Z load of either sign, its bridge reading nothing
    out = E.LoadSignBidirectional(asymmetry=0.01).outputs(v.copy(), _ctx(v, loads=loads))
    assert out[:, 2] == pytest.approx([0.01 * 2.0 * 0.5] * 2)
    assert np.all(out[:, [0, 1, 3, 4, 5]] == 0)


def test_neighbour_dead_band_leaks_only_beyond_the_band():
    v = np.zeros((3, 6))
    loads = np.zeros((3, 6))
    loads[:, 0] = [30.0, -70.0, 100.0]  # 0.3, 0.7, 1.0 of capacity; band 0.4
    out = E.NeighbourDeadBand(fraction_of_rated=0.01, source=0, target=1, dead_band=0.4).outputs(
        v.copy(), _ctx(v, loads=loads)
    )
    assert out[:, 1] == pytest.approx(0.01 * 2.0 * np.array([0.0, 0.5, 1.0]))
    assert np.all(out[:, [0, 2, 3, 4, 5]] == 0)


def test_new_shapes_parse_from_a_parameter_string():
    effects = E.parse_effects(
        'creep:fraction=1e-3; supply_drift:gain_per_hour=1e-4; '
        'play_hysteresis:fraction_of_rated=3e-4'
    )
    assert [type(e).__name__ for e in effects] == ['Creep', 'SupplyDrift', 'PlayHysteresis']
    assert [e.name for e in effects] == ['creep', 'excitation', 'hysteresis']
