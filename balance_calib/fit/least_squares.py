"""Least-squares fit of a balance model, TM-663 §3: minimise eq. (19).

Eq. (19) sums the squared load errors of all six components; every component shares the same
design matrix, so it separates into one least-squares problem per component with a common
matrix. We solve it with column scaling, pivoted QR to find the terms the load schedule does not
excite, and SVD for the solution and the coefficient covariance; never the normal equations that
eq. (28) writes (they square the condition number).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import scipy.linalg

from ..model.balance_model import BalanceModel
from ..model.terms import Term, as_variables, design_matrix
from ..units import BRIDGE_OUTPUTS, COMPONENTS

# A term whose rated-scaled column, after removing what the other terms already explain, keeps
# less than this fraction of a fully excited column is "not excited by the schedule".
UNEXCITED_TOLERANCE = 1e-4


class UnexcitedTermsError(ValueError):
    """The load schedule leaves some terms undetermined; the message names them."""

    def __init__(self, terms: Sequence[str], model_name: str):
        self.terms = tuple(terms)
        super().__init__(
            f'the load schedule does not excite {len(self.terms)} term(s) of the {model_name} model: '
            f'{", ".join(self.terms)}; load those bridges (alone and combined) or fit a smaller model')


class TooFewPointsError(ValueError):
    """More coefficients than points: the message says how many of each."""

    def __init__(self, points: int, terms: int, tares: int, model_name: str):
        super().__init__(
            f'{points} points cannot determine the {model_name} model\'s {terms} terms and {tares} '
            f'series tare(s) (it needs at least {terms + tares + 1} points); fit fewer terms')


@dataclass(frozen=True)
class FitResult:
    """A fitted model with what a person needs to trust it."""

    model: BalanceModel
    rank: int
    condition_number: float              # of the column-scaled design matrix
    unexcited_terms: tuple[str, ...]     # fixed at zero (only with on_unexcited='drop')
    standard_errors: np.ndarray          # (n_components, n_terms), same units as coefficients
    residuals: np.ndarray                # (N, n_components): measured - fitted load, N / N·m
    degrees_of_freedom: int

    @property
    def points(self) -> int:
        return self.residuals.shape[0]


def term_scales(terms: Sequence[Term], rated_outputs: Mapping[str, float] | None,
                design: np.ndarray) -> np.ndarray:
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


def fit_model(terms: Sequence[Term], bridge_outputs_mv, loads, *, name: str = 'custom',
              extra: Mapping[str, np.ndarray] | None = None,
              rated_outputs: Mapping[str, float] | None = None,
              components: Sequence[str] = COMPONENTS, inputs: Sequence[str] = BRIDGE_OUTPUTS,
              on_unexcited: str = 'raise') -> FitResult:
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
    design = design_matrix(terms, as_variables(tuple(inputs), outputs, extra), n_points)

    # Column scaling by the term's size at rated output, normalised so a fully excited column
    # has norm about 1.
    scales = term_scales(terms, rated_outputs, design) * np.sqrt(max(n_points, 1))
    scaled = design / scales

    # Pivoted QR: columns in order of how much new information each brings.
    _, r_factor, pivots = scipy.linalg.qr(scaled, mode='economic', pivoting=True)
    diagonal = np.abs(np.diag(r_factor)) if r_factor.size else np.zeros(0)
    diagonal = np.concatenate([diagonal, np.zeros(n_terms - diagonal.size)])
    excited_mask = np.zeros(n_terms, dtype=bool)
    excited_mask[pivots[diagonal > UNEXCITED_TOLERANCE]] = True
    unexcited = tuple(terms[j].name for j in range(n_terms) if not excited_mask[j])
    if unexcited and on_unexcited == 'raise':
        raise UnexcitedTermsError(unexcited, name)
    if on_unexcited not in ('raise', 'drop'):
        raise ValueError(f"on_unexcited must be 'raise' or 'drop', not {on_unexcited!r}")

    kept = np.flatnonzero(excited_mask)
    if kept.size > n_points:
        raise UnexcitedTermsError([terms[j].name for j in kept[n_points:]], name)
    u, singular, vt = np.linalg.svd(scaled[:, kept], full_matrices=False)
    solution_scaled = vt.T @ ((u.T @ targets) / singular[:, None])        # (kept, n_components)
    coefficients = np.zeros((targets.shape[1], n_terms))
    coefficients[:, kept] = (solution_scaled / scales[kept, None]).T

    fitted = design @ coefficients.T
    residuals = targets - fitted
    dof = n_points - kept.size
    variance = (residuals ** 2).sum(axis=0) / dof if dof > 0 else np.full(targets.shape[1], np.nan)
    covariance_diag = ((vt.T / singular) ** 2).sum(axis=1)               # diag((Xs^T Xs)^-1)
    standard_errors = np.zeros_like(coefficients)
    standard_errors[:, kept] = np.sqrt(np.outer(variance, covariance_diag)) / scales[kept]
    condition = float(singular[0] / singular[-1]) if singular.size else float('inf')
    model = BalanceModel(name, terms, coefficients, tuple(components), tuple(inputs))
    return FitResult(model, int(kept.size), condition, unexcited, standard_errors, residuals, dof)


def refit_like(model: BalanceModel, bridge_outputs_mv, loads, **kwargs) -> FitResult:
    """Fit the term list of an existing model to new data."""
    return fit_model(model.terms, bridge_outputs_mv, loads, name=model.name,
                     components=model.components, inputs=model.inputs, **kwargs)
