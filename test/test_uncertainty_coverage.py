"""The standard uncertainty of each load covers the true error: on points from the schedule's
support and on points with six loads at once (outside it), |predicted - true| <= 1.96 u in 93-97 %
of samples, and u grows outside the support instead of quoting the in-sample σ."""
import numpy as np
import pytest

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.fit.iterative import iterative_point_uncertainty
from balance_calib.fit.series_tares import direct_point_uncertainty
from balance_calib.model.uncertainty import load_standard_uncertainty
from balance_calib.tables import synthetic as sy
from balance_calib.tables.calibrate import calibrate_table

OUTPUT_NOISE_MV = 0.0006


def _coverage(error, u):
    return float(np.mean(np.abs(error) <= 1.96 * u))


@pytest.fixture(scope='module')
def iterative_fit():
    rng = np.random.default_rng(4242)
    truth = sy.iterative_truth(rng)
    schedule = sy.support_schedule(rng, 21, 70)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.iterative_campaign(rng, truth, schedule, tares, OUTPUT_NOISE_MV)
    result = calibrate_table(sy.make_table(applied, outputs, schedule.series), method='iterative',
                             statistics=False)
    return rng, truth, tares, result


def _new_points(rng, truth, tares, applied):
    """Fresh measurements: outputs of the true total loads plus output noise, in random calibration series."""
    labels = np.array(sorted(tares))
    series = rng.choice(labels, len(applied))
    totals = applied + np.array([tares[int(s)] for s in series])
    outputs = truth.outputs(totals) + rng.normal(0, OUTPUT_NOISE_MV, totals.shape)
    return series, totals, outputs


def test_iterative_uncertainty_covers_inside_and_outside_the_support(iterative_fit):
    rng, truth, tares, result = iterative_fit
    fit = result.fits['iterative']
    inside = sy.support_schedule(rng, 21, 100).applied_si
    outside = sy.six_at_once(rng, 1600)
    means = {}
    for name, applied in (('inside', inside), ('outside', outside)):
        series, _, outputs = _new_points(rng, truth, tares, applied)
        u = iterative_point_uncertainty(fit, outputs, series)
        error = fit.predict_applied(outputs, series) - applied
        coverage = _coverage(error, u)
        assert 0.93 <= coverage <= 0.97, (name, coverage)
        means[name] = np.mean(u / sy.capacity_si())
    assert means['outside'] > 1.05 * means['inside']      # the design-row covariance grows off the support


def test_live_uncertainty_from_calibration_yaml_covers_six_loads_at_once(iterative_fit, tmp_path):
    """What the live node publishes: total loads from outputs, u from the covariance in calibration.yaml."""
    rng, truth, tares, result = iterative_fit
    save_calibration(tmp_path / 'calibration.yaml', result.calibration)
    calibration = load_calibration(tmp_path / 'calibration.yaml')
    for applied in (sy.support_schedule(rng, 21, 100).applied_si, sy.six_at_once(rng, 1600)):
        _, totals, outputs = _new_points(rng, truth, tares, applied)
        u = load_standard_uncertainty(calibration, outputs)
        error = calibration.model().loads(outputs) - totals
        assert 0.93 <= _coverage(error, u) <= 0.97
    assert np.all(np.isnan(load_standard_uncertainty(calibration, np.full((1, 6), np.nan))))


def test_direct_prediction_interval_covers_new_observations_inside_and_outside(tmp_path):
    rng = np.random.default_rng(77)
    truth = sy.direct_truth(rng, nonlinear_fraction=0.02)
    noise = 0.0002 * sy.capacity_si()
    schedule = sy.support_schedule(rng, 21, 60)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.direct_campaign(rng, truth, schedule, tares, noise)
    fit = calibrate_table(sy.make_table(applied, outputs, schedule.series), method='direct',
                          statistics=False).fits['direct']
    means = {}
    for name, points in (('inside', sy.support_schedule(rng, 21, 100).applied_si), ('outside', sy.six_at_once(rng, 1600))):
        series = rng.choice(np.array(sorted(tares)), len(points))
        new = sy.Schedule(points, series)
        recorded, new_outputs = sy.direct_campaign(rng, truth, new, tares, noise)
        u = direct_point_uncertainty(fit, new_outputs, series)
        coverage = _coverage(fit.predict_applied(new_outputs, series) - recorded, u)
        assert 0.93 <= coverage <= 0.97, (name, coverage)
        means[name] = np.mean(u / sy.capacity_si())
    assert means['outside'] > means['inside']
