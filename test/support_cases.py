"""A calibration with a recorded support (±30 % of capacity on every component) and loads inside
and outside it, for the support-share tests with and without ROS.
"""

from dataclasses import replace

from live_cases import calibration_with_covariance, CAPACITY
import numpy as np

from balance_calib.coverage.support import ScheduleSupport
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.units import COMPONENTS

RANGE_SHARE = 0.3


def supported_calibration(leverage_max=1e12):
    calibration = calibration_with_covariance()
    support = ScheduleSupport(
        COMPONENTS,
        CAPACITY,
        -RANGE_SHARE * CAPACITY,
        RANGE_SHARE * CAPACITY,
        leverage_max,
        'cubic',
    )
    return replace(calibration, extra={'support': support.to_dict()})


def outputs_of(calibration, loads):
    return outputs_for_loads(calibration.model('cubic').without_constant(), loads)


def loads_with_some_outside(n, outside_rows, component='FZ'):
    """Loads (n, 6) at 20 % of capacity (inside); outside_rows at 50 % on one component."""
    loads = np.tile(0.2 * CAPACITY, (n, 1)) * np.where(np.arange(6) % 2, -1, 1)
    loads[outside_rows, COMPONENTS.index(component)] = 0.5 * CAPACITY[COMPONENTS.index(component)]
    return loads
