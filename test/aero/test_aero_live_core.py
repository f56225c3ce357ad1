"""The node's core (aero/live.py) fed message by message gives the same held points as `reduce`'s
offline run (aero/run.py), whatever order the three topics arrive in; stale inputs are dropped.
"""

from aero_cases import CALIBRATION, MODEL, readings, simulated_run
import numpy as np
import pytest

from balance_calib.aero.held_points import HoldSettings
from balance_calib.aero.live import LiveReduction
from balance_calib.aero.run import reduce_run

START_NS = 1_700_000_000 * 10**9


def feed(core, stamps, loads, attitude, q, rng):
    """Every sample's three messages in a random order, wrenches sometimes a few samples late."""
    samples, points = [], []
    delayed = []
    for i, stamp in enumerate(stamps):
        messages = [('attitude', attitude[i]), ('q', q[i])]
        rng.shuffle(messages)
        for kind, value in messages:
            out = (
                core.add_attitude(stamp, value)
                if kind == 'attitude'
                else core.add_dynamic_pressure(stamp, value)
            )
            samples += out[0]
            points += out[1]
        delayed.append((stamp, loads[i]))
        if rng.random() < 0.7:
            for s, value in delayed:
                out = core.add_wrench(s, value)
                samples += out[0]
                points += out[1]
            delayed = []
    for s, value in delayed:
        out = core.add_wrench(s, value)
        samples += out[0]
        points += out[1]
    out = core.flush(int(stamps[-1]) + 10**10)
    return samples + out[0], points + out[1]


@pytest.mark.parametrize('point_samples', [0, 30])
def test_live_points_equal_the_offline_reduction(point_samples):
    sigma = np.array([CALIBRATION.sigma_pct_fs[c] for c in CALIBRATION.components])
    profile, raw = simulated_run(noise_pct_fs=sigma, seed=5)
    loads = readings(raw)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    settings = HoldSettings(point_samples=point_samples, settle_samples=3)
    model = MODEL.with_estimated_weight()
    sigma_loads = sigma / 100 * CALIBRATION.capacity
    offline = reduce_run(
        loads, profile.support_attitude, profile.q_pa, model, settings, sigma_loads
    )
    core = LiveReduction(model, settings, sigma_loads, max_input_age_s=0.5)
    samples, points = feed(
        core, stamps, loads, profile.support_attitude, profile.q_pa, np.random.default_rng(2)
    )
    live = [p.point for p in points if not p.point.wind_off]
    assert len(live) == len(offline.wind_on) == 13
    for a, b in zip(live, offline.wind_on):
        assert np.max(np.abs(a.reduced.body - b.reduced.body)) < 1e-12
        assert np.max(np.abs(a.reduced.wind - b.reduced.wind)) < 1e-12
        assert np.max(np.abs(a.scatter_body - b.scatter_body)) < 1e-12
        assert a.samples == b.samples == (point_samples or 50 - 3)
    # every wind-on sample got its coefficients once, in stamp order
    wind_on = stamps[profile.q_pa > 0]
    assert [s.stamp_ns for s in samples] == list(wind_on)
    assert core.counters.stale == 0 and core.tracker.fits == 1


def test_samples_without_a_recent_attitude_are_dropped_as_stale():
    profile, raw = simulated_run()
    loads = readings(raw)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    core = LiveReduction(MODEL, HoldSettings(), np.ones(6), max_input_age_s=0.5)
    for i in range(300):  # q∞ keeps coming, the attitude stops after 100 samples
        core.add_dynamic_pressure(stamps[i], profile.q_pa[i])
        if i < 100:
            core.add_attitude(stamps[i], profile.support_attitude[i])
        core.add_wrench(stamps[i], loads[i])
    # the rest wait for an attitude at or after their stamp ...
    assert core.counters.samples == 100
    core.flush(int(stamps[299]) + 503 * 10**6)  # ... for match_wait_s (2 s) after they arrived:
    assert core.counters.samples == 150  # at 3.498 s, those stamped (= arrived) before 1.498 s
    core.flush(int(stamps[299]) + 3 * 10**9)
    # samples up to 0.5 s after the last attitude still use it; later ones are stale
    assert core.counters.samples == 300 and core.counters.stale == 300 - 100 - 50
    assert 'attitude older than 0.5 s' in core.counters.last_stale_reason


def test_a_point_on_demand_averages_the_next_samples_of_the_hold_or_says_why_not():
    profile, raw = simulated_run()
    loads = readings(raw)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    core = LiveReduction(MODEL, HoldSettings(), np.ones(6))

    def play(indices):
        for i in indices:
            core.add_attitude(stamps[i], profile.support_attitude[i])
            core.add_dynamic_pressure(stamps[i], profile.q_pa[i])
            core.add_wrench(stamps[i], loads[i])

    first_wind_on = int(np.flatnonzero(profile.q_pa > 0)[0])  # holds of 50 samples from here
    request = core.request_point(20)
    play(range(first_wind_on - 5))
    assert request.done and not request.success and 'wind off' in request.message
    play(range(first_wind_on - 5, first_wind_on))
    request = core.request_point(20)
    play(range(first_wind_on, first_wind_on + 10))
    assert not request.done  # 10 of 20 so far
    play(range(first_wind_on + 10, first_wind_on + 30))
    assert request.done and request.success and request.point.samples == 20
    # the point of samples 0..19 of the hold: exactly the reduction of those samples' mean
    from balance_calib.aero.coefficients import reduce_loads

    expected = reduce_loads(
        loads[first_wind_on : first_wind_on + 20].mean(axis=0),
        profile.support_attitude[first_wind_on],
        50e3,
        MODEL,
        core.tracker.tare,
    )
    assert np.allclose(request.point.reduced.body, expected.body, atol=1e-14, rtol=0)
    assert np.allclose(
        request.point.reduced.body, profile.body_coefficients[first_wind_on], atol=1e-9
    )
    request = core.request_point(30)  # 20 samples left in this hold
    play(range(first_wind_on + 30, first_wind_on + 60))
    assert request.done and not request.success and 'changed after 20 of 30' in request.message
