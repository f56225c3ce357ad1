"""Cross-validated residuals of a linear-in-coefficients fit: PRESS, leave-one-point-out.

For least squares the residual of point i when it is left out of the fit is e_i / (1 - h_ii),
h_ii the leverage (diagonal of the hat matrix); no refits needed.
"""

from __future__ import annotations

import numpy as np


def leverages(design: np.ndarray) -> np.ndarray:
    """Diagonal of the hat matrix X (X^T X)^-1 X^T, through an orthonormal basis of X's columns."""
    scaled = design / np.maximum(np.linalg.norm(design, axis=0), 1e-300)
    u, singular, _ = np.linalg.svd(scaled, full_matrices=False)
    rank = int(np.sum(singular > singular[0] * 1e-12)) if singular.size else 0
    return np.sum(u[:, :rank] ** 2, axis=1)


def press_residuals(design: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """Leave-one-out residuals (N, k) from in-sample residuals (N, k) of a fit on `design` (N,
    p).
    """
    h = np.minimum(leverages(design), 1.0 - 1e-12)
    return residuals / (1.0 - h)[:, None]
