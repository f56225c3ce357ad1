"""thrust_analyzer's parameter table (parameter_table.Spec), without rclpy.

The node reads every parameter once, at start-up: all are read-only. The nozzle's defaults are
the lab manual's (thrust_stand/nozzle.py); the ranges are those Nozzle holds its arguments to.
"""

from __future__ import annotations

from ..parameter_table import Spec, startup
from .nozzle import (
    DEFAULT_CHAMBER_K,
    DEFAULT_EXIT_DIAMETER_M,
    DEFAULT_GAMMA,
    DEFAULT_GAS_CONSTANT_J_KG_K,
    DEFAULT_THROAT_DIAMETER_M,
)

PARAMETERS: dict[str, Spec] = {
    'throat_diameter_m': startup(
        DEFAULT_THROAT_DIAMETER_M, 'nozzle throat diameter D_t, m (Fig. 4)', 0.0, low_open=True
    ),
    'exit_diameter_m': startup(
        DEFAULT_EXIT_DIAMETER_M,
        'nozzle exit diameter D_e, m (Fig. 4), not below the throat diameter',
        0.0,
        low_open=True,
    ),
    'gamma': startup(
        DEFAULT_GAMMA, 'ratio of specific heats γ of the gas (§2.1)', 1.0, low_open=True
    ),
    'gas_constant': startup(
        DEFAULT_GAS_CONSTANT_J_KG_K, 'specific gas constant R, J/(kg·K) (§2.1)', 0.0, low_open=True
    ),
    'chamber_k': startup(
        DEFAULT_CHAMBER_K,
        'chamber temperature T_c, K; it only enters m_dot, u_e, C* and I_sp of the report',
        0.0,
        low_open=True,
    ),
    'window_s': startup(
        1.0,
        'each signal is averaged over the last this many seconds (arrival '
        "time on the node's clock)",
        0.0,
        low_open=True,
    ),
    'publish_period_s': startup(0.5, 'period of /diagnostics, s', 0.0, low_open=True),
    'stale_after_s': startup(2.0, 'an input silent this long is STALE, s', 0.0, low_open=True),
    'thrust_relative_sigma': startup(0.01, 'σ of the calibration constant a, relative'),
    'throat_diameter_sigma_m': startup(1e-5, 'σ of the throat diameter, m'),
    'report_path': startup(
        '',
        "'' = none; else on shutdown, and when the std_srvs/Trigger "
        'service ~/report is called, write <report_path>.json and '
        "<report_path>.md (a '.json' or '.md' suffix is replaced) "
        'comparing the last firing (the last window whose throat was '
        'choked; the last window if none was)',
    ),
}
