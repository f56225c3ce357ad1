"""Simulated wind-tunnel runs for the data-reduction tests (test_aero_*.py, test_coverage_design):
the LMC6522 with the memo's cubic matrix as the truth of the balance, the Euler replica model
with a known weight and centre of gravity, and a run written as a bag.
"""

import numpy as np

from balance_calib.aero.bag_io import write_run_bag
from balance_calib.aero.model_file import load_model
from balance_calib.calibration_file import load_calibration
from balance_calib.config import load_balance_config
from balance_calib.model.active_calibration import activate, six_axis_loads
from balance_calib.simulation.balance_sim import noise_mv_for_load_sigma
from balance_calib.simulation.wind_on import aero_run_profile, TunnelRun, wind_on_outputs
from balance_calib.tunnel_axes import UPRIGHT

CONFIG = load_balance_config('lmc6522')
CALIBRATION = load_calibration('lmc6522')
MODEL = load_model('euler_replica_lmc6522')
TRUE_WEIGHT_N, TRUE_CG_M = 250.0, np.array([0.015, 0.0, -0.004])
START_NS = 1_700_000_000 * 10**9


def simulated_run(
    q_pa=50e3, noise_pct_fs=0.0, seed=0, model=MODEL, rate_hz=100.0, alphas=range(-2, 23, 2)
):
    profile = aero_run_profile(
        model,
        UPRIGHT,
        TunnelRun(
            q_pa=q_pa, rate_hz=rate_hz, alphas_deg=tuple(alphas), hold_s=0.5, wind_off_hold_s=0.5
        ),
        weight_n=TRUE_WEIGHT_N,
        cg_m=TRUE_CG_M,
    )
    truth = CONFIG.matrices['cubic']
    samples_per_hold = round(0.5 * rate_hz)
    noise_mv = noise_mv_for_load_sigma(
        truth.without_constant(), CONFIG.capacity, noise_pct_fs
    ) * np.sqrt(samples_per_hold)
    raw = wind_on_outputs(
        truth, profile.loads_balance, electrical_zero_mv=0.0, noise_mv=noise_mv, seed=seed
    )
    return profile, raw


def readings(raw, model_name='cubic'):
    active = activate(CALIBRATION, model_name, UPRIGHT)
    return UPRIGHT.to_tunnel(six_axis_loads(active.model, raw))


def run_bag(path, noise_pct_fs=0.0, seed=0, drop=None, with_q=True):
    profile, raw = simulated_run(noise_pct_fs=noise_pct_fs, seed=seed)
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    keep = np.ones(len(stamps), bool) if drop is None else ~drop(profile)
    write_run_bag(
        path,
        stamps[keep],
        raw[keep],
        profile.support_attitude[keep],
        profile.q_pa[keep] if with_q else np.full(keep.sum(), np.nan),
        truth_body=profile.body_coefficients[keep],
        truth_wind=profile.wind_coefficients[keep],
    )
    return profile
