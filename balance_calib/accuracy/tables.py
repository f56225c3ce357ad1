"""Coefficient tables in the layout of TM-663 Tables 10-16.

Linear (Tables 10, 14): one row per component, columns 1, FXV ... MZV.
Quadratic / cubic (Tables 11-12, 15-16): per component "COEFFICIENTS OF FX", an upper-triangular
table whose row r / column c entry is the coefficient of r·c (row "1" holds the constant and the
linear terms), then the cubes as FXV**3 ... (the memo prints the moment cubes as ELV, EMV, ENV).
Terms outside that layout (temperature, absolute-value, ... terms) follow as "term  value" lines.
Given the coefficients' standard errors, a coefficient whose standard error exceeds its size is
marked WEAK_MARK (`weak_coefficients`): the data do not tell its sign.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike

from ..model.balance_model import BalanceModel
from ..model.terms import Term

_MEMO_CUBE_NAMES = {'MXV': 'ELV', 'MYV': 'EMV', 'MZV': 'ENV'}
WEAK_MARK = '*'
WEAK_NOTE = (
    f'{WEAK_MARK}: standard error larger than the coefficient itself (the data do not determine '
    'its sign)'
)


def weak_coefficients(coefficients: ArrayLike, standard_errors: ArrayLike) -> np.ndarray:
    """(n_components, n_terms) True where a coefficient's standard error exceeds its size; False
    where the error is unknown (NaN) or the coefficient is exactly zero with a zero error.
    """
    values = np.abs(np.asarray(coefficients, dtype=float))
    errors = np.asarray(standard_errors, dtype=float)
    with np.errstate(invalid='ignore'):
        weak: np.ndarray = np.isfinite(errors) & (errors > values)
    return weak


def _cell(value: float | None, weak: bool | None = None) -> str:
    """A coefficient, 11 wide; with marks (weak not None) one more column for WEAK_MARK."""
    mark = '' if weak is None else (WEAK_MARK if weak else ' ')
    return (f'{value:11.4f}' if value is not None else f'{"":11}') + (
        mark if value is not None else ' ' * len(mark)
    )


def format_linear_table(model: BalanceModel, weak: np.ndarray | None = None) -> str:
    width = 11 if weak is None else 12
    header = f'{"":6}' + ''.join(f'{name:>{width}}' for name in ['1', *model.inputs])
    lines = [header]
    for k, component in enumerate(model.components):
        cells = []
        for name in ['1', *model.inputs]:
            try:
                j = model.term_index(name)
            except ValueError:
                cells.append(_cell(None, None if weak is None else False))
                continue
            cells.append(
                _cell(model.coefficients[k, j], None if weak is None else bool(weak[k, j]))
            )
        lines.append(f'{component:6}' + ''.join(cells))
    return '\n'.join(lines)


def format_component_table(
    model: BalanceModel,
    component: str,
    memo_cube_names: bool = True,
    weak: np.ndarray | None = None,
) -> str:
    k = model.components.index(component)
    inputs = list(model.inputs)
    shown: set[str] = set()
    width = 11 if weak is None else 12

    def cell(term_name: str) -> str:
        try:
            j = model.term_index(term_name)
        except ValueError:
            return _cell(None, None if weak is None else False)
        shown.add(model.terms[j].name)
        return _cell(model.coefficients[k, j], None if weak is None else bool(weak[k, j]))

    blank = _cell(None, None if weak is None else False)
    lines = [
        f'COEFFICIENTS OF {component}',
        f'{"":8}' + ''.join(f'{n:>{width}}' for n in ['1', *inputs]),
    ]
    lines.append(f'{"1":8}' + ''.join(cell(n) for n in ['1', *inputs]))
    for r, row in enumerate(inputs):
        cells = [blank] * (r + 1)  # blank under the diagonal (and the '1' column)
        cells += [cell(f'{row}*{col}') for col in inputs[r:]]
        lines.append(f'{row:8}' + ''.join(cells))
    for name in inputs:
        try:
            model.term_index(f'{name}^3')
        except ValueError:
            continue
        label = (_MEMO_CUBE_NAMES.get(name, name) if memo_cube_names else name) + '**3'
        lines.append(f'{label:8}' + cell(f'{name}^3'))
    for j, term in enumerate(model.terms):
        if term.name not in shown:
            lines.append(
                f'{term.name:8}'
                + _cell(model.coefficients[k, j], None if weak is None else bool(weak[k, j]))
                + '   (beyond TM-663 §2)'
            )
    return '\n'.join(lines)


def format_coefficient_tables(
    model: BalanceModel, standard_errors: ArrayLike | None = None
) -> str:
    """The whole matrix in the memo's layout (linear as Table 10, others as Tables 11-12); with
    standard_errors (n_components, n_terms) the weak coefficients marked WEAK_MARK.
    """
    weak = (
        None if standard_errors is None else weak_coefficients(model.coefficients, standard_errors)
    )
    if all(
        t.degree <= 1
        and not any(f.absolute for f in t.factors)
        and set(t.variables) <= set(model.inputs)
        for t in model.terms
    ):
        return format_linear_table(model, weak)
    return '\n\n'.join(format_component_table(model, c, weak=weak) for c in model.components)


def is_memo_term(term: Term, inputs: Iterable[str]) -> bool:
    return (
        set(term.variables) <= set(inputs)
        and not any(f.absolute for f in term.factors)
        and term.degree <= 3
    )
