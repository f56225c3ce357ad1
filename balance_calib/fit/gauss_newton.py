"""The successive approximation of TM-663 §3, eqs. (20)-(28), for models nonlinear in C.

C_j = C_j0 + ΔC_j (eq. (20)); the load error is linearised in ΔC (eqs. (21)-(26)) and the
approximate objective (27) minimised. Eq. (28) sets its gradient to zero, i.e. the normal
equations; we solve the same linearised least-squares problem by SVD instead (same minimiser,
without squaring the condition number), then iterate until the step is negligible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class GaussNewtonResult:
    parameters: np.ndarray
    iterations: int
    converged: bool
    objective: float  # eq. (19): sum of squared load errors


def gauss_newton(
    residual: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray], np.ndarray],
    initial: np.ndarray,
    *,
    max_iterations: int = 50,
    relative_step: float = 1e-12,
) -> GaussNewtonResult:
    """Minimise sum(residual(C)**2) from C0 = initial.

    residual(C) -> (M,) measured minus model (all components stacked, eq. (19));
    jacobian(C) -> (M, P) = d model / d C (the ∂F_X/∂C_j ... of eqs. (21)-(26)).
    """
    parameters = np.asarray(initial, dtype=float).copy()
    for iteration in range(1, max_iterations + 1):
        error = residual(parameters)
        step, *_ = np.linalg.lstsq(jacobian(parameters), error, rcond=None)  # ΔC of eq. (28)
        parameters = parameters + step  # eq. (20)
        if np.linalg.norm(step) <= relative_step * max(float(np.linalg.norm(parameters)), 1e-300):
            return GaussNewtonResult(
                parameters, iteration, True, float(np.sum(residual(parameters) ** 2))
            )
    return GaussNewtonResult(
        parameters, max_iterations, False, float(np.sum(residual(parameters) ** 2))
    )
