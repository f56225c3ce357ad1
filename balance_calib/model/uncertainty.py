"""The standard uncertainty (k = 1, GUM) of each calibrated load, sample by sample.

For a direct (TM-663) model L = C·x(V), component k:

    u_k² = σ_k² · (1 + x (XᵀX)⁻¹ xᵀ)  [+ u_tare,k²]

x (XᵀX)⁻¹ xᵀ is the full design-row prediction variance of the fitted coefficients (including their
correlation with the series tares they were fitted with); it is small where the schedule put
points and grows where it did not (six loads at once). σ_k is the calibration's residual scatter.
For an iterative (R-091) model V = A·g(L) the same is computed in output space at the solved loads
and mapped to loads by the inverse Jacobian: cov_L = J⁻¹ diag(σ_V² (1 + g C gᵀ)) J⁻ᵀ.
The pieces are stored by the fit in each model's `metadata.uncertainty` in calibration.yaml.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from .balance_model import BalanceModel
from .calibration import Calibration
from .identity_cache import IdentityCache
from .leverage import leverage_of_rows
from .r091 import IterativeModel

_CACHE: IdentityCache[tuple[np.ndarray, np.ndarray]] = IdentityCache(limit=64)


class UncertaintyUnavailable(ValueError):
    """The calibration carries no coefficient covariance (e.g. the memo's published matrices)."""


def covariance_and_sigma(
    model: BalanceModel | IterativeModel,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The model's unscaled coefficient covariance and residual σ per component (cached), or None
    when the calibration carries none (the memo's published matrices).
    """
    cached = _CACHE.get(model)
    if cached is not None:
        return cached
    metadata = getattr(model, 'metadata', None) or {}
    meta = metadata.get('uncertainty') if isinstance(metadata, Mapping) else None
    if not meta:
        return None
    covariance = np.asarray(meta['covariance_unscaled'], dtype=float)
    sigma = np.asarray(meta['residual_sigma'], dtype=float)
    if covariance.shape != (len(model.terms), len(model.terms)):
        return None
    return _CACHE.put(model, (covariance, sigma))


def _resolve(
    calibration_or_model: Calibration | BalanceModel | IterativeModel, model: str
) -> BalanceModel | IterativeModel:
    if hasattr(calibration_or_model, 'models') and hasattr(calibration_or_model, 'model'):
        return calibration_or_model.model(model)
    return calibration_or_model


def has_uncertainty(
    calibration_or_model: Calibration | BalanceModel | IterativeModel, model: str = 'adopted'
) -> bool:
    return covariance_and_sigma(_resolve(calibration_or_model, model)) is not None


def require_covariance(
    calibration_or_model: Calibration | BalanceModel | IterativeModel, model: str = 'adopted'
) -> None:
    chosen = _resolve(calibration_or_model, model)
    if covariance_and_sigma(chosen) is None:
        raise UncertaintyUnavailable(
            f'model {getattr(chosen, "name", "?")} carries no coefficient covariance '
            f'(metadata.uncertainty); refit it with balance-calib fit or refit'
        )


def load_standard_uncertainty(
    calibration_or_model: Calibration | BalanceModel | IterativeModel,
    outputs_mv: ArrayLike,
    extra: Mapping[str, np.ndarray] | None = None,
    *,
    model: str = 'adopted',
    tare_sigma: ArrayLike | None = None,
    loads: ArrayLike | None = None,
    design: ArrayLike | None = None,
) -> np.ndarray:
    """(N, n_components) standard uncertainty (k = 1) of each load, N / N·m, model component order.

    outputs_mv (N, n_inputs) as passed to model.loads; extra likewise. tare_sigma: optional
    (n_components,) standard uncertainty of a live load tare, added in quadrature. NaN rows where
    the model has no stored covariance or the outputs are not finite. loads: optional (N,
    n_components) the model's loads at these outputs if the caller has them already (an iterative
    model then skips its Newton solve). design: optional (N, n_terms) design rows of a direct model
    at these outputs, if the caller has them already (the live calibrator: those its loads came
    from).
    """
    chosen = _resolve(calibration_or_model, model)
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    n = outputs.shape[0]
    pieces = covariance_and_sigma(chosen)
    # the whole batch at once (a live batch is often one sample); rows only if some is not finite
    finite = np.isfinite(outputs)
    everyone = bool(finite.all())
    finite = finite if everyone else finite.all(axis=1)  # (N,) when some row is not
    if pieces is None or not (everyone or finite.any()):
        return np.full((n, len(chosen.components)), np.nan)
    covariance, sigma = pieces
    good = outputs if everyone else outputs[finite]
    if isinstance(chosen, IterativeModel):
        if loads is not None:
            loads = np.asarray(loads, dtype=float)
            loads = loads if everyone else loads[finite]
        loads = np.atleast_2d(chosen.loads(good) if loads is None else loads)
        design, jac = chosen.design_and_output_jacobian(loads)
        variance_out = _direct_variance(design, covariance, sigma)  # in output space
        inverse = np.linalg.inv(jac)
        variance: FloatArray = np.einsum('nmk,nk->nm', inverse**2, variance_out)
    else:
        sub_extra = (
            extra
            if extra is None or everyone
            else {
                k: (np.asarray(v)[finite] if np.ndim(v) and np.shape(v)[0] == n else v)
                for k, v in extra.items()
            }
        )
        if design is None:
            design = chosen.design(good, sub_extra)
        else:
            design = np.atleast_2d(design)
            design = design if everyone else design[finite]
        variance = _direct_variance(design, covariance, sigma)
    if tare_sigma is not None:
        variance = variance + np.square(np.asarray(tare_sigma, dtype=float))
    if everyone:
        return np.sqrt(variance)
    result = np.full((n, len(chosen.components)), np.nan)
    result[finite] = np.sqrt(variance)
    return result


def _direct_variance(design: np.ndarray, covariance: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(N, n_components) u² = σ² (1 + x (XᵀX)⁻¹ xᵀ) for design rows x (N, n_terms) of a direct
    model.
    """
    variance: FloatArray = np.multiply.outer(
        1.0 + leverage_of_rows(design, covariance), np.square(sigma)
    )
    return variance


def with_covariance(
    model: BalanceModel, covariance: ArrayLike, sigma: ArrayLike, dof: int
) -> BalanceModel:
    """The model with `metadata.uncertainty` = this (n_terms, n_terms) unscaled covariance (XᵀX)⁻¹
    and residual σ (n_components,), N / N·m, as calibration.yaml stores them.
    """
    return model.with_coefficients(
        model.coefficients,
        uncertainty={
            'residual_sigma': np.asarray(sigma, dtype=float).tolist(),
            'covariance_unscaled': np.asarray(covariance, dtype=float).tolist(),
            'dof': int(dof),
        },
    )
