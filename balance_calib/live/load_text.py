"""The text of a load, a zero and a tare as the calibrator says them (its replies and
/diagnostics): bridge outputs with their unit, loads per component in the installation's tunnel
axes, N and N·m.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..model.active_calibration import ActiveCalibration, six_axis_loads
from ..model.inverse import InverseDidNotConverge
from ..units import BRIDGE_OUTPUTS, COMPONENTS

UNITS = ('N', 'N', 'N', 'N·m', 'N·m', 'N·m')


def output_text(value: float, active: ActiveCalibration) -> str:
    """A bridge output with its unit: mV to 5 decimals; counts, -, mV/V to 6 digits."""
    unit = active.calibration.output_unit
    return f'{value:+.5f} mV' if unit == 'mV' else f'{value:+.6g} {unit}'


def describe_loads(loads_balance: ArrayLike, active: ActiveCalibration) -> str:
    """A load (6,) in balance axes, written per component in the installation's tunnel axes."""
    tunnel = active.installation.to_tunnel(np.asarray(loads_balance, dtype=float))
    return ', '.join(f'{c}={v:+.3f} {u}' for c, v, u in zip(COMPONENTS, tunnel, UNITS))


def describe_tare(tare_load: ArrayLike, active: ActiveCalibration) -> str:
    """The tare load subtracted, N and N·m, in tunnel axes."""
    return (
        f'{describe_loads(tare_load, active)} ({active.installation.name} tunnel axes, '
        f'{active.model_name} model on the full outputs)'
    )


def describe_zero(zero_mv: ArrayLike, active: ActiveCalibration) -> str:
    """The zero subtracted, per bridge output in mV, and the load it stands for in tunnel axes."""
    zero = np.asarray(zero_mv, dtype=float)
    try:
        equivalent = (
            six_axis_loads(active.base_model, zero[None, :])[0]
            if not active.base_model.extra_variables
            else np.full(6, np.nan)
        )
    except InverseDidNotConverge:  # an iterative model without a solution there: no number
        equivalent = np.full(6, np.nan)
    names = active.calibration.bridge_outputs
    outputs = ', '.join(
        f'{c}={output_text(v, active)}'
        for c, v in zip(names, zero[[BRIDGE_OUTPUTS.index(b) for b in names]])
    )
    return (
        f'{outputs} (the load these outputs read as, {active.installation.name} tunnel axes, '
        f'{active.base_name} model: {describe_loads(equivalent, active)})'
    )
