"""Least-squares fit of a balance model, TM-663 §3: minimise eq. (19).

Eq. (19) sums the squared load errors of all six components; every component shares the same
design matrix, so it separates into one least-squares problem per component with a common
matrix. The memo reaches the minimum by the corrections of eqs. (20)-(27) and the normal
equations of eq. (28), ∂F/∂C_k = 0; for a model linear in its coefficients that is one step, and
we take it without forming the normal equations (they square the condition number): columns
scaled, pivoted QR to find the terms the load schedule does not excite, the triangular factor
for the solution and the coefficient covariance. `scaled_least_squares` is that primitive; the
series-tare fits (series_tares.py) and the diagnosis (diagnosis/statistics.py) call it too.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
import scipy.linalg

from ..array_types import FloatArray
from ..model.balance_model import BalanceModel
from ..model.leverage import leverage_of_rows
from ..model.terms import as_variables, design_matrix, Term
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .svd import column_norms, singular_values

IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]

# A term whose rated-scaled column, after removing what the other terms already explain, keeps
# less than this fraction of a fully excited column is "not excited by the schedule".
UNEXCITED_TOLERANCE = 1e-4


class UnexcitedTermsError(ValueError):
    """The load schedule leaves some terms undetermined; the message names them."""

    def __init__(self, terms: Sequence[str], model_name: str):
        self.terms = tuple(terms)
        super().__init__(
            f'the load schedule does not excite {len(self.terms)} term(s) of the {model_name} '
            f'model: {", ".join(self.terms)}; load those bridges (alone and combined) or fit a '
            'smaller model'
        )


class TooFewPointsError(ValueError):
    """More coefficients than points: the message says how many of each."""

    def __init__(self, points: int, terms: int, tares: int, model_name: str):
        super().__init__(
            f"{points} points cannot determine the {model_name} model's {terms} terms and {tares} "
            f'series tare(s) (it needs at least {terms + tares + 1} points); fit fewer terms'
        )


# A point that alone determines a coefficient (h_ii -> 1) has no leave-one-out prediction; its
# PRESS residual is taken with 1 - h clipped here instead of dividing by zero.
MIN_ONE_MINUS_LEVERAGE = 1e-6


@dataclass(frozen=True)
class LeastSquares:
    """The least-squares fit of ``design · coefficients ≈ targets``, eqs. (19) and (28): the one
    result type of the package's least squares (as statsmodels' RegressionResults with
    OLSInfluence's leverage and PRESS residuals).

    Shapes: N points, p design columns, k targets (k absent for a 1-D target), r = rank.
    Coefficients are in the units of targets / design column; a column the others already
    explain (below the rank tolerance) is fixed at zero and left out of `basis` and
    `covariance_unscaled`.
    """

    coefficients: FloatArray  # (p,) or (p, k); 0 for dependent columns
    pivots: IntArray  # (p,) column order of the pivoted QR: most new information first
    pivot_diagonal: FloatArray  # (p,) |R_ii| of the scaled columns in pivot order, 0-padded
    r_factor: FloatArray  # (r, r) upper triangular factor of the kept scaled columns
    basis: FloatArray  # (N, r) orthonormal basis of the kept columns' span (Q)
    scales: FloatArray  # (p,) the column scales used (design / scales was factored)
    residuals: FloatArray  # (N,) or (N, k) targets - design · coefficients

    @classmethod
    def of_projection(cls, basis: FloatArray, residuals: FloatArray) -> LeastSquares:
        """The fit whose residuals (N,) are already orthogonal to an orthonormal basis (N, r)
        of its columns: the basis is its own Q (R = I, unit scales), the coefficients are not
        kept (zeros). For stacking the fits of several components into one (block-diagonal)
        basis.
        """
        rank = basis.shape[1]
        return cls(
            np.zeros(rank),
            np.arange(rank),
            np.ones(rank),
            np.eye(rank),
            basis,
            np.ones(rank),
            residuals,
        )

    @property
    def rank(self) -> int:
        return int(self.basis.shape[1])

    @property
    def points(self) -> int:
        return int(self.residuals.shape[0])

    @property
    def dof(self) -> int:
        """Residual degrees of freedom, N - rank."""
        return self.points - self.rank

    @property
    def rss(self) -> float:
        """Residual sum of squares of a 1-D target."""
        return float(self.residuals @ self.residuals)

    @property
    def variance(self) -> float:
        """Residual variance RSS / (N - rank) of a 1-D target (NaN without degrees of freedom)."""
        return self.rss / self.dof if self.dof > 0 else float('nan')

    @cached_property
    def kept(self) -> BoolArray:
        """(p,) bool: the columns solved for (the others are dependent, fixed at zero)."""
        mask = np.zeros(self.pivots.size, dtype=bool)
        mask[self.pivots[: self.rank]] = True
        return mask

    @cached_property
    def dependent_columns(self) -> IntArray:
        """Indices of the dependent columns, in pivot order (least new information last)."""
        return self.pivots[self.rank :]

    @cached_property
    def leverage(self) -> FloatArray:
        """(N,) hat-matrix diagonal h_ii: the squared row norms of the basis."""
        return leverage_of_rows(self.basis)

    @property
    def press_residuals(self) -> FloatArray:
        """Leave-one-out residuals e_i / (1 - h_ii) (PRESS), 1 - h_ii clipped at
        MIN_ONE_MINUS_LEVERAGE; (N,) or (N, k) as the residuals.
        """
        one_minus = np.maximum(1.0 - self.leverage, MIN_ONE_MINUS_LEVERAGE)
        press: FloatArray = self.residuals / (
            one_minus if self.residuals.ndim == 1 else one_minus[:, None]
        )
        return press

    @property
    def press(self) -> float:
        """Sum of the squared PRESS residuals (all targets)."""
        return float(np.sum(self.press_residuals**2))

    @cached_property
    def covariance_unscaled(self) -> FloatArray:
        """(p, p) (XᵀX)⁻¹ over the kept columns, in the design's units (zero rows and columns
        for dependent ones): times σ² it is the coefficient covariance of eq. (28)'s solution.
        """
        p = self.pivots.size
        order = self.pivots[: self.rank]
        inverse_r = scipy.linalg.solve_triangular(self.r_factor, np.eye(self.rank))
        covariance = np.zeros((p, p))
        covariance[np.ix_(order, order)] = (inverse_r @ inverse_r.T) / np.outer(
            self.scales[order], self.scales[order]
        )
        return covariance

    @property
    def covariance(self) -> FloatArray:
        """Coefficient covariance σ² (XᵀX)⁻¹: (p, p) for a 1-D target, (k, p, p) for k targets
        (σ² = RSS / (N - rank) of each; NaN without degrees of freedom).
        """
        sigma2 = np.sum(self.residuals**2, axis=0) / self.dof if self.dof > 0 else np.nan
        covariance: FloatArray = np.multiply.outer(sigma2, self.covariance_unscaled)
        return covariance

    @property
    def t_statistics(self) -> FloatArray:
        """Per-term t = coefficient / standard error, (p,) or (k, p) (0 for dependent columns)."""
        variance = np.diagonal(self.covariance, axis1=-2, axis2=-1)
        coefficients = self.coefficients.T  # (p,) or (k, p)
        with np.errstate(divide='ignore', invalid='ignore'):
            t: FloatArray = np.where(self.kept, coefficients / np.sqrt(variance), 0.0)
        return t

    @cached_property
    def condition_number(self) -> float:
        """2-norm condition number of the kept scaled columns (inf when none is kept)."""
        if not self.rank:
            return float('inf')
        singular = singular_values(self.r_factor)
        return float(singular[0] / singular[-1])


def scaled_least_squares(
    design: ArrayLike,
    targets: ArrayLike,
    *,
    scales: FloatArray | None = None,
    tolerance: float = 1e-9,
    relative: bool = True,
) -> LeastSquares:
    """Minimise ``||targets - design · coefficients||²`` per target column, eqs. (19), (28).

    Parameters
    ----------
    design : array_like, shape (N, p)
        Design matrix, one column per term (any units).
    targets : array_like, shape (N,) or (N, k)
        Measured values (loads in N / N·m, or bridge outputs in mV).
    scales : ndarray, shape (p,), optional
        Column scales: design / scales is factored. Default: the column norms (unit columns).
    tolerance : float
        A column whose pivoted-QR diagonal |R_ii| (of the scaled design) is not above this is
        dependent on the columns before it and fixed at zero.
    relative : bool
        True: the tolerance is a fraction of the largest |R_ii|; False: an absolute bound on the
        scaled columns (meaningful when the scales make a fully excited column of norm ~1).

    Returns
    -------
    LeastSquares
        Coefficients of shape (p,) or (p, k) in the design's units and the residuals, with the
        factor, basis, leverage, PRESS residuals, covariance and condition number of the kept
        columns.
    """
    design = np.asarray(design, dtype=float)
    targets = np.asarray(targets, dtype=float)
    n_columns = design.shape[1]
    scales = column_norms(design) if scales is None else np.asarray(scales, dtype=float)
    q_factor, r_factor, pivots = scipy.linalg.qr(design / scales, mode='economic', pivoting=True)
    diagonal = np.zeros(n_columns)
    diagonal[: min(r_factor.shape)] = np.abs(np.diag(r_factor))
    threshold = tolerance * max(diagonal[0], 1e-300) if relative and n_columns else tolerance
    rank = int(np.sum(diagonal > threshold))
    basis = q_factor[:, :rank]
    r_kept = r_factor[:rank, :rank]
    coefficients = np.zeros((n_columns,) + targets.shape[1:])
    if rank:
        solution = scipy.linalg.solve_triangular(r_kept, basis.T @ targets)
        order = pivots[:rank]
        scale = scales[order] if targets.ndim == 1 else scales[order, None]
        coefficients[order] = solution / scale
    residuals = targets - design @ coefficients
    return LeastSquares(coefficients, pivots, diagonal, r_kept, basis, scales, residuals)


@dataclass(frozen=True)
class FitResult:
    """A fitted model with what a person needs to trust it."""

    model: BalanceModel
    rank: int
    condition_number: float  # of the column-scaled design matrix
    unexcited_terms: tuple[str, ...]  # fixed at zero (only with on_unexcited='drop')
    standard_errors: np.ndarray  # (n_components, n_terms), same units as coefficients
    residuals: np.ndarray  # (N, n_components): measured - fitted load, N / N·m
    degrees_of_freedom: int

    @property
    def points(self) -> int:
        return int(self.residuals.shape[0])


def term_scales(
    terms: Sequence[Term], rated_outputs: Mapping[str, float] | None, design: np.ndarray
) -> np.ndarray:
    """Size of each term at rated outputs (products of rated values), else its largest value."""
    scales = np.empty(len(terms))
    for j, term in enumerate(terms):
        if rated_outputs and all(v in rated_outputs for v in term.variables):
            scale = 1.0
            for factor in term.factors:
                scale *= abs(rated_outputs[factor.variable]) ** factor.power
        else:
            scale = float(np.max(np.abs(design[:, j]))) if design.shape[0] else 0.0
        scales[j] = scale if scale > 0 else 1.0
    return scales


def fit_model(
    terms: Sequence[Term],
    bridge_outputs_mv: ArrayLike,
    loads: ArrayLike,
    *,
    name: str = 'custom',
    rated_outputs: Mapping[str, float] | None = None,
    components: Sequence[str] = COMPONENTS,
    inputs: Sequence[str] = BRIDGE_OUTPUTS,
    on_unexcited: str = 'raise',
) -> FitResult:
    """Fit coefficients so that loads ≈ model(outputs), eq. (19).

    bridge_outputs_mv (N, n_inputs), loads (N, n_components). `rated_outputs` (mV by input name)
    sets the physical size of every term; with it an unexcited term is recognised as such even in
    noisy data. on_unexcited: 'raise' (UnexcitedTermsError naming the terms) or 'drop' (fix them at
    zero and list them in the result).
    """
    terms = tuple(terms)
    outputs = np.atleast_2d(np.asarray(bridge_outputs_mv, dtype=float))
    targets = np.atleast_2d(np.asarray(loads, dtype=float))
    if outputs.shape[0] != targets.shape[0]:
        raise ValueError(f'{outputs.shape[0]} output rows but {targets.shape[0]} load rows')
    if not (np.all(np.isfinite(outputs)) and np.all(np.isfinite(targets))):
        raise ValueError('calibration data contain NaN or infinity; reject those points first')
    n_points, n_terms = outputs.shape[0], len(terms)
    design = design_matrix(terms, as_variables(tuple(inputs), outputs), n_points)

    # Column scaling by the term's size at rated output, normalised so a fully excited column
    # has norm about 1: the absolute tolerance then means "not excited by the schedule".
    scales = term_scales(terms, rated_outputs, design) * np.sqrt(max(n_points, 1))
    solution = scaled_least_squares(
        design, targets, scales=scales, tolerance=UNEXCITED_TOLERANCE, relative=False
    )
    excited_mask = solution.kept
    unexcited = tuple(terms[j].name for j in range(n_terms) if not excited_mask[j])
    if unexcited and on_unexcited == 'raise':
        raise UnexcitedTermsError(unexcited, name)
    if on_unexcited not in ('raise', 'drop'):
        raise ValueError(f"on_unexcited must be 'raise' or 'drop', not {on_unexcited!r}")

    kept = np.flatnonzero(excited_mask)
    if kept.size > n_points:
        raise UnexcitedTermsError([terms[j].name for j in kept[n_points:]], name)
    coefficients = np.ascontiguousarray(solution.coefficients.T)  # (n_components, n_terms)

    fitted = design @ coefficients.T
    residuals = targets - fitted
    dof = n_points - kept.size
    variance = (residuals**2).sum(axis=0) / dof if dof > 0 else np.full(targets.shape[1], np.nan)
    covariance_diag = np.diag(solution.covariance_unscaled)[kept]  # diag((XᵀX)⁻¹)
    standard_errors = np.zeros_like(coefficients)
    standard_errors[:, kept] = np.sqrt(np.outer(variance, covariance_diag))
    condition = solution.condition_number
    model = BalanceModel(name, terms, coefficients, tuple(components), tuple(inputs))
    return FitResult(model, int(kept.size), condition, unexcited, standard_errors, residuals, dof)


def refit_like(
    model: BalanceModel, bridge_outputs_mv: ArrayLike, loads: ArrayLike, **kwargs: Any
) -> FitResult:
    """Fit the term list of an existing model to new data; returns the fit."""
    return fit_model(
        model.terms,
        bridge_outputs_mv,
        loads,
        name=model.name,
        components=model.components,
        inputs=model.inputs,
        **kwargs,
    )
