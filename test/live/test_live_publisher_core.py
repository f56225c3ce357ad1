"""What bridge_publisher plays, without ROS: campaign timelines, wind-on profiles, point
selection.
"""

import numpy as np
import pytest

from balance_calib.config import load_balance_config
from balance_calib.simulation import timeline as tl
from balance_calib.simulation.balance_sim import simulate_campaign, SimulationSettings
from balance_calib.simulation.wind_on import (
    AeroModel,
    aoa_sweep_profile,
    csv_profile,
    sweep_loads_tunnel,
    wind_on_outputs,
)
from balance_calib.tunnel_axes import INVERTED, UPRIGHT

CONFIG = load_balance_config('lmc6522')


@pytest.fixture(scope='module')
def campaign():
    schedule = tl.select_points(CONFIG.schedule, '1-40')
    settings = SimulationSettings(
        samples_per_point=20,
        sample_rate_hz=200.0,
        point_duration_s=0.1,
        transition_s=0.03,
        transition_samples=6,
        noise_sigma_pct_fs=0.02,
        seed=3,
    )
    return simulate_campaign(CONFIG, schedule=schedule, settings=settings)


def test_campaign_timeline_puts_each_points_samples_after_its_applied_load(campaign):
    """interfaces.md: a point's samples are the raw messages from its applied_load to the next
    applied_load.
    """
    timeline = tl.campaign_timeline(campaign, transition_s=0.03, temperature_every=10)
    assert np.all(np.diff(timeline.times_s) >= 0)
    kinds, values = timeline.kinds, timeline.values
    applied = np.flatnonzero(kinds == tl.APPLIED_LOAD)
    settled = applied[~np.isnan(values[applied, 0])]
    # one NaN before every point
    assert len(settled) == len(campaign.point) == 40 and len(applied) == 80
    np.testing.assert_array_equal(values[settled], campaign.applied_loads)
    raw_index = np.cumsum(kinds == tl.RAW) - 1  # which campaign sample each event follows
    bounds = np.append(applied, len(kinds))
    for k, start in enumerate(applied):
        between = np.flatnonzero(kinds[start : bounds[k + 1]] == tl.RAW) + start
        expected_point = -1 if np.isnan(values[start, 0]) else np.searchsorted(settled, start)
        assert np.all(campaign.sample_point[raw_index[between]] == expected_point)
    assert timeline.count(tl.RAW) == len(campaign.times_s) == 40 * 26


def test_gravity_is_published_before_the_points_of_each_orientation(campaign):
    timeline = tl.campaign_timeline(campaign, transition_s=0.03)
    gravity = np.flatnonzero(timeline.kinds == tl.GRAVITY)
    changes = 1 + np.count_nonzero(np.diff(campaign.orientation))
    assert len(gravity) == changes >= 2
    settled = np.flatnonzero(
        (timeline.kinds == tl.APPLIED_LOAD) & ~np.isnan(timeline.values[:, 0])
    )
    for index in gravity:
        point = np.searchsorted(settled, index)  # the first point after the rotation
        np.testing.assert_allclose(
            timeline.values[index, :3], CONFIG.gravity(campaign.orientation[point])
        )
        assert point == 0 or campaign.orientation[point] != campaign.orientation[point - 1]


def test_point_selection_uses_the_printed_point_numbers():
    subset = tl.select_points(CONFIG.schedule, '5-7, 100')
    assert subset.point.tolist() == [5, 6, 7, 100]
    assert len(tl.select_points(CONFIG.schedule, '')) == 328
    with pytest.raises(ValueError, match='not a point number'):
        tl.select_points(CONFIG.schedule, '1-x')
    with pytest.raises(ValueError, match='no point'):
        tl.select_points(CONFIG.schedule, '9000-9001')


def test_sweep_has_the_aero_shape_and_stays_at_half_capacity():
    alphas = np.arange(-2.0, 23.0, 2.0)
    coefficients = AeroModel().coefficients(alphas)
    lift_slope = np.gradient(coefficients[:, 2], np.radians(alphas))
    assert lift_slope[1] == pytest.approx(0.7 * 2 * np.pi, rel=0.05)  # linear range near α = 0
    assert lift_slope[-1] < 0.5 * lift_slope[1]  # limited near 22°
    loads = sweep_loads_tunnel(alphas, CONFIG.capacity)
    peak = np.max(np.abs(loads), axis=0) / CONFIG.capacity
    np.testing.assert_allclose(peak, [0.5, 0.05, 0.5, 0.05, 0.5, 0.05])


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_wind_on_outputs_read_back_as_the_profile_loads(installation):
    profile = aoa_sweep_profile(
        CONFIG.capacity,
        installation,
        50.0,
        alphas_deg=[0.0, 10.0, 20.0],
        hold_s=0.2,
        wind_off_s=0.1,
        model_weight_n=0.0,
    )
    assert profile.label[0] == 'wind off' and np.all(
        profile.aero_tunnel[profile.condition == 0] == 0
    )
    assert len(profile.times_s) == 5 + 3 * 10
    np.testing.assert_allclose(
        profile.loads_balance, installation.from_tunnel(profile.aero_tunnel)
    )
    truth = CONFIG.matrices['cubic']
    raw = wind_on_outputs(truth, profile.loads_balance, electrical_zero_mv=0.04, noise_mv=0.0)
    read = truth.without_constant().loads(raw - 0.04)
    np.testing.assert_allclose(
        read / CONFIG.capacity, profile.loads_balance / CONFIG.capacity, atol=1e-9
    )


def test_load_csv_is_interpolated_and_its_errors_name_the_line(tmp_path):
    good = tmp_path / 'loads.csv'
    good.write_text('time_s,FX,FY,FZ,MX,MY,MZ\n0,0,0,0,0,0,0\n1,10,0,100,0,0,0\n')
    profile = csv_profile(good, UPRIGHT, 10.0)
    assert len(profile.times_s) == 10
    np.testing.assert_allclose(profile.loads_balance[:, 2], 100 * profile.times_s)
    np.testing.assert_allclose(profile.aero_tunnel[:, 2], -100 * profile.times_s)  # F_Z = -F_Z̄
    bad = tmp_path / 'bad.csv'
    bad.write_text('time_s,FX,FY,FZ,MX,MY,MZ\n0,0,0,0,0,0,0\n1,ten,0,0,0,0,0\n')
    with pytest.raises(ValueError, match='bad.csv: line 3'):
        csv_profile(bad, UPRIGHT, 10.0)
