"""The shipped graph raises no overload during its own calibration campaign, and still raises one
beyond its limit: the core's overload check against the schedules' own loads (rated loads plus
the calibration body's weight) and against the campaign the graph's bridge_publisher plays, both
through the shipped config/graph_params.yaml.
"""

import numpy as np
import pytest
import yaml

from balance_calib.calibration_file import load_calibration
from balance_calib.config import CONFIG_DIR, load_balance_config, resolve_config_path
from balance_calib.launchless.campaign import graph_parameter
from balance_calib.live.parameters import PARAMETERS
from balance_calib.live.session import live_settings
from balance_calib.live.stream import LiveCalibrator, OverloadMonitor
from balance_calib.model.active_calibration import activate
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.nodes.bridge_publisher import PARAMETERS as PUBLISHER_DEFAULTS
from balance_calib.simulation.balance_sim import paced_settings, simulate_campaign, table17_noise
from balance_calib.tare.calibration_body import tare_loads

GRAPH = yaml.safe_load((CONFIG_DIR / 'graph_params.yaml').read_text())
PUBLISHER = {**PUBLISHER_DEFAULTS, **GRAPH['bridge_publisher']['ros__parameters']}
CALIBRATOR = GRAPH['balance_calibrator']['ros__parameters']
BALANCES = ('lmc6522', 'b660h')  # the shipped balance configs with a load schedule


def schedule_loads(config):
    """(P, 6) what the balance carries at each point: the hung loads and the body's weight."""
    gravity = np.array([config.gravity(i) for i in config.schedule.orientation])
    return np.asarray(config.schedule.loads, float) + tare_loads(config.calibration_body, gravity)


@pytest.mark.parametrize('balance', BALANCES)
def test_the_schedules_own_loads_stay_inside_the_shipped_limit(balance):
    config = load_balance_config(balance)
    capacity = np.asarray(config.capacity, float)
    loads = schedule_loads(config)
    monitor = OverloadMonitor(capacity, float(CALIBRATOR['overload_fraction']), 1.0)
    assert not monitor.update(loads, np.zeros(len(loads), bool), 0.0) and not monitor.active
    peak = np.abs(loads / capacity).max()
    # the campaign goes beyond rated (the body's weight on top of rated F_Y): 1.0 would trip
    assert 1.1 < peak < float(CALIBRATOR['overload_fraction']), peak
    assert OverloadMonitor(capacity, 1.0, 1.0).update(loads, np.zeros(len(loads), bool), 0.0)


def live_calibrator(balance, **changed):
    defaults = {name: spec.default for name, spec in PARAMETERS.items()}
    parameters = {**defaults, **CALIBRATOR, **changed}  # as the node reads the file
    calibration = load_calibration(resolve_config_path(balance))
    active = activate(
        calibration,
        parameters['model'],
        parameters['installation'],
        float(parameters['envelope_margin']),
        output_range_factor=float(parameters['output_range_factor']),
    )
    return LiveCalibrator(active, live_settings(parameters.__getitem__))


def graph_campaign(balance):
    """The campaign the shipped graph's bridge_publisher plays (its parameters, one cycle)."""
    config = load_balance_config(balance)
    noise = PUBLISHER['noise_sigma_pct_fs']
    assert noise < 0  # the file's choice: the Table 17 cubic row
    settings = paced_settings(
        PUBLISHER['rate_hz'],
        PUBLISHER['point_duration_s'],
        PUBLISHER['transition_s'],
        table17_noise(config),
        PUBLISHER['seed'],
        PUBLISHER['physical_seconds_per_point'],
    )
    return simulate_campaign(config, config.matrices[PUBLISHER['truth_model']], settings=settings)


def play(live, campaign):
    stamps = np.round(campaign.times_s * 1e9).astype(np.int64) + 10**9
    for start in range(0, len(stamps), 40):  # the node's batches
        live.process(
            campaign.raw_mv[start : start + 40],
            stamps[start : start + 40],
            now_s=float(campaign.times_s[start]),
        )
    return stamps[-1]


@pytest.mark.parametrize('balance', BALANCES)
def test_the_graphs_campaign_raises_no_overload_and_a_real_one_still_raises_it(balance):
    campaign = graph_campaign(balance)
    live = live_calibrator(balance)
    last = play(live, campaign)
    assert live.overload.events == 0 and not live.overload.active, live.overload.peak_fraction
    # the check is live: one sample 1.1 x beyond the limit on F_Z raises it
    config = load_balance_config(balance)
    beyond = np.zeros(6)
    beyond[2] = 1.1 * float(CALIBRATOR['overload_fraction']) * config.capacity[2]
    raw = outputs_for_loads(config.matrices['cubic'].without_constant(), beyond[None])
    live.process(raw, np.array([last + 5_000_000]), now_s=1e6)
    assert live.overload.active and live.overload.components == ('FZ',)
    # and the limit the graph shipped before (1 x rated) raised it during the campaign
    before = live_calibrator(balance, overload_fraction=1.0)
    play(before, campaign)
    assert before.overload.events > 0


def test_the_campaign_story_uses_the_shipped_graphs_limit():
    shipped = graph_parameter('balance_calibrator', 'overload_fraction')
    assert shipped == CALIBRATOR['overload_fraction']
