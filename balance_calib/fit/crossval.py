"""Cross-validated residuals of a linear-in-coefficients fit: PRESS, leave-one-point-out.

For least squares the residual of point i when it is left out of the fit is e_i / (1 - h_ii),
h_ii the leverage (diagonal of the hat matrix, fit/least_squares.LeastSquares.leverage); no
refits needed.
"""

from __future__ import annotations

import numpy as np

from .least_squares import scaled_least_squares

# A unit-norm column whose part not explained by the others is below this fraction counts as
# dependent (left out of the hat matrix), as the SVD rank cut this module used before did.
RANK_TOLERANCE = 1e-12


def press_residuals(design: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """Leave-one-out residuals (N, k) from in-sample residuals (N, k) of a fit on `design` (N,
    p).
    """
    design = np.asarray(design, dtype=float)
    h = scaled_least_squares(design, np.zeros(len(design)), tolerance=RANK_TOLERANCE).leverage
    h = np.minimum(h, 1.0 - 1e-12)
    return residuals / (1.0 - h)[:, None]
