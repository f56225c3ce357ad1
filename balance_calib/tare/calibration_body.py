"""The calibration body's own weight (風袋), TM-663 §6 and §7.1.

- Weight and centre of gravity from the outputs at two opposite orientations through the linear
  matrix, eqs. (29)-(31) (Tables 4/5 and 7/8), generalised to any set of opposite pairs.
- Tare loads for any gravity direction, Tables 9 and 13.
- Tare outputs from the inverse linear model loads -> outputs, eqs. (32)-(37) with the constants
  C'1, C'8, ... set to zero.
- The corrected data of §7.1: applied + tare loads against zero-subtracted + tare outputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..config import CalibrationBody
from ..fit.least_squares import fit_model
from ..fit.svd import minimum_norm_solve
from ..model.balance_model import BalanceModel
from ..model.inverse import linear_part
from ..model.terms import parse_terms
from ..units import BRIDGE_OUTPUTS, COMPONENTS


def body_loads_from_rotation(
    linear_model: BalanceModel, output_difference_mv: ArrayLike
) -> np.ndarray:
    """Loads of the body, ½ C ΔV, from the output difference between two opposite orientations.

    Eqs. (29)-(31) are the F_Z, M_X and M_Y rows of this product (C16-C21, C23-C28, C30-C35 of
    Table 10 / 14); the other rows are returned too. ΔV = V(orientation) - V(opposite), mV.
    """
    half_c_dv: np.ndarray = (
        0.5 * linear_part(linear_model) @ np.asarray(output_difference_mv, dtype=float)
    )
    return half_c_dv


def tare_loads(
    body: CalibrationBody,
    gravity_unit: ArrayLike,
    *,
    axial_jig: bool = False,
    axial_jig_sign: ArrayLike = 1.0,
) -> np.ndarray:
    """Loads of the body's weight for gravity direction(s) g (unit vector(s), balance axes).

    Force W·g at the centre of gravity r: F = W g, M = r x F (Table 9 / 13: for I_g = 2,
    F_Z = W and M_Y = -x_cg W). With axial_jig the F_X jig weight (±2.94 N in the tables) is added
    with the given sign. Returns (6,) or (N, 6).
    """
    gravity = np.asarray(gravity_unit, dtype=float)
    single = gravity.ndim == 1
    gravity = np.atleast_2d(gravity)
    force = body.weight_n * gravity
    moment = np.cross(np.asarray(body.cg_m, dtype=float), force)
    loads = np.hstack([force, moment])
    if axial_jig:
        loads[:, 0] += body.axial_jig_weight_n * np.broadcast_to(
            np.asarray(axial_jig_sign, float), (len(loads),)
        )
    return loads[0] if single else loads


@dataclass(frozen=True)
class BodyEstimate:
    """Weight and CG of the calibration body estimated from zero points, with what it rests on."""

    weight_n: float
    cg_m: tuple[float, float, float]
    pairs: int  # opposite orientation pairs used
    moment_residual_nm: float  # RMS misfit of M = r x F over the pairs

    def as_body(self, axial_jig_weight_n: float = 0.0) -> CalibrationBody:
        return CalibrationBody(self.weight_n, self.cg_m, axial_jig_weight_n)


def estimate_body(
    linear_model: BalanceModel, gravity_units: ArrayLike, output_differences_mv: ArrayLike
) -> BodyEstimate:
    """Weight and CG from zero-point output differences at opposite orientations.

    Each pair k: ΔV_k = V(g_k) - V(-g_k); ½ C ΔV_k = (W g_k, r x W g_k) (eqs. (29)-(31)). W is the
    mean projection of the force on g; r solves M_k = -(F_k x) r in least squares over all pairs.
    With only the F_Z pair (the memo's case) x_cg and y_cg are found and z_cg is left at 0.
    """
    gravity = np.atleast_2d(np.asarray(gravity_units, dtype=float))
    differences = np.atleast_2d(np.asarray(output_differences_mv, dtype=float))
    half = differences @ (0.5 * linear_part(linear_model)).T  # (K, 6)
    forces, moments = half[:, :3], half[:, 3:]
    weight = float(np.mean(np.einsum('ij,ij->i', forces, gravity)))
    # r x F = -F x r = -[F]x r  ->  stack the 3x3 skew matrices
    rows = []
    for force in weight * gravity:
        fx, fy, fz = force
        rows.append(-np.array([[0, -fz, fy], [fz, 0, -fx], [-fy, fx, 0]]))
    system = np.vstack(rows)
    target = moments.reshape(-1)
    cg = minimum_norm_solve(system, target, rcond=1e-10).solution  # unobservable axes stay 0
    residual = float(np.sqrt(np.mean((system @ cg - target) ** 2))) if target.size else 0.0
    return BodyEstimate(weight, (float(cg[0]), float(cg[1]), float(cg[2])), len(gravity), residual)


def fit_inverse_linear(
    bridge_outputs_mv: ArrayLike,
    loads: ArrayLike,
    components: Sequence[str] = COMPONENTS,
    outputs: Sequence[str] = BRIDGE_OUTPUTS,
) -> BalanceModel:
    """The linear model outputs = C'(1, loads), eqs. (32)-(37), fitted by least squares."""
    terms = parse_terms(['1'] + list(components))
    result = fit_model(
        terms,
        loads,
        bridge_outputs_mv,
        name='inverse linear (eqs. 32-37)',
        components=tuple(outputs),
        inputs=tuple(components),
        on_unexcited='drop',
    )
    return result.model


def tare_outputs(inverse_linear: BalanceModel, tare_loads_n: ArrayLike) -> np.ndarray:
    """Outputs of the tare loads, eqs. (32)-(37) with C'1 = C'8 = ... = 0."""
    return inverse_linear.without_constant().loads(tare_loads_n)


@dataclass(frozen=True)
class CorrectedData:
    """§7.1 修正データ: the total load on the balance and the outputs that belong to it."""

    loads: np.ndarray  # (N, 6) applied + tare, N and N·m
    bridge_outputs_mv: np.ndarray  # (N, 6) zero-subtracted + tare outputs, mV
    tare_loads: np.ndarray  # (N, 6)
    tare_outputs_mv: np.ndarray  # (N, 6)

    def with_tare_changed(
        self, load_change: ArrayLike, output_change_mv: ArrayLike
    ) -> 'CorrectedData':
        """The same points with the tare loads and tare outputs moved by (N, 6) changes: the
        totals move with them (another body, or its outputs read through another model).
        """
        return CorrectedData(
            self.loads + load_change,
            self.bridge_outputs_mv + output_change_mv,
            self.tare_loads + load_change,
            self.tare_outputs_mv + output_change_mv,
        )


def corrected_data(
    applied_loads: ArrayLike,
    zeroed_outputs_mv: ArrayLike,
    tare_loads_n: ArrayLike,
    tare_outputs_mv: ArrayLike,
) -> CorrectedData:
    applied = np.asarray(applied_loads, float)
    zeroed = np.asarray(zeroed_outputs_mv, float)
    return CorrectedData(
        applied + tare_loads_n,
        zeroed + tare_outputs_mv,
        np.asarray(tare_loads_n, float),
        np.asarray(tare_outputs_mv, float),
    )
