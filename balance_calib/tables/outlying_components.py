"""A component whose residuals stand out, named with its points, and a term of its own channel
offered when it removes the structure (refit's closing of the loop).

A load is odd when its cross-validated σ (% capacity) is more than ODD_RATIO times the median of
the other loads', or when some of its leave-one-out residuals lie beyond ODD_ROBUST_SIGMAS robust
σ (1.4826 MAD) of its own: a knee at low load, one series' first step far off the line. The points
furthest off are named. Then each candidate term of the load's own channel (square, x|x| and |x|
of the output that follows it in the direct form, of the load itself in the iterative form) that
the model lacks is added in turn and the form refitted; the one that lowers the load's
cross-validated σ most, by at least OFFER_GAIN, is offered as an effect with its before/after
(not adopted: the live node runs the adopted model). Otherwise the load goes to `unexplained`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..model.terms import Term
from .model_selection import crossval_pct, FIT_ERRORS, fit_form
from .term_screen import dominant_loads, linear_response

ODD_RATIO = 3.0
ODD_ROBUST_SIGMAS = 6.0
OFFER_GAIN = 0.10  # the load's cross-validated σ lower by at least 10 %
NAMED_POINTS = 5


def _own_channel_terms(method: str, k: int, table, outputs: np.ndarray) -> list[Term]:
    if method == 'direct':
        relative, onehot, response = linear_response(table, outputs)
        follows = dominant_loads(relative, onehot, outputs, response)
        channels = [table.bridge_symbols[j] for j in range(len(follows)) if follows[j] == k]
        variable = channels[0] if channels else table.bridge_symbols[min(k, len(outputs[0]) - 1)]
    else:
        variable = table.load_symbols[k]
    return [
        Term.parse(f'{variable}^2'),
        Term.parse(f'{variable}*|{variable}|'),
        Term.parse(f'|{variable}|'),
    ]


def outlying_components(
    method: str, fit, terms: Sequence[Term], table, outputs: np.ndarray
) -> tuple[list[dict], list[dict]]:
    """(effects offered, unexplained entries) for the adopted fit, interfaces.md's keys."""
    capacity = table.load_capacity_si
    cv = crossval_pct(fit, capacity)
    press = fit.press_load_residuals / capacity * 100.0
    effects, unexplained = [], []
    names = {t.name for t in terms}
    for k, symbol in enumerate(table.load_symbols):
        others = np.delete(cv, k)
        ratio = float(cv[k] / max(np.median(others), 1e-300)) if len(others) else 1.0
        column = press[:, k]
        robust = 1.4826 * np.median(np.abs(column - np.median(column)))
        far = np.abs(column) > ODD_ROBUST_SIGMAS * max(robust, 1e-300)
        if not (ratio > ODD_RATIO or np.any(far)):
            continue
        worst = np.argsort(-np.abs(column))[:NAMED_POINTS]
        points = [table.point_id[i] for i in worst]
        listed = ', '.join(f'{table.point_id[i]} {column[i]:+.3g} %' for i in worst[:3])
        evidence = (
            f'{symbol} cross-validated σ {cv[k]:.3g} % capacity, {ratio:.1f}x the other '
            f"loads' median; {int(far.sum())} point(s) beyond {ODD_ROBUST_SIGMAS:g} robust σ; "
            f'furthest off: {listed}'
        )
        best = None
        for term in _own_channel_terms(method, k, table, outputs):
            if term.name in names:
                continue
            try:
                trial = fit_form(method, tuple(terms) + (term,), table, outputs)
            except FIT_ERRORS:
                continue
            after = crossval_pct(trial, capacity)
            if (
                after[k] <= (1 - OFFER_GAIN) * cv[k]
                and np.mean(after) < np.mean(cv)
                and (best is None or after[k] < best[1][k])
            ):
                best = (term, after)
        if best is not None:
            term, after = best
            effects.append(
                {
                    'name': 'bidirectional'
                    if any(f.absolute for f in term.factors)
                    else 'nonlinearity',
                    'components': [symbol],
                    'evidence': f'{evidence}; adding {term.name} lowers it to {after[k]:.3g} %',
                    'terms': [term.name],
                    'points': points,
                    'sigma_before_pct_fs': {symbol: round(float(cv[k]), 5)},
                    'sigma_after_pct_fs': {symbol: round(float(after[k]), 5)},
                    'adopted': False,
                }
            )
        else:
            unexplained.append(
                {
                    'components': [symbol],
                    'points': points,
                    'evidence': evidence
                    + '; no square, x|x| or |x| term of its own channel removes it',
                    'tracks': 'nothing found',
                    'sigma_pct_fs': {symbol: round(float(cv[k]), 5)},
                }
            )
    return effects, unexplained
