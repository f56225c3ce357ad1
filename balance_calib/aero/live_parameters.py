"""aero_coefficients' parameter table (parameter_table.Spec), without rclpy.

The node reads every parameter once, at start-up (its model, calibration σ and hold settings are
built from them): all are read-only. The ranges are those aero/held_points.HoldSettings and
aero/live.LiveReduction hold their arguments to.
"""

from __future__ import annotations

from ..parameter_table import Spec, startup

PARAMETERS: dict[str, Spec] = {
    'model': startup('euler_replica', 'the wind-tunnel model: config/models/NAME.yaml or a path'),
    'estimate_weight': startup(
        False, 'true: weight and CG from the wind-off sweep, whatever the model file says'
    ),
    'calibration_file': startup(
        'lmc6522',
        'calibration.yaml or balance config (also by name), '
        'for the calibration σ that weights the tare fit and '
        "gives the uncertainty; as the calibrator's",
    ),
    'installation': startup(
        'upright', "upright (TM-663 §10.2.1) | inverted (§10.2.2); as the calibrator's"
    ),
    'wind_off_q_pa': startup(1.0, 'q∞ below this is wind-off, Pa', 0.0),
    'attitude_tolerance_rad': startup(
        1e-4, 'a support angle moving more than this between samples starts a new hold, rad', 0.0
    ),
    'q_tolerance_pa': startup(
        1.0,
        'q∞ moving by more than max(q_tolerance_pa, '
        'q_tolerance_fraction·q∞) starts a new hold, Pa',
        0.0,
    ),
    'q_tolerance_fraction': startup(0.01, 'the relative part of that tolerance on q∞', 0.0),
    'settle_samples': startup(0, 'samples skipped at the start of each hold', 0),
    'point_samples': startup(
        0,
        '0: one point per hold at its end; N: a point of the first N '
        'settled samples, as soon as they are in',
        0,
    ),
    'min_samples': startup(5, 'a hold with fewer settled samples gives no point', 1),
    'max_input_age_s': startup(
        0.5, 'an attitude or q∞ older than this makes a wrench sample stale, s', 0.0, low_open=True
    ),
    'match_wait_s': startup(
        2.0,
        'how long a wrench sample waits for its attitude and q∞ to arrive, s',
        0.0,
        low_open=True,
    ),
    'diagnostics_period_s': startup(
        1.0, 'period of /diagnostics, s (0: as often as the executor can)', 0.0
    ),
    'take_point_samples': startup(
        100, '~/take_point: a point of the next N wind-on samples of the held attitude', 1
    ),
    'take_point_timeout_s': startup(
        30.0, '~/take_point gives up after this long, s', 0.0, low_open=True
    ),
}
