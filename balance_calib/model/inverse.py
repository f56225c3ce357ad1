"""The inverse of a balance model: loads -> bridge outputs, by Newton iteration.

Used to simulate a balance (a matrix as the truth gives the outputs that a load produces) and for
tare outputs. The linear part gives the starting point; each step solves J(V) dV = L - f(V).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from .balance_model import BalanceModel


class InverseDidNotConverge(ArithmeticError):
    """Newton's method did not reach the requested tolerance for some samples."""


def linear_part(model: BalanceModel) -> np.ndarray:
    """(n_components, n_inputs) matrix of the first-order coefficients."""
    matrix = np.zeros((len(model.components), len(model.inputs)))
    for j, term in enumerate(model.terms):
        if (
            term.degree == 1
            and len(term.factors) == 1
            and not term.factors[0].absolute
            and term.factors[0].variable in model.inputs
        ):
            matrix[:, model.inputs.index(term.factors[0].variable)] = model.coefficients[:, j]
    return matrix


def outputs_for_loads(
    model: BalanceModel,
    loads: ArrayLike,
    extra: Mapping[str, np.ndarray] | None = None,
    tolerance: float = 1e-12,
    max_iterations: int = 50,
) -> np.ndarray:
    """Bridge outputs V (N, n_inputs) with model.loads(V) = loads (N, n_components).

    tolerance is relative to the norm of the linear part times a typical output, i.e. a load error
    of about 1e-12 of full scale. Raises InverseDidNotConverge naming the samples that failed.
    """
    targets = np.atleast_2d(np.asarray(loads, dtype=float))
    if len(model.components) != len(model.inputs):
        raise ValueError('the inverse needs as many components as bridge outputs')
    if not np.all(np.isfinite(targets)):
        raise ValueError('loads contain NaN or infinity')
    linear = linear_part(model)
    try:
        linear_inverse = np.linalg.inv(linear)
    except np.linalg.LinAlgError:
        raise InverseDidNotConverge('the linear part of the model is singular') from None
    constant = model.loads(np.zeros((targets.shape[0], len(model.inputs))), extra)
    outputs: FloatArray = (targets - constant) @ linear_inverse.T
    scale = np.maximum(np.abs(targets), 1e-9 * (np.abs(linear).max() + 1.0))
    for _ in range(max_iterations):
        error = targets - model.loads(outputs, extra)
        if np.all(np.abs(error) <= tolerance * np.maximum(scale, np.abs(linear).max())):
            return outputs
        jac = model.jacobian(outputs, extra)
        try:
            step = np.linalg.solve(jac, error[..., None])[..., 0]
        except np.linalg.LinAlgError:
            raise InverseDidNotConverge('the model Jacobian is singular at some load') from None
        outputs = outputs + step
        if not np.all(np.isfinite(outputs)):
            break
    error = targets - model.loads(outputs, extra)
    bad = np.flatnonzero(
        np.any(~np.isfinite(error) | (np.abs(error) > 1e-6 * np.maximum(scale, 1.0)), axis=1)
    )
    if bad.size == 0:
        return outputs
    raise InverseDidNotConverge(
        f'Newton inverse of model {model.name} did not converge for {bad.size} of {len(targets)} '
        f'load(s), first at index {bad[0]} (loads {np.round(targets[bad[0]], 4).tolist()}); '
        f'the load is probably outside the range the model is valid for'
    )
