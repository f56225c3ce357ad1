"""AIAA R-091's iterative method with series tares inside the regressors.

Outputs as a polynomial of the total loads, total = applied + T_s for the point's series s:

    V_i = A · g(applied_i + T_{s(i)})        (g: the term set, no constant: V is measured from the
                                             natural zero)

For fixed tares A is a linear least-squares problem; the tares enter nonlinearly. We iterate
Gauss-Newton on the tares with A projected out (variable projection, Kaufman's Jacobian): each step
refits A on the current total loads and moves T along the part of dV/dT that A cannot absorb, until
the step is below 1e-9 of capacity. The outputs are weighted by 1/σ of each channel, so a noisy
bridge does not dominate. Start: output intercepts per series mapped through the linear part.
"""

from __future__ import annotations

from typing import cast, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..model.leverage import leverage_of_rows
from ..model.r091 import IterativeModel, TermEvaluator
from ..model.terms import Term
from .least_squares import TooFewPointsError
from .series_tares import (
    series_indicator,
    series_rows,
    SeriesLabels,
    SeriesTareFit,
    solve_scaled,
)
from .term_selection import term_statistics

# Gauss-Newton steps on the tares before giving up (they settle in a handful on a sound schedule)
MAX_ITERATIONS = 40


class IterationDidNotConverge(ArithmeticError):
    """The tares did not settle; the message says after how many steps and by how much."""


def fit_iterative(
    terms: Sequence[Term],
    applied_loads: ArrayLike,
    outputs: ArrayLike,
    series: ArrayLike,
    *,
    components: Sequence[str],
    inputs: Sequence[str],
    capacity: ArrayLike,
    statistics: bool = True,
) -> SeriesTareFit:
    """Fit outputs = A · g(applied + tares) by variable projection (module docstring), the model
    named 'iterative'. components: the load symbols (the terms' variables), inputs: the bridge
    outputs, capacity (n_loads,) N / N·m: the tares' convergence scale. statistics: also the
    per-term statistics (term_selection.term_statistics). Returns the fit with its tares, load
    residuals (own and leave-one-out) and point uncertainty; IterationDidNotConverge after
    MAX_ITERATIONS Gauss-Newton steps.
    """
    name = 'iterative'
    terms = tuple(t for t in terms if not t.is_constant)
    applied = np.atleast_2d(np.asarray(applied_loads, float))
    outputs = np.atleast_2d(np.asarray(outputs, float))
    capacity = np.asarray(capacity, float)
    labels, index, onehot = series_indicator(series)
    n, m = applied.shape
    n_out = outputs.shape[1]
    if n_out != m:
        raise ValueError(
            f'the iterative method needs as many bridge outputs as loads ({n_out} outputs, {m} '
            'loads)'
        )
    evaluator = TermEvaluator(terms, components)
    term_names = [t.name for t in terms]
    n_series = len(labels)
    if n - len(terms) - n_series <= 0:
        raise TooFewPointsError(n, len(terms), n_series, name)

    # start: output intercepts per series, mapped to loads by the linear part
    design = evaluator.design(applied)
    start = solve_scaled(
        np.hstack([design, onehot]), outputs, term_names + [f'series {s}' for s in labels], name
    )
    linear = _linear_matrix(terms, components, start.coefficients[: len(terms)].T)
    # (n_series, m)
    tares = np.linalg.lstsq(linear, start.coefficients[len(terms) :].T, rcond=None)[0].T
    residual0 = outputs - np.hstack([design, onehot]) @ start.coefficients
    weights = 1.0 / np.maximum(np.sqrt(np.mean(residual0**2, axis=0)), 1e-300)

    converged = False
    iteration = 0
    for iteration in range(1, MAX_ITERATIONS + 1):
        totals = applied + tares[index]
        design, derivatives = evaluator.design_and_derivatives(totals)
        solution = solve_scaled(design, outputs, term_names, name)
        coefficients = solution.coefficients  # (p, n_out)
        residuals = outputs - design @ coefficients
        # (n_out, N, m) dV_k/dL_v
        sensitivity = np.einsum('vnp,pk->knv', derivatives, coefficients)
        jac = (sensitivity[:, :, None, :] * onehot[None, :, :, None]).reshape(
            n_out, n, n_series * m
        )
        jac = jac - np.einsum(
            'nr,krq->knq', solution.basis, np.einsum('nr,knq->krq', solution.basis, jac)
        )
        weighted_jac = (jac * weights[:, None, None]).reshape(n_out * n, n_series * m)
        weighted_res = (residuals.T * weights[:, None]).reshape(-1)
        step = np.linalg.lstsq(weighted_jac, weighted_res, rcond=None)[0].reshape(n_series, m)
        tares = tares + step
        if np.all(np.abs(step) <= 1e-9 * capacity):
            converged = True
            break
    if not converged:
        raise IterationDidNotConverge(
            f'{name}: series tares did not converge in {MAX_ITERATIONS} iterations (last step '
            f'{np.max(np.abs(step) / capacity):.2e} of capacity); the term set may be too large '
            'for the data'
        )

    totals = applied + tares[index]
    design = evaluator.design(totals)
    solution = solve_scaled(design, outputs, term_names, name)
    coefficients = solution.coefficients
    residuals = outputs - design @ coefficients
    dof = n - len(terms) - n_series
    sigma = np.sqrt((residuals**2).sum(axis=0) / dof)
    # tare covariance: Gauss-Newton at the solution, outputs weighted by their own σ
    weights = 1.0 / sigma
    weighted_jac = (jac * weights[:, None, None]).reshape(n_out * n, n_series * m)
    _, singular, vt = np.linalg.svd(weighted_jac, full_matrices=False)
    tare_cov = (vt.T / singular**2) @ vt
    tare_sigma = np.sqrt(np.diag(tare_cov)).reshape(n_series, m)

    # covariance for predictions: tares as output intercepts of one linear problem [g(L), e_s]
    full_design = np.hstack([design, onehot])
    full = solve_scaled(full_design, outputs, term_names + [f'series {s}' for s in labels], name)
    metadata = {
        'capacity': capacity.tolist(),
        'uncertainty': {
            'residual_sigma': sigma.tolist(),
            'covariance_unscaled': full.covariance_unscaled[: len(terms), : len(terms)].tolist(),
            'dof': int(dof),
        },
    }
    model = IterativeModel(name, terms, coefficients.T, tuple(components), tuple(inputs), metadata)
    predicted_total = model.loads(outputs)
    load_residuals = applied - (predicted_total - tares[index])
    _, out_jac = model.output_jacobian(predicted_total)
    inverse = np.linalg.inv(out_jac)  # (N, m, n_out) dL/dV
    h = np.minimum(full.leverage, 1 - 1e-12)
    press_outputs = residuals / (1 - h)[:, None]
    press_loads = -np.einsum('nmk,nk->nm', inverse, press_outputs)
    uncertainty = _load_sigma(inverse, sigma[None, :] ** 2 * (1.0 + h)[:, None])
    stats = (
        term_statistics(
            full_design,
            outputs,
            full.coefficients,
            full.covariance_unscaled,
            len(terms),
            term_names,
            list(inputs),
        )
        if statistics
        else None
    )
    return SeriesTareFit(
        'iterative',
        model,
        labels,
        tares,
        tare_sigma,
        load_residuals,
        press_loads,
        uncertainty,
        sigma,
        dof,
        stats,
        solution.condition_number,
        iteration,
        (),
        full.covariance_unscaled,
    )


def _linear_matrix(
    terms: Sequence[Term], components: Sequence[str], coefficients: np.ndarray
) -> np.ndarray:
    matrix = np.zeros((coefficients.shape[0], len(components)))
    for j, term in enumerate(terms):
        if term.degree == 1 and not term.factors[0].absolute:
            matrix[:, list(components).index(term.factors[0].variable)] = coefficients[:, j]
    return matrix


def _load_sigma(inverse: np.ndarray, output_variance: np.ndarray) -> np.ndarray:
    """sqrt(diag(J⁻¹ diag(var_V) J⁻ᵀ)) per point: (N, m)."""
    sigma: np.ndarray = np.sqrt(np.einsum('nmk,nk->nm', inverse**2, output_variance))
    return sigma


def iterative_point_uncertainty(
    fit: SeriesTareFit, outputs: ArrayLike, series: SeriesLabels
) -> np.ndarray:
    """K = 1 uncertainty of applied loads predicted at new points with the calibration's tares."""
    model = fit.model
    outputs = np.atleast_2d(np.asarray(outputs, float))
    totals = model.loads(outputs)
    _, out_jac = model.output_jacobian(totals)
    z = np.hstack([model.design(totals), series_rows(fit, series)])
    # fitted with it
    h = leverage_of_rows(z, cast(np.ndarray, fit.full_covariance_unscaled))
    return _load_sigma(
        np.linalg.inv(out_jac), fit.residual_sigma[None, :] ** 2 * (1.0 + h)[:, None]
    )
