"""Which terms of a candidate set a load schedule determines (R-091 practice: a term the schedule
cannot separate from the others is left out of the math model, not solved for).

The judgement is made on columns the schedule sets (term values of the applied loads, or of
the loads each output follows), in order of priority: the nuisance columns (series tares) first,
then the terms by degree, single-variable terms before products, in the set's order. A term is kept
when the part of its column that the columns already kept cannot explain is at least `SEPARATION`
of its norm (modified Gram-Schmidt, unit-norm columns, twice for stability). Then hierarchy: a
product term stays only with its single-variable factors (those of the set). Last, the number of
points: terms are dropped from the end of the priority order until every load keeps at least
`min_dof` residual degrees of freedom (N - terms - tares), so PRESS and σ stay defined.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..model.terms import Term

# fraction of a column's norm that must be new to the columns already kept (loads set to 0.1 % are
# separable; a product of two loads never applied together is an exact zero column)
SEPARATION = 1e-3


@dataclass(frozen=True)
class TermScreen:
    kept: tuple[Term, ...]  # in the set's own order
    dropped: tuple[tuple[str, str], ...]  # (term name, one-line reason), in screening order
    no_room: tuple[str, ...] = ()  # dropped for want of points


def _factor_terms(term: Term) -> tuple[Term, ...]:
    """The single-variable parts of a product term (FZ*|MZ| -> FZ, |MZ|); () for others."""
    if len(term.variables) < 2:
        return ()
    return tuple(Term((f,)) for f in term.factors)


def priority(terms: Sequence[Term]) -> list[int]:
    """Indices of `terms` in screening order: degree, one-variable before products, set order."""
    return sorted(
        range(len(terms)), key=lambda j: (terms[j].degree, len(terms[j].variables) > 1, j)
    )


def screen_terms(
    terms: Sequence[Term], columns: np.ndarray, nuisance: np.ndarray, *, min_dof: int = 2
) -> TermScreen:
    """Keep the terms the schedule separates.

    Parameters
    ----------
    terms : the candidate terms (p,)
    columns : (N, p) each term's values at the schedule's points (exact set values, any unit)
    nuisance : (N, q) columns always kept (series tares: one-hot per series)
    min_dof : residual degrees of freedom to leave: N - kept - q >= min_dof

    Returns
    -------
    TermScreen with the kept terms and a reason for every dropped one.
    """
    terms = tuple(terms)
    n = columns.shape[0]
    basis = np.zeros((n, 0))

    def orthogonal_part(column: np.ndarray) -> np.ndarray:
        vector = column / np.linalg.norm(column)
        for _ in range(2):
            vector = vector - basis @ (basis.T @ vector)
        part: np.ndarray = vector
        return part

    def new_part(column: np.ndarray) -> float:
        return float(np.linalg.norm(orthogonal_part(column))) if np.any(column) else 0.0

    def accept(column: np.ndarray) -> None:
        nonlocal basis
        vector = orthogonal_part(column)
        basis = np.hstack([basis, (vector / np.linalg.norm(vector))[:, None]])

    for k in range(nuisance.shape[1]):
        if new_part(nuisance[:, k]) >= SEPARATION:
            accept(nuisance[:, k])
    q = basis.shape[1]
    kept: list[int] = []
    dropped: list[tuple[str, str]] = []
    names = [t.name for t in terms]
    order = priority(terms)
    for j in order:
        needed = [f.name for f in _factor_terms(terms[j]) if f.name in names]
        missing = [f for f in needed if names.index(f) not in kept]
        if missing:
            dropped.append(
                (names[j], f'hierarchy: its factor(s) {", ".join(missing)} not in the model')
            )
            continue
        part = new_part(columns[:, j])
        if part < SEPARATION:
            why = (
                'the schedule never applies it (column all zero)'
                if not np.any(columns[:, j])
                else f'the schedule cannot separate it from the terms and tares kept before it '
                f'({100 * part:.2g} % of its column is new)'
            )
            dropped.append((names[j], why))
            continue
        accept(columns[:, j])
        kept.append(j)
    limit = n - q - min_dof
    no_room: list[str] = []
    if len(kept) > limit:
        by_priority = [j for j in order if j in kept]
        for j in by_priority[max(limit, 0) :]:
            no_room.append(names[j])
            dropped.append(
                (
                    names[j],
                    f'{n} points leave room for {max(limit, 0)} terms beside '
                    f'{q} series tares and {min_dof} residual degrees of '
                    f'freedom',
                )
            )
        kept = by_priority[: max(limit, 0)]
    return TermScreen(tuple(terms[j] for j in sorted(kept)), tuple(dropped), tuple(no_room))
