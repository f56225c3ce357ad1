"""The terms of a table's candidate set that its load schedule determines, per model form.

The iterative form's terms are polynomials of the loads: judged at the applied loads the schedule
sets (tares, unknown, are the nuisance columns). The direct form's are polynomials of the outputs:
a term is dropped when the loads its bridges follow (each output's dominant load in a least-squares
fit of the outputs on the applied loads and the series) are never applied together, or when the
measured output columns leave nothing of it the other terms and tares do not explain. Cross-talk
and noise make such a product's measured column non-zero; it would be fitted to noise.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..fit.determinable import screen_terms, TermScreen
from ..fit.series_tares import series_indicator
from ..fit.svd import minimum_norm_solve
from ..model.r091 import TermEvaluator
from ..model.terms import Factor, Term
from .errors import TableCalibrationError


def linear_response(table, outputs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(applied / capacity (N, n_loads), series one-hot (N, n_series), response (n_loads, n_out)):
    least squares of the outputs on the applied loads (fractions of capacity) and the series, so
    response[v, k] is output k's change from zero to capacity of load v.
    """
    _, _, onehot = series_indicator(table.series)
    relative = table.applied_loads_si / table.load_capacity_si
    n_loads = relative.shape[1]
    response = minimum_norm_solve(np.hstack([relative, onehot]), outputs).solution[:n_loads]
    return relative, onehot, response


def dominant_loads(
    relative_loads: np.ndarray,
    onehot: np.ndarray,
    outputs: np.ndarray,
    response: np.ndarray | None = None,
) -> np.ndarray:
    """(n_outputs,) index of the load each output follows most (response at capacity)."""
    n_loads = relative_loads.shape[1]
    if response is None:
        response = minimum_norm_solve(np.hstack([relative_loads, onehot]), outputs).solution
        response = response[:n_loads]
    scale = np.maximum(np.max(np.abs(response), axis=0), 1e-300)
    return np.argmax(np.abs(response) / scale, axis=0)


def schedule_columns(
    method: str,
    terms: Sequence[Term],
    applied_si: np.ndarray,
    capacity: np.ndarray,
    outputs: np.ndarray,
    series: np.ndarray,
    inputs: Sequence[str],
    loads: Sequence[str],
) -> tuple[np.ndarray, np.ndarray]:
    """((N, p) term columns, (N, n_series) one-hot of the series): the iterative form's at the
    applied loads; the direct form's from the measured outputs, zero where the schedule never
    applies the loads its bridges follow together.
    """
    _, _, onehot = series_indicator(series)
    relative = applied_si / capacity
    if method == 'iterative':
        return TermEvaluator(terms, loads).design(relative), onehot
    follows = dominant_loads(relative, onehot, outputs)
    load_of = {name: loads[follows[j]] for j, name in enumerate(inputs)}
    as_loads = tuple(
        Term(tuple(Factor(load_of[f.variable], f.power, f.absolute) for f in t.factors))
        for t in terms
    )
    by_name = dict(zip(loads, relative.T))
    applied_together = np.array([np.any(t.evaluate(by_name, len(relative))) for t in as_loads])
    measured = TermEvaluator(terms, inputs).design(outputs)
    return measured * applied_together[None, :], onehot


def screen_for_table(
    method: str, terms: Sequence[Term], table, outputs: np.ndarray, min_dof: int = 2
) -> TermScreen:
    """The determinable terms of one form; TableCalibrationError when none is left."""
    columns, onehot = schedule_columns(
        method,
        terms,
        table.applied_loads_si,
        table.load_capacity_si,
        outputs,
        table.series,
        table.bridge_symbols,
        table.load_symbols,
    )
    screen = screen_terms(terms, columns, onehot, min_dof=min_dof)
    linear = [t.name for t in terms if t.degree == 1 and not t.factors[0].absolute]
    kept_linear = [t for t in screen.kept if t.name in linear]
    # the loads cannot be told apart without a linear term per load: a schedule too short for them
    # is "nothing left" (a dead channel's term is dropped too, but the channels gate judges that)
    lost = [name for name in screen.no_room if name in linear]
    if not kept_linear or (lost and len(kept_linear) < table.n_loads):
        raise TableCalibrationError(
            f'{table.source}: the load schedule determines none of the {method} models: '
            f'{len(kept_linear)} of the {table.n_loads} linear terms are left ({table.points} '
            f'points, '
            f'{onehot.shape[1]} series: no room for {", ".join(lost) or "any"})'
        )
    return screen
