"""balance_recorder's parameter table (parameter_table.Spec), without rclpy.

The node reads both parameters once, at start-up: they are read-only.
"""

from __future__ import annotations

from ..parameter_table import Spec, startup

# every topic of docs/interfaces.md: a calibration campaign, the live calibrator, a wind-on run
DEFAULT_TOPICS = [
    '/balance/raw',
    '/balance/temperature',
    '/calibration/applied_load',
    '/calibration/gravity',
    '/balance/wrench',
    '/balance/wrench_uncertainty',
    '/balance/overload',
    '/diagnostics',
    '/model/attitude',
    '/tunnel/dynamic_pressure',
    '/aero/coefficients',
    '/aero/wind_coefficients',
]

PARAMETERS: dict[str, Spec] = {
    'topics': startup(
        DEFAULT_TOPICS,
        "topics to record (default: every topic of "
        "docs/interfaces.md, the calibration's, the live wrench's "
        "and the wind-on run's)",
    ),
    'output': startup('', 'bag directory to create (required); it must not exist yet'),
}
