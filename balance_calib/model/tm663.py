"""The math models of TM-663 §2 and the memo's coefficient numbering C1...C204.

This module is the one source of truth for the term order: eqs. (1)-(6) (linear, 7 terms per
component, C1-C42), eqs. (7)-(12) (quadratic, 28 terms, C1-C168) and eqs. (13)-(18) (cubic,
34 terms, C1-C204). Component k (FX=0 ... MZ=5) and term j (0-based) carry the coefficient
number C_{k*n_terms + j + 1}. Fitting, evaluation, YAML files and printed tables all derive
from the lists below.
"""

from __future__ import annotations

from itertools import combinations
from typing import Sequence

from ..units import BRIDGE_OUTPUTS
from .terms import parse_terms, Term

MODEL_ORDERS = ('linear', 'quadratic', 'cubic')


def _names(order: str, outputs: Sequence[str] = BRIDGE_OUTPUTS) -> list[str]:
    names = ['1'] + list(outputs)  # eqs. (1)-(6)
    if order in ('quadratic', 'cubic'):
        names += [f'{v}^2' for v in outputs]  # C8-C13 of eq. (7)
        names += [f'{a}*{b}' for a, b in combinations(outputs, 2)]  # C14-C28 of eq. (7)
    if order == 'cubic':
        names += [f'{v}^3' for v in outputs]  # C29-C34 of eq. (13)
    if order not in MODEL_ORDERS:
        raise ValueError(f'unknown model {order!r}; expected one of {", ".join(MODEL_ORDERS)}')
    return names


def tm663_terms(order: str, outputs: Sequence[str] = BRIDGE_OUTPUTS) -> tuple[Term, ...]:
    """The term list of TM-663 §2.1 (linear), §2.2 (quadratic) or §2.3 (cubic), in the memo's
    order.
    """
    return parse_terms(_names(order, outputs))


def coefficient_number(component_index: int, term_index: int, n_terms: int) -> int:
    """TM-663's C index (1-based) of a coefficient: C_{k*n_terms + j + 1}."""
    return component_index * n_terms + term_index + 1


def constant_coefficient_numbers(n_terms: int, n_components: int = 6) -> tuple[int, ...]:
    """The constants dropped for wind-on use, §10.1: (1,8,15,...), (1,29,57,...), (1,35,69,...)."""
    return tuple(coefficient_number(k, 0, n_terms) for k in range(n_components))
