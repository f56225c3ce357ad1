"""Sting and balance deflection under load: the attitude the model really has.

The support reports its own angles; under load the sting and the balance bend, and the model sits
at support angle + deflection (interfaces.md, model file `deflection`):

    Δα = alpha_rad_per_n · F_Z̄ + alpha_rad_per_nm · M_Ȳ
    Δβ = beta_rad_per_n  · F_Ȳ + beta_rad_per_nm  · M_Z̄

with the total loads the balance carries (air loads plus weight) about the balance centre. Roll is
not changed.

The total load itself depends on the attitude wherever it is predicted rather than measured (the
simulation: air loads and weight at the deflected attitude; the wind-off fit: weight at the
deflected attitude), so `iterate_attitude` solves attitude = support + Δ(loads(attitude)) by fixed
point; with a stiff sting (|∂Δ/∂attitude| << 1) each pass gains many digits. In the wind-on
reduction the balance measures the total load directly and one pass is exact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np


class DeflectionDidNotConverge(ArithmeticError):
    pass


@dataclass(frozen=True)
class Deflection:
    alpha_rad_per_n: float = 0.0
    alpha_rad_per_nm: float = 0.0
    beta_rad_per_n: float = 0.0
    beta_rad_per_nm: float = 0.0
    KEYS: ClassVar[tuple[str, ...]] = (
        'alpha_rad_per_n',
        'alpha_rad_per_nm',
        'beta_rad_per_n',
        'beta_rad_per_nm',
    )

    @property
    def matrix(self) -> np.ndarray:
        """(3, 6): attitude change (φ, α, β) per load (F_X̄ ... M_Z̄)."""
        m = np.zeros((3, 6))
        m[1, 2], m[1, 4] = self.alpha_rad_per_n, self.alpha_rad_per_nm
        m[2, 1], m[2, 5] = self.beta_rad_per_n, self.beta_rad_per_nm
        return m

    def change(self, total_loads) -> np.ndarray:
        """Attitude change (..., 3) rad for total loads (..., 6) N, N·m about the balance
        centre.
        """
        return np.asarray(total_loads, dtype=float) @ self.matrix.T

    def corrected(self, support_attitude, total_loads) -> np.ndarray:
        """Support attitude + deflection under the measured total loads (..., 3) rad."""
        return np.asarray(support_attitude, dtype=float) + self.change(total_loads)


def iterate_attitude(
    support_attitude,
    deflection: Deflection,
    total_loads_at: Callable[[np.ndarray], np.ndarray],
    tolerance_rad: float = 1e-13,
    max_iterations: int = 100,
) -> np.ndarray:
    """Solve attitude = support + deflection(total_loads_at(attitude)) by fixed-point iteration.

    total_loads_at(attitude (..., 3)) -> loads (..., 6). Raises DeflectionDidNotConverge when the
    sting is so soft that the iteration does not contract.
    """
    support = np.asarray(support_attitude, dtype=float)
    attitude = support.copy()
    for _ in range(max_iterations):
        updated = deflection.corrected(support, total_loads_at(attitude))
        if np.max(np.abs(updated - attitude), initial=0.0) <= tolerance_rad:
            return updated
        attitude = updated
    raise DeflectionDidNotConverge(
        f'deflection did not converge in {max_iterations} iterations: '
        f'the sting is too soft for the loads (check the deflection coefficients)'
    )
