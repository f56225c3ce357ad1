"""refit/bag_points.read_bag_points: a recorded campaign's corrected points, the ones the refit's
fits start from (cut, zero points, calibration-body tare), with what only a bag has beside them;
and export-table, which reads nothing else (no fit of the calibration, no gate, no report).
"""

import numpy as np
import pytest

from balance_calib.bags.reader import read_bags
from balance_calib.benchmarks.refit_reliability import (
    _copy_events,
    campaign_events,
    LOAD,
    small_campaign,
    write_mcap,
)
from balance_calib.calibrate.from_bags import RefitSettings, run_refit
from balance_calib.calibration_settings import CalibrationSettings
from balance_calib.cli import main
from balance_calib.config import load_balance_config
from balance_calib.reduction import reduce_points
from balance_calib.refit.bag_points import BagReading, read_bag_points
from balance_calib.refit.load_points import cut_load_points
from balance_calib.refit.pipeline import calibrate_points, RefitError
from balance_calib.tables.balfit_reader import read_table


def _cut(bag, config):
    data = read_bags([bag], required=('raw', 'applied_load', 'gravity'))
    return cut_load_points(data, config, source=str(bag))


def test_the_reader_gives_the_points_the_refit_fits(campaigns):
    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=11, recipe='bag')
    load_points, cut = _cut(bag, config)
    refit = calibrate_points(
        load_points, config, cut=cut, settings=CalibrationSettings(diagnose=False, force=True)
    )
    final = refit.reduction.corrected  # after the refit's tare through its fitted cubic

    points = read_bag_points([bag], config, BagReading(tare_model='cubic'))
    assert points.points == len(final.loads) == refit.report['points']
    np.testing.assert_allclose(points.applied_loads, final.loads, rtol=0, atol=1e-12)
    np.testing.assert_allclose(points.outputs, final.bridge_outputs_mv, rtol=0, atol=1e-12)
    assert points.load_symbols == tuple(config.components)
    assert points.output_symbols == tuple(config.bridge_outputs)
    assert np.all(points.series == 1)

    # without the model's tare: the linear eqs. (32)-(37), as reduce_points gives them
    linear = read_bag_points([bag], config)
    first = reduce_points(load_points, config).corrected
    np.testing.assert_allclose(linear.applied_loads, first.loads, rtol=0, atol=1e-12)
    np.testing.assert_allclose(linear.outputs, first.bridge_outputs_mv, rtol=0, atol=1e-12)


def test_the_bag_only_fields_ride_along(campaigns):
    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=11, recipe='bag')
    load_points, cut = _cut(bag, config)
    points = read_bag_points([bag], config)
    record = points.bag
    assert record is not None and record.config is config
    assert record.cut == cut
    assert record.files == (str(bag),)
    np.testing.assert_array_equal(record.orientation, load_points.orientation)
    np.testing.assert_array_equal(record.load_points.outputs_mv, load_points.outputs_mv)
    assert record.integrity is not None and record.integrity['salvaged'] is False
    assert record.integrity['messages_read']['/calibration/applied_load'] > 0
    assert record.clock is not None  # a simulated campaign says so
    np.testing.assert_array_equal(points.gravity, record.reduction.points.gravity)


def test_export_table_needs_no_gate(tmp_path):
    """A campaign the refit refuses by an acceptance gate (one weight 10 % wrong: the capacity
    gate) is still exported, as read: the reader runs no gate.
    """
    campaign = small_campaign('lmc6522', seed=3)
    events = _copy_events(tuple(campaign_events(campaign)))
    capacity = load_balance_config('lmc6522').capacity
    loads = [i for i, e in enumerate(events) if e.topic == LOAD and not np.all(np.isnan(e.values))]
    which = int(np.argmax([np.max(np.abs(events[i].values) / capacity) for i in loads]))
    component = int(np.argmax(np.abs(events[loads[which]].values) / capacity))
    events[loads[which]].values[component] *= 1.1
    bag = write_mcap(events, tmp_path / 'campaign.mcap')
    with pytest.raises(RefitError, match='refused by acceptance gate'):
        run_refit([bag], 'lmc6522', tmp_path / 'refit', RefitSettings(diagnose=False, plots=False))
    out = tmp_path / 'campaign.csv'
    assert main(['export-table', str(bag), '--balance', 'lmc6522', '--out', str(out)]) == 0
    config = load_balance_config('lmc6522')
    points = read_bag_points([bag], config, BagReading(tare_model='cubic'))
    table = read_table(out)
    assert table.points == points.points
    np.testing.assert_allclose(table.applied_loads_si, points.applied_loads, rtol=1e-6)


def test_too_few_points_are_refused_by_name(campaigns):
    bag = campaigns.bag(points=slice(0, 8))
    with pytest.raises(RefitError, match='far too few'):
        read_bag_points([bag], load_balance_config('lmc6522'))
