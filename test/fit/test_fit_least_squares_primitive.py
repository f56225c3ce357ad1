"""One least-squares primitive (fit/least_squares.scaled_least_squares) and its three callers.

The reference case is worked by hand: an 8-point Hadamard design whose first five columns,
mixed by an integer triangular matrix and scaled 1e-6 … 1e6, carry the model, and whose last
two columns carry the residual. The exact answer (coefficients, residual, leverage 5/8 at
every point, covariance) follows from H ᵀH = 8 I without a least-squares solver.
"""

import numpy as np
import pytest
import scipy.linalg

from balance_calib.diagnosis.statistics import fit_columns
from balance_calib.fit.least_squares import (
    fit_model,
    LeastSquares,
    scaled_least_squares,
    UnexcitedTermsError,
)
from balance_calib.fit.series_tares import solve_scaled
from balance_calib.model.leverage import leverage_of_rows
from balance_calib.model.terms import parse_terms

HADAMARD = scipy.linalg.hadamard(8).astype(float)  # columns orthogonal, norm √8
MIXING = np.array(
    [
        [1, 2, 0, -1, 3],  # unit upper triangular: the
        [0, 1, 4, 2, 0],  # columns are correlated
        [0, 0, 1, 5, -2],
        [0, 0, 0, 1, 1],
        [0, 0, 0, 0, 1],
    ],
    dtype=float,
)
SCALES = np.array([1e-6, 1e-3, 1.0, 1e3, 1e6])
TRUE = np.array([[3.0, -1.0], [-2.0, 4.0], [5.0, 0.5], [1.0, -3.0], [-4.0, 2.0]])  # (5, 2)
OFF_MODEL = HADAMARD[:, 5:] @ np.array([[2.0, -1.0], [-1.0, 0.5], [0.5, 3.0]])  # (8, 2)


def hand_case():
    """Design (8, 5) = H₅ M diag(s), targets (8, 2) = H₅ M c + residual ⟂ the columns."""
    unscaled = HADAMARD[:, :5] @ MIXING
    design = unscaled * SCALES
    targets = unscaled @ TRUE + OFF_MODEL
    # exact: coefficients c / s; (XᵀX)⁻¹ = diag(1/s) (8 MᵀM)⁻¹ diag(1/s)
    inverse_mixing = np.linalg.inv(MIXING)  # integer matrix: M is unit triangular
    covariance = (inverse_mixing @ inverse_mixing.T / 8.0) / np.outer(SCALES, SCALES)
    return design, targets, TRUE / SCALES[:, None], covariance


def test_the_hand_worked_ill_conditioned_case_is_solved_to_round_off():
    design, targets, coefficients, covariance = hand_case()
    assert np.linalg.cond(design) > 1e11  # the column scales alone make it so
    solution = scaled_least_squares(design, targets)
    assert solution.rank == 5 and solution.kept.all()
    np.testing.assert_allclose(solution.coefficients, coefficients, rtol=1e-12)
    np.testing.assert_allclose(targets - design @ solution.coefficients, OFF_MODEL, atol=1e-12)
    np.testing.assert_allclose(solution.leverage, np.full(8, 5 / 8), rtol=1e-13)
    np.testing.assert_allclose(solution.covariance_unscaled, covariance, rtol=1e-11)
    basis = solution.basis
    np.testing.assert_allclose(basis.T @ basis, np.eye(5), atol=1e-14)
    # scaled to unit columns, the design's condition is that of H₅ M with unit columns
    unit = HADAMARD[:, :5] @ MIXING
    assert solution.condition_number == pytest.approx(
        np.linalg.cond(unit / np.linalg.norm(unit, axis=0)), rel=1e-12
    )


def test_the_primitive_agrees_with_numpy_lstsq_on_the_scaled_problem():
    design, targets, _, _ = hand_case()
    norms = np.linalg.norm(design, axis=0)
    reference = np.linalg.lstsq(design / norms, targets, rcond=None)[0] / norms[:, None]
    solution = scaled_least_squares(design, targets)
    np.testing.assert_allclose(solution.coefficients, reference, rtol=1e-12)
    # and one target column at a time gives the same 1-D answer
    np.testing.assert_allclose(
        scaled_least_squares(design, targets[:, 1]).coefficients, reference[:, 1], rtol=1e-12
    )


def test_the_three_callers_give_the_primitives_answer():
    design, targets, coefficients, covariance = hand_case()
    primitive = scaled_least_squares(design, targets)
    names = [f'c{j}' for j in range(5)]

    tares = solve_scaled(design, targets, names)  # fit/series_tares.py
    np.testing.assert_array_equal(tares.coefficients, primitive.coefficients)
    np.testing.assert_allclose(tares.covariance_unscaled, covariance, rtol=1e-11)

    for k in range(2):  # diagnosis/statistics.py
        component = fit_columns(design, targets[:, k])
        np.testing.assert_array_equal(
            component.coefficients, scaled_least_squares(design, targets[:, k]).coefficients
        )
        np.testing.assert_allclose(
            component.coefficients, primitive.coefficients[:, k], rtol=1e-12
        )
        np.testing.assert_allclose(component.coefficients, coefficients[:, k], rtol=1e-12)
        np.testing.assert_allclose(component.leverage, np.full(8, 5 / 8), rtol=1e-13)
        assert component.rank == 5 and component.dof == 3
        assert component.rss == pytest.approx(float(OFF_MODEL[:, k] @ OFF_MODEL[:, k]), rel=1e-12)


def test_fit_model_agrees_with_the_primitive_and_lstsq_with_bridges_of_very_different_size():
    """fit_model (fit/least_squares.py) on terms whose columns span twelve decades."""
    rng = np.random.default_rng(23)
    n = 40
    sizes = np.array([1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4])  # mV, per bridge
    outputs = rng.uniform(-1.0, 1.0, (n, 6)) * sizes
    terms = parse_terms(['1', 'FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV', 'FXV*MZV'])
    design = np.column_stack([np.ones(n), outputs, outputs[:, 0] * outputs[:, 5]])
    true = rng.normal(size=(6, 8)) / np.concatenate([[1.0], sizes, [sizes[0] * sizes[5]]])
    noise = rng.normal(scale=0.01, size=(n, 6))
    loads = design @ true.T + noise
    fit = fit_model(terms, outputs, loads)

    norms = np.linalg.norm(design, axis=0)
    reference = (np.linalg.lstsq(design / norms, loads, rcond=None)[0] / norms[:, None]).T
    np.testing.assert_allclose(fit.model.coefficients, reference, rtol=1e-10)
    residuals = loads - design @ reference.T
    np.testing.assert_allclose(fit.residuals, residuals, rtol=1e-8, atol=1e-14)
    # standard errors: sqrt(RSS / (N - p) · diag((XᵀX)⁻¹)), (XᵀX)⁻¹ from the scaled SVD
    _, singular, vt = np.linalg.svd(design / norms, full_matrices=False)
    inverse_diagonal = ((vt.T / singular) ** 2).sum(axis=1) / norms**2
    variance = (residuals**2).sum(axis=0) / (n - 8)
    np.testing.assert_allclose(
        fit.standard_errors, np.sqrt(np.outer(variance, inverse_diagonal)), rtol=1e-9
    )
    assert fit.rank == 8 and fit.degrees_of_freedom == n - 8


def test_a_dependent_column_is_fixed_at_zero_or_named():
    design, targets, coefficients, _ = hand_case()
    doubled = np.column_stack([design, 2.0 * design[:, 2]])  # column 5 = 2 × column 2
    solution = scaled_least_squares(doubled, targets)
    assert solution.rank == 5 and not solution.kept.all()
    assert len(solution.dependent_columns) == 1 and solution.dependent_columns[0] in (2, 5)
    np.testing.assert_allclose(doubled @ solution.coefficients, design @ coefficients, rtol=1e-11)
    assert np.all(solution.coefficients[~solution.kept] == 0.0)
    assert np.all(solution.covariance_unscaled[~solution.kept] == 0.0)
    assert fit_columns(doubled, targets[:, 0]).rank == 5
    with pytest.raises(UnexcitedTermsError, match=r'c[25]'):
        solve_scaled(doubled, targets, [f'c{j}' for j in range(6)])


def test_fit_model_drops_a_term_the_schedule_does_not_excite():
    rng = np.random.default_rng(5)
    outputs = rng.uniform(-1.0, 1.0, (30, 6))
    outputs[:, 4] = 0.0  # MYV never loaded
    terms = parse_terms(['FXV', 'FYV', 'MYV'])
    loads = rng.normal(size=(30, 6))
    fit = fit_model(
        terms,
        outputs,
        loads,
        rated_outputs=dict.fromkeys(('FXV', 'FYV', 'MYV'), 1.0),
        on_unexcited='drop',
    )
    assert fit.unexcited_terms == ('MYV',) and fit.rank == 2
    assert np.all(fit.model.coefficients[:, 2] == 0.0) and np.all(fit.standard_errors[:, 2] == 0.0)


def test_the_one_result_type_on_a_hand_worked_straight_line():
    """Y = a + b x through four points, every statistic from the textbook formulas:
    b = Sxy / Sxx, a = ȳ - b x̄, h_ii = 1/n + (x_i - x̄)² / Sxx, PRESS e_i / (1 - h_ii),
    Var(b) = σ² / Sxx, Var(a) = σ² (1/n + x̄² / Sxx), Cov(a, b) = -x̄ σ² / Sxx, σ² = RSS / (n - 2).
    """
    x = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([1.0, 3.0, 2.0, 5.0])
    n = 4
    x_mean, y_mean = 1.5, 2.75
    sxx = 5.0  # 2.25 + 0.25 + 0.25 + 2.25
    sxy = 5.5  # 2.625 - 0.125 - 0.375 + 3.375
    slope = sxy / sxx  # 1.1
    intercept = y_mean - slope * x_mean  # 1.1
    residuals = np.array([-0.1, 0.8, -1.3, 0.6])  # y - (1.1 + 1.1 x)
    rss = 2.7
    sigma2 = rss / (n - 2)
    leverage = 1 / n + (x - x_mean) ** 2 / sxx  # 0.7, 0.3, 0.3, 0.7
    unscaled = np.array([[1 / n + x_mean**2 / sxx, -x_mean / sxx], [-x_mean / sxx, 1 / sxx]])
    # unit-norm columns (1, x) / (2, √14): Gram [[1, c], [c, 1]], eigenvalues 1 ± c
    c = 3 / np.sqrt(14)

    fit = scaled_least_squares(np.column_stack([np.ones(n), x]), y)

    assert isinstance(fit, LeastSquares) and fit.rank == 2 and fit.dof == 2
    np.testing.assert_allclose(fit.coefficients, [intercept, slope], rtol=1e-14)
    np.testing.assert_allclose(fit.residuals, residuals, atol=1e-14)
    assert fit.rss == pytest.approx(rss, rel=1e-14)
    assert fit.variance == pytest.approx(sigma2, rel=1e-14)
    np.testing.assert_allclose(fit.leverage, [0.7, 0.3, 0.3, 0.7], rtol=1e-14)
    np.testing.assert_allclose(fit.leverage, leverage, rtol=1e-14)
    np.testing.assert_allclose(fit.press_residuals, residuals / (1 - leverage), rtol=1e-13)
    assert fit.press == pytest.approx(float(np.sum((residuals / (1 - leverage)) ** 2)), rel=1e-13)
    np.testing.assert_allclose(fit.covariance_unscaled, unscaled, rtol=1e-13)
    np.testing.assert_allclose(fit.covariance, sigma2 * unscaled, rtol=1e-13)
    np.testing.assert_allclose(
        fit.t_statistics,
        [intercept / np.sqrt(sigma2 * unscaled[0, 0]), slope / np.sqrt(sigma2 * unscaled[1, 1])],
        rtol=1e-13,
    )
    assert fit.condition_number == pytest.approx(np.sqrt((1 + c) / (1 - c)), rel=1e-13)
    # the same line twice (k = 2 targets): per-target residuals, covariance and t
    both = scaled_least_squares(np.column_stack([np.ones(n), x]), np.column_stack([y, 2 * y]))
    np.testing.assert_allclose(
        both.residuals, np.column_stack([residuals, 2 * residuals]), atol=1e-13
    )
    np.testing.assert_allclose(both.covariance[1], 4 * sigma2 * unscaled, rtol=1e-13)
    np.testing.assert_allclose(both.t_statistics[1], fit.t_statistics, rtol=1e-13)


def test_leverage_of_other_rows_is_the_same_hat_diagonal():
    """model/leverage.leverage_of_rows with the fit's (XᵀX)⁻¹ gives the fit's own h_ii back, and
    at a new point x0 the textbook 1/n + (x0 - x̄)² / Sxx.
    """
    x = np.array([0.0, 1.0, 2.0, 3.0])
    design = np.column_stack([np.ones(4), x])
    fit = scaled_least_squares(design, np.array([1.0, 3.0, 2.0, 5.0]))
    np.testing.assert_allclose(
        leverage_of_rows(design, fit.covariance_unscaled), fit.leverage, rtol=1e-13
    )
    assert leverage_of_rows([[1.0, 5.0]], fit.covariance_unscaled)[0] == pytest.approx(
        1 / 4 + 3.5**2 / 5, rel=1e-13
    )
