"""The memo's LMC6522 for the live calibrator's tests (test_live_*.py, test_sample_kernel,
test_ros_calibrator*.py): its figures, a run of zero, wind-off and wind-on outputs with a model
weight, windows fed to LiveCalibrator, and calibrations for special cases (a coefficient
covariance, a temperature term, eight outputs).
"""

import numpy as np

from balance_calib.calibration_file import Calibration, load_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.model.balance_model import BalanceModel
from balance_calib.model.terms import parse_terms
from balance_calib.simulation.balance_sim import noise_mv_for_load_sigma
from balance_calib.simulation.wind_on import aoa_sweep_profile, wind_on_outputs
from balance_calib.tables import synthetic as sy

MEMO = load_calibration(CONFIG_DIR / 'lmc6522.yaml')
CAPACITY = MEMO.capacity
TRUTH = MEMO.model('cubic')
ELECTRICAL_ZERO_MV = np.array([0.04, -0.03, 0.05, 0.02, -0.01, 0.03])
# 0.03 % FS per sample
NOISE_MV = noise_mv_for_load_sigma(TRUTH.without_constant(), CAPACITY, 0.03)


def model_weight_tunnel() -> np.ndarray:
    """The Show case: a model whose weight puts 0.3 FS on F_Z and 0.05 FS on M_Y (tunnel axes)."""
    weight = np.zeros(6)
    weight[2], weight[4] = -0.3 * CAPACITY[2], 0.05 * CAPACITY[4]
    return weight


def show_run(installation, samples_per_condition=50, seed=0):
    """Raw outputs of a run on the memo's cubic balance as the truth: nothing on the balance (for
    ~/zero), the model wind-off (for ~/tare), then the wind-on conditions of an α sweep whose loads
    stay within the schedule's support (≤ 0.5 FS). Returns (zero, wind_off, wind_on (C, S, 6),
    aerodynamic loads (C, 6) tunnel axes).
    """
    rng = np.random.default_rng(seed)
    profile = aoa_sweep_profile(CAPACITY, installation, 100.0, hold_s=0.01, wind_off_s=0.0)
    aero = profile.aero_tunnel[np.unique(profile.condition, return_index=True)[1]][1:]
    weight = model_weight_tunnel()

    def outputs(loads_tunnel, n):
        clean = wind_on_outputs(
            TRUTH,
            installation.from_tunnel(np.atleast_2d(loads_tunnel)),
            electrical_zero_mv=ELECTRICAL_ZERO_MV,
        )
        return clean[:, None, :] + rng.normal(0.0, NOISE_MV, (len(clean), n, 6))

    return (
        outputs(np.zeros(6), 100)[0],
        outputs(weight, 100)[0],
        outputs(aero + weight, samples_per_condition),
        aero,
    )


def take(live, kind, outputs, stamp0=0):
    live.start_window(kind, len(outputs))
    live.process(outputs, stamp0 + np.arange(1, len(outputs) + 1) * 1_000_000, now_s=0.0)
    return live.finish_window()


def calibration_with_covariance():
    """The memo's cubic model with a coefficient covariance and residual σ from 300 synthetic
    points.
    """
    from dataclasses import replace

    from balance_calib.fit.fitted_covariance import with_fitted_covariance

    rng = np.random.default_rng(11)
    outputs = rng.uniform(-1.0, 1.0, (300, 6)) * MEMO.rated_output_mv
    residuals = rng.normal(0.0, 1e-4, (300, 6)) * CAPACITY
    cubic = with_fitted_covariance(MEMO.model('cubic'), outputs, residuals)
    return replace(MEMO, models={**MEMO.models, 'cubic': cubic})


def temperature_calibration() -> Calibration:
    """The memo's linear model plus a dT term on F_Z (10 N/K), base model linear."""
    linear = MEMO.model('linear')
    terms = linear.terms + parse_terms(['dT'])
    coefficients = np.hstack([linear.coefficients, np.zeros((6, 1))])
    coefficients[2, -1] = 10.0
    augmented = BalanceModel('linear+temperature', terms, coefficients)
    return Calibration(
        'LMC6522',
        {'linear': linear, 'linear+temperature': augmented},
        'linear+temperature',
        'linear',
        MEMO.capacity,
        MEMO.rated_output_mv,
        reference_temperature_c=20.0,
    )


CHANNELS = tuple(f'E{i}' for i in range(1, 9))  # the 8-channel sensor's outputs


def eight_output_calibration() -> Calibration:
    """A linear calibration of six components from the 8 channels (coefficients arbitrary)."""
    model = BalanceModel(
        'linear', parse_terms(list(CHANNELS)), np.arange(48.0).reshape(6, 8), sy.LOADS, CHANNELS
    )
    return Calibration(
        'sensor-8',
        {'linear': model},
        'linear',
        'linear',
        sy.capacity_si(),
        np.full(8, 2.5),
        sy.LOADS,
        CHANNELS,
    )
