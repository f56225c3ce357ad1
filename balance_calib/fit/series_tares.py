"""Series tares estimated with the model (AIAA R-091 practice), and the direct (TM-663) form.

Every load series s carries an unknown tare load T_s: total load = applied + T_s. In the direct
form (TM-663 eqs. (1)-(18): loads as a polynomial of the outputs) the tares are per-series load
intercepts of one linear least-squares problem:

    applied_i = C · x(V_i) - T_{s(i)}          (x without the constant: T takes its role)

solved with scaled columns by pivoted QR (fit/least_squares.scaled_least_squares; never the normal
equations), giving coefficients, tares and their full covariance, from all points of each series
rather than its zero-load point alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, cast, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..model.balance_model import BalanceModel
from ..model.leverage import leverage_of_rows
from ..model.terms import as_variables, design_matrix, Term
from .least_squares import (
    LeastSquares,
    scaled_least_squares,
    TooFewPointsError,
    UnexcitedTermsError,
)
from .term_selection import term_statistics, TermStatistics

RANK_TOLERANCE = 1e-9
# the load series of each point (N,): integer labels, a list or an array
SeriesLabels = Sequence[int] | np.ndarray


def solve_scaled(
    design: np.ndarray, targets: np.ndarray, column_names: Sequence[str], model_name: str = 'model'
) -> LeastSquares:
    """Least squares with columns scaled to unit norm, eq. (19) with the tares as columns.

    design (N, q), targets (N, k); raises UnexcitedTermsError naming the dependent columns.
    """
    solution = scaled_least_squares(design, targets, tolerance=RANK_TOLERANCE)
    if solution.rank < design.shape[1]:
        raise UnexcitedTermsError(
            [column_names[j] for j in solution.dependent_columns], model_name
        )
    return solution


def series_indicator(series: ArrayLike) -> tuple[tuple[int, ...], np.ndarray, np.ndarray]:
    """(labels, index of each point's series (N,), one-hot (N, n_series))."""
    series = np.asarray(series, dtype=int)
    labels, index = np.unique(series, return_inverse=True)
    onehot = np.zeros((len(series), len(labels)))
    onehot[np.arange(len(series)), index] = 1.0
    return tuple(int(x) for x in labels), index, onehot


@dataclass(frozen=True)
class SeriesTareFit:
    """A model fitted with its series tares, in SI, with what the report needs."""

    method: str  # 'direct' | 'iterative'
    model: Any  # BalanceModel (direct) or IterativeModel (iterative)
    series_labels: tuple[int, ...]
    tares: np.ndarray  # (n_series, n_loads) N / N·m, total = applied + tare
    tare_sigma: np.ndarray  # (n_series, n_loads) standard errors
    load_residuals: np.ndarray  # (N, n_loads) applied - predicted applied
    press_load_residuals: np.ndarray  # (N, n_loads) the same with each point left out of the fit
    point_uncertainty: np.ndarray  # (N, n_loads) k = 1 standard uncertainty of each point's load
    residual_sigma: np.ndarray  # (n_targets,) σ of the fit's own residuals (loads or outputs)
    dof: int
    statistics: TermStatistics | None
    condition_number: float
    iterations: int = 1
    notes: tuple[str, ...] = field(default_factory=tuple)
    # (p + n_series, p + n_series) of [terms, series]
    full_covariance_unscaled: np.ndarray | None = None

    def tare_rows(self, series: SeriesLabels) -> np.ndarray:
        """(N, n_loads) the calibration's tare of each point's series; KeyError names a series
        it lacks.
        """
        lookup = {s: i for i, s in enumerate(self.series_labels)}
        missing = sorted({int(s) for s in series} - set(lookup))
        if missing:
            raise KeyError(
                f'load series {", ".join(map(str, missing))} not in the calibration '
                f'(it has {", ".join(map(str, self.series_labels))})'
            )
        return self.tares[[lookup[int(s)] for s in series]]

    def predict_applied(self, outputs: ArrayLike, series: SeriesLabels) -> np.ndarray:
        """Applied loads predicted for validation points: model loads minus the calibration's
        tares.
        """
        predicted: np.ndarray = np.atleast_2d(self.model.loads(outputs)) - self.tare_rows(series)
        return predicted


def fit_direct(
    terms: Sequence[Term],
    outputs: ArrayLike,
    applied_loads: ArrayLike,
    series: ArrayLike,
    *,
    components: Sequence[str],
    inputs: Sequence[str],
    name: str = 'direct',
    statistics: bool = True,
) -> SeriesTareFit:
    """TM-663's form with per-series load intercepts (the tares), eq. (19) plus tares."""
    terms = tuple(t for t in terms if not t.is_constant)
    outputs = np.atleast_2d(np.asarray(outputs, float))
    applied = np.atleast_2d(np.asarray(applied_loads, float))
    labels, index, onehot = series_indicator(series)
    x = design_matrix(terms, as_variables(tuple(inputs), outputs), len(outputs))
    design = np.hstack([x, -onehot])
    names = [t.name for t in terms] + [f'tare of series {s}' for s in labels]
    p = len(terms)
    dof = len(outputs) - design.shape[1]
    if dof <= 0:
        raise TooFewPointsError(len(outputs), p, len(labels), name)
    solution = solve_scaled(design, applied, names, name)
    coefficients = solution.coefficients[:p].T
    tares = solution.coefficients[p:]
    residuals = applied - design @ solution.coefficients
    sigma = np.sqrt((residuals**2).sum(axis=0) / dof)
    cov_diag = np.diag(solution.covariance_unscaled)
    tare_sigma = np.sqrt(np.outer(cov_diag[p:], sigma**2))
    h = np.minimum(solution.leverage, 1 - 1e-12)
    press = residuals / (1 - h)[:, None]
    uncertainty = sigma[None, :] * np.sqrt(1.0 + h)[:, None]
    metadata = {
        'uncertainty': {
            'residual_sigma': sigma.tolist(),
            'covariance_unscaled': solution.covariance_unscaled[:p, :p].tolist(),
            'dof': int(dof),
        }
    }
    model = BalanceModel(name, terms, coefficients, tuple(components), tuple(inputs), metadata)
    stats = (
        term_statistics(
            design,
            applied,
            solution.coefficients,
            solution.covariance_unscaled,
            p,
            [t.name for t in terms],
            list(components),
        )
        if statistics
        else None
    )
    return SeriesTareFit(
        'direct',
        model,
        labels,
        tares,
        tare_sigma,
        residuals,
        press,
        uncertainty,
        sigma,
        dof,
        stats,
        solution.condition_number,
        1,
        (),
        solution.covariance_unscaled,
    )


def series_rows(fit: SeriesTareFit, series: SeriesLabels) -> np.ndarray:
    """(N, n_series) one-hot rows of the calibration's series for new points (KeyError if
    unknown).
    """
    fit.tare_rows(series)
    rows = np.zeros((len(series), len(fit.series_labels)))
    rows[np.arange(len(series)), [fit.series_labels.index(int(s)) for s in series]] = 1.0
    return rows


def direct_point_uncertainty(
    fit: SeriesTareFit, outputs: ArrayLike, series: SeriesLabels
) -> np.ndarray:
    """K = 1 uncertainty of applied loads predicted at new points with the calibration's tares:
    u² = σ² (1 + z (ZᵀZ)⁻¹ zᵀ), z = [x(V), -e_s]: coefficients, the tare's own uncertainty and
    their correlation, plus the residual scatter.
    """
    outputs = np.atleast_2d(np.asarray(outputs, float))
    z = np.hstack([fit.model.design(outputs), -series_rows(fit, series)])
    # fitted with it
    h = leverage_of_rows(z, cast(np.ndarray, fit.full_covariance_unscaled))
    return fit.residual_sigma[None, :] * np.sqrt(1.0 + h)[:, None]


def tares_with_model_fixed(
    totals: ArrayLike, applied: ArrayLike, series: ArrayLike
) -> tuple[np.ndarray, dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Each series' tare estimated from its own points with the model held fixed.

    totals (N, n) the model's total loads, applied (N, n) the applied ones, series (N,) labels:
    T_s = mean over the series' points of (total - applied), its standard error the scatter of
    those differences / √n_s (NaN for a series of one point). Returns the tare of each point's
    series (N, n) and, by series, the tares and their standard errors (n,), SI as given.
    """
    totals = np.atleast_2d(np.asarray(totals, dtype=float))
    difference = totals - np.atleast_2d(np.asarray(applied, dtype=float))
    series = np.asarray(series, dtype=int)
    rows = np.zeros_like(totals)
    tares, sigma = {}, {}
    for label in np.unique(series):
        mask = series == label
        n = int(mask.sum())
        tares[int(label)] = difference[mask].mean(axis=0)
        sigma[int(label)] = (
            difference[mask].std(axis=0, ddof=1) / np.sqrt(n)
            if n > 1
            else np.full(totals.shape[1], np.nan)
        )
        rows[mask] = tares[int(label)]
    return rows, tares, sigma
