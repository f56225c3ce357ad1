"""The `tare` explanation: refit the calibration body's weight and centre of gravity, TM-663 §6-7.

Why it is weak: a load point and its bracketing zero points (§5(4)) carry the same body in the same
orientation, so the zero-subtracted outputs contain V(applied + body) - V(body), and the corrected
data of §7.1 add the tare outputs of the *declared* body back. For a linear balance the declared
weight cancels exactly; only the balance's nonlinearity (the interaction of the applied load with
the body's load) shows a wrong body. A +50 % weight error on LMC6522 leaves ~0.03 % FS in F_X.

The body parameters enter nonlinearly (through the tare outputs and the fitted model), so they are
found with the successive approximation of §3, eqs. (20)-(28) (`fit.gauss_newton`), around an
inner linear least-squares fit of the coefficients (variable projection).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from ..config import CalibrationBody
from ..fit.gauss_newton import gauss_newton
from ..fit.svd import singular_values
from ..model.balance_model import BalanceModel
from ..model.inverse import InverseDidNotConverge, linear_part, outputs_for_loads
from ..tare.calibration_body import CorrectedData, tare_loads

# parameter -> (how a scaled unknown x maps to the body, a readable name)
BODY_PARAMETERS = ('weight_n', 'cg_x_m', 'cg_y_m', 'cg_z_m')
CG_SCALE_M = 0.01  # x = 1 moves the CG by 1 cm
FINITE_STEP = 1e-3  # forward-difference step in the scaled unknowns


def body_from_unknowns(
    declared: CalibrationBody, parameters: Sequence[str], unknowns
) -> CalibrationBody:
    weight = declared.weight_n
    cg = list(declared.cg_m)
    for name, x in zip(parameters, unknowns):
        if name == 'weight_n':
            weight = declared.weight_n * (1.0 + x)
        else:
            cg['xyz'.index(name[3])] += CG_SCALE_M * x
    return replace(
        declared, weight_n=float(weight), cg_m=(float(cg[0]), float(cg[1]), float(cg[2]))
    )


class TareOutputChange:
    """Tare outputs as they would be with another body, through the fitted model's inverse.

    Only the change is added to the reduction's tare outputs, so whatever way the reduction made
    them (eqs. (32)-(37) or a model's inverse) is kept. The tare depends on the orientation only:
    the inverse runs once per distinct gravity direction.
    """

    def __init__(self, corrected: CorrectedData, gravity: np.ndarray, inverse_model: BalanceModel):
        self.corrected = corrected
        self.gravity = np.asarray(gravity, dtype=float)
        _, first, self.index = np.unique(
            np.round(self.gravity, 9), axis=0, return_index=True, return_inverse=True
        )
        self.index = np.ravel(self.index)
        self.unique_gravity = self.gravity[first]
        self.inverse_model = inverse_model
        self.old_outputs = self._outputs(corrected.tare_loads[first])

    def _outputs(self, loads):
        try:
            return outputs_for_loads(self.inverse_model, loads)
        except (InverseDidNotConverge, np.linalg.LinAlgError):
            return loads @ np.linalg.inv(linear_part(self.inverse_model)).T

    def __call__(self, body: CalibrationBody) -> CorrectedData:
        """The corrected data of §7.1 with `body` instead of the one the reduction used."""
        new_tare = tare_loads(body, self.gravity)
        delta = (self._outputs(tare_loads(body, self.unique_gravity)) - self.old_outputs)[
            self.index
        ]
        return self.corrected.with_tare_changed(new_tare - self.corrected.tare_loads, delta)


@dataclass(frozen=True)
class BodyRefit:
    body: CalibrationBody
    corrected: CorrectedData
    unknowns: np.ndarray
    identifiable: int  # numerical rank of the Jacobian: parameters the data determine
    converged: bool


def refit_body(
    corrected: CorrectedData,
    gravity: np.ndarray,
    declared: CalibrationBody,
    inverse_model: BalanceModel,
    weighted_residuals: Callable[[CorrectedData], np.ndarray],
    parameters: Sequence[str] = ('weight_n', 'cg_x_m'),
    max_iterations: int = 4,
) -> BodyRefit:
    """Body parameters minimising the weighted residuals of the current model, eqs. (20)-(28).

    weighted_residuals(corrected data) -> (M,) stacked residuals of all components, each divided
    by its σ, after refitting the coefficients (the inner linear problem). The residuals are
    close to linear in the body parameters, so the derivatives of eqs. (21)-(26) are taken once,
    by forward differences at the declared body, and kept (a chord iteration): each step then
    costs one refit.
    """
    parameters = tuple(parameters)
    unknown_names = [p for p in parameters if p in BODY_PARAMETERS]
    with_body = TareOutputChange(corrected, gravity, inverse_model)

    def data(x):
        return with_body(body_from_unknowns(declared, unknown_names, x))

    def residual(x):
        return weighted_residuals(data(x))

    start = np.zeros(len(unknown_names))
    at_start = residual(start)
    columns = []
    for i in range(len(start)):
        step = np.zeros(len(start))
        step[i] = FINITE_STEP
        columns.append(-(residual(step) - at_start) / FINITE_STEP)  # d model / d x
    chord = np.column_stack(columns) if columns else np.zeros((len(at_start), 0))
    first = [True]

    def residual_cached(x):
        if first[0] and not np.any(x):
            first[0] = False
            return at_start
        return residual(x)

    result = gauss_newton(
        residual_cached, lambda x: chord, start, max_iterations=max_iterations, relative_step=1e-3
    )
    unknowns = result.parameters
    if result.objective > float(np.sum(at_start**2)):
        unknowns = start  # never worse than the body we were given
    singular = singular_values(chord)
    identifiable = int(np.sum(singular > 1e-6 * max(singular[0], 1e-300))) if singular.size else 0
    return BodyRefit(
        body_from_unknowns(declared, unknown_names, unknowns),
        data(unknowns),
        unknowns,
        identifiable,
        bool(result.converged),
    )
