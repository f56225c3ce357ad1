"""Units and the component names of TM-663 (Fig. 1 / Fig. 11.1). SI on the wire: N, N·m, mV.

Lab units live only at the edges: bridge outputs recorded ratiometrically (mV/V, µV/V) become mV
with the excitation voltage they were measured at; loads are shown in lbf / in-lbf (or kgf) in
reports on request. Everything inside stays N, N·m, mV.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .array_types import FloatArray

STANDARD_GRAVITY_M_S2 = 9.80665  # kgf -> N, as interfaces.md prescribes

# Loads in balance calibration axes and the bridge outputs that measure them, in the memo's order.
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
BRIDGE_OUTPUTS = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')

# Exact by definition: 1 lb = 0.45359237 kg, 1 in = 0.0254 m.
METRE_PER_INCH = 0.0254
NEWTON_PER_LBF = 0.45359237 * STANDARD_GRAVITY_M_S2  # 4.4482216152605 N
NEWTON_METRE_PER_INCH_LBF = NEWTON_PER_LBF * METRE_PER_INCH  # 0.1129848290276167 N·m

# Display systems for loads: (force unit, moment unit, N per force unit, N·m per moment unit).
LOAD_UNIT_SYSTEMS: dict[str, tuple[str, str, float, float]] = {
    'si': ('N', 'N·m', 1.0, 1.0),
    'lbf': ('lbf', 'in-lbf', NEWTON_PER_LBF, NEWTON_METRE_PER_INCH_LBF),
    'kgf': ('kgf', 'kgf·m', STANDARD_GRAVITY_M_S2, STANDARD_GRAVITY_M_S2),
}

# Ratiometric bridge-output units -> mV per volt of excitation.
_MV_PER_UNIT_PER_VOLT = {'mV/V': 1.0, 'microV/V': 1e-3, 'µV/V': 1e-3, 'uV/V': 1e-3}


def kgf_to_newton(value_kgf: FloatArray | float) -> FloatArray | float:
    """Kgf (or kgf·m) to N (or N·m)."""
    return value_kgf * STANDARD_GRAVITY_M_S2


def is_moment(component: str) -> bool:
    """True for a moment component (M_X, M_Y, M_Z, or any name starting with M)."""
    return str(component).upper().startswith('M')


def load_unit(component: str, system: str = 'si') -> str:
    """The unit a load component is shown in: N / N·m, lbf / in-lbf or kgf / kgf·m."""
    force, moment, _, _ = _system(system)
    return moment if is_moment(component) else force


def loads_to_display(
    values_si: ArrayLike, components: Sequence[str], system: str = 'si'
) -> FloatArray:
    """Loads (…, n_components) in N / N·m to the display system (lbf and in-lbf for 'lbf')."""
    _, _, per_force, per_moment = _system(system)
    factors = np.array(
        [per_moment if is_moment(c) else per_force for c in components], dtype=np.float64
    )
    return np.asarray(values_si, dtype=np.float64) / factors


def ratiometric_to_mv(values: ArrayLike, unit: str, excitation_v: ArrayLike) -> FloatArray:
    """Bridge outputs recorded ratiometrically (mV/V or µV/V) to mV at the given excitation.

    excitation_v is the bridge supply in volts: a scalar, or an array broadcasting against values
    (one per sample when the lab measures it). A missing, zero, negative or NaN excitation raises
    ValueError naming it: NaN never becomes a number.
    """
    try:
        per_volt = _MV_PER_UNIT_PER_VOLT[unit]
    except KeyError:
        raise ValueError(
            f'bridge output unit {unit!r}: expected one of {", ".join(_MV_PER_UNIT_PER_VOLT)}'
        ) from None
    excitation = np.asarray(excitation_v, dtype=np.float64)
    if excitation.size == 0 or not np.all(np.isfinite(excitation)) or np.any(excitation <= 0.0):
        raise ValueError(
            f'excitation voltage {excitation_v!r}: must be a positive number of volts '
            f'to convert {unit} to mV'
        )
    return np.asarray(values, dtype=np.float64) * per_volt * excitation


def implied_excitation_v(
    rated_output_mv: ArrayLike, rated_output_microstrain: ArrayLike, gauge_factor: float = 2.0
) -> float | None:
    """Excitation implied by a table giving rated outputs both in mV and in µst (TM-663 Tables 3,
    6).

    A strain meter reads µst = 4·V_out / (K·E) for a bridge (K the gauge factor it is set to), so
    E = 4·V_out / (K·µst). The median over the bridges; None if the table lacks either row.
    """
    try:
        mv = np.asarray(rated_output_mv, dtype=float)
        strain = np.asarray(rated_output_microstrain, dtype=float) * 1e-6
    except (TypeError, ValueError):
        return None
    if mv.shape != strain.shape or mv.size == 0 or not np.all(strain > 0):
        return None
    return float(np.median(4.0 * mv * 1e-3 / (gauge_factor * strain)))


def _system(system: str) -> tuple[str, str, float, float]:
    try:
        return LOAD_UNIT_SYSTEMS[str(system).lower()]
    except KeyError:
        raise ValueError(
            f'load units {system!r}: expected one of {", ".join(LOAD_UNIT_SYSTEMS)}'
        ) from None
