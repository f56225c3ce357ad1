"""Error propagation of §A1.4 for the measured thrust coefficient, and the firing analysis."""

import numpy as np
import pytest

from balance_calib.simulation.thrust_stand import ThrustStandSimulator
from balance_calib.thrust_stand.analysis import compare_with_theory, window_mean
from balance_calib.thrust_stand.nozzle import Nozzle
from balance_calib.thrust_stand.report import write_report
from balance_calib.thrust_stand.uncertainty import (
    measured_thrust_coefficient,
    numerical_partials,
    propagate,
    thrust_coefficient_uncertainty,
)

# a firing as a student records it: a in N/mV from §4.2, V_F from the trace, p_G from the gauge
VALUES = {
    'calibration_slope': 5.0,
    'thrust_reading': 0.52,
    'chamber_gauge_pa': 0.5e6,
    'ambient_pa': 101325.0,
    'throat_diameter_m': 2.5e-3,
}
SIGMAS = {
    'calibration_slope': 0.05,
    'thrust_reading': 0.01,
    'chamber_gauge_pa': 7.5e3,
    'ambient_pa': 50.0,
    'throat_diameter_m': 2e-5,
}


def cf_function(
    calibration_slope, thrust_reading, chamber_gauge_pa, ambient_pa, throat_diameter_m
):
    return measured_thrust_coefficient(
        calibration_slope * thrust_reading, chamber_gauge_pa, ambient_pa, throat_diameter_m
    )


def test_eq20_agrees_with_monte_carlo_within_5_percent():
    result = thrust_coefficient_uncertainty(**VALUES, sigmas=SIGMAS)
    rng = np.random.default_rng(20261124)
    draws = {
        name: value + SIGMAS[name] * rng.standard_normal(200_000) for name, value in VALUES.items()
    }
    monte_carlo = cf_function(**draws)
    assert result.value == pytest.approx(
        0.52 * 5.0 / (601325.0 * np.pi * 2.5e-3**2 / 4), rel=1e-12
    )
    assert result.sigma == pytest.approx(np.std(monte_carlo), rel=0.05)
    assert result.value == pytest.approx(np.mean(monte_carlo), rel=0.01)


def test_analytic_partials_match_numerical_ones():
    result = thrust_coefficient_uncertainty(**VALUES, sigmas=SIGMAS)
    numeric = numerical_partials(cf_function, VALUES)
    for name, derivative in numeric.items():
        assert result.partials[name] == pytest.approx(derivative, rel=1e-6)


def test_worst_case_bounds_rss_which_bounds_the_dominant_term():
    result = propagate(1.0, {'x': 2.0, 'y': -3.0, 'z': 0.5}, {'x': 0.1, 'y': 0.1, 'z': 0.0})
    assert result.worst_case == pytest.approx(0.5)  # eq. (19): 0.2 + 0.3
    assert result.sigma == pytest.approx(np.sqrt(0.13))  # eq. (20)
    assert result.dominant == pytest.approx(0.3) and result.dominant_input == 'y'  # eq. (21)
    # the manual's example: here the reading of V_F dominates the budget
    budget = thrust_coefficient_uncertainty(**VALUES, sigmas=SIGMAS)
    assert budget.dominant_input == 'thrust_reading'
    assert budget.dominant <= budget.sigma <= budget.worst_case


def test_simulated_firing_analysed_gives_efficiency_times_theory(tmp_path):
    simulator = ThrustStandSimulator(seed=5)
    start, end = simulator.firing_windows()[0]
    times = np.arange(start, end, 1e-3)
    sample = simulator.sample(times)
    thrust = simulator.calibration_slope_n_per_mv * (sample.strain_mv - simulator.zero_offset_mv)
    comparison = compare_with_theory(
        window_mean(thrust),
        window_mean(sample.chamber_gauge_pa),
        window_mean(sample.ambient_pa),
        Nozzle(),
        thrust_relative_sigma=0.01,
        throat_diameter_sigma_m=1e-5,
    )
    assert comparison.firing
    assert comparison.cf_ratio == pytest.approx(simulator.efficiency, rel=0.01)
    assert comparison.cf_measured.value == pytest.approx(simulator.firing_cf, rel=0.01)
    json_path, markdown_path = write_report(tmp_path / 'firing.json', comparison)
    assert json_path.name == 'firing.json' and markdown_path.name == 'firing.md'
    assert 'eq. (20)' in markdown_path.read_text()
