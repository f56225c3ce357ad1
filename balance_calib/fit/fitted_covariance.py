"""A fitted model's coefficient covariance from its own points, for calibration.yaml's
`metadata.uncertainty` (read back by model/uncertainty.py at run time).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from ..model.balance_model import BalanceModel
from ..model.uncertainty import with_covariance
from .svd import unscaled_covariance


def with_fitted_covariance(
    model: BalanceModel,
    bridge_outputs_mv: ArrayLike,
    residuals: ArrayLike,
    extra: Mapping[str, FloatArray] | None = None,
) -> BalanceModel:
    """A least-squares-fitted BalanceModel with `metadata.uncertainty` from its own fitted points:
    (XᵀX)⁻¹ by SVD of the unit-norm-scaled design (rank-deficient directions left out) and the
    residual σ per component with N − rank degrees of freedom. For refit's calibration.yaml.
    Returns the model with that metadata.
    """
    design = model.design(bridge_outputs_mv, extra)
    residual_rows = np.atleast_2d(np.asarray(residuals, dtype=float))
    covariance, rank = unscaled_covariance(design)
    dof = max(design.shape[0] - rank, 1)
    sigma = np.sqrt((residual_rows**2).sum(axis=0) / dof)
    return with_covariance(model, covariance, sigma, dof)
