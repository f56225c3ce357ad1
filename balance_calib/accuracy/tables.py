"""Coefficient tables in the layout of TM-663 Tables 10-16.

Linear (Tables 10, 14): one row per component, columns 1, FXV ... MZV.
Quadratic / cubic (Tables 11-12, 15-16): per component "COEFFICIENTS OF FX", an upper-triangular
table whose row r / column c entry is the coefficient of r·c (row "1" holds the constant and the
linear terms), then the cubes as FXV**3 ... (the memo prints the moment cubes as ELV, EMV, ENV).
Terms outside that layout (temperature, absolute-value, ... terms) follow as "term  value" lines.
"""

from __future__ import annotations

from ..model.balance_model import BalanceModel
from ..model.terms import Term

_MEMO_CUBE_NAMES = {'MXV': 'ELV', 'MYV': 'EMV', 'MZV': 'ENV'}


def _cell(value) -> str:
    return f'{value:11.4f}' if value is not None else f'{"":11}'


def format_linear_table(model: BalanceModel) -> str:
    header = f'{"":6}' + ''.join(f'{name:>11}' for name in ['1', *model.inputs])
    lines = [header]
    for k, component in enumerate(model.components):
        values = []
        for name in ['1', *model.inputs]:
            try:
                values.append(model.coefficients[k, model.term_index(name)])
            except ValueError:
                values.append(None)
        lines.append(f'{component:6}' + ''.join(_cell(v) for v in values))
    return '\n'.join(lines)


def format_component_table(
    model: BalanceModel, component: str, memo_cube_names: bool = True
) -> str:
    k = model.components.index(component)
    inputs = list(model.inputs)
    shown: set[str] = set()

    def coefficient(term_name):
        try:
            j = model.term_index(term_name)
        except ValueError:
            return None
        shown.add(model.terms[j].name)
        return model.coefficients[k, j]

    lines = [
        f'COEFFICIENTS OF {component}',
        f'{"":8}' + ''.join(f'{n:>11}' for n in ['1', *inputs]),
    ]
    lines.append(f'{"1":8}' + ''.join(_cell(coefficient(n)) for n in ['1', *inputs]))
    for r, row in enumerate(inputs):
        cells = [None] * (r + 1)  # blank under the diagonal (and the '1' column)
        cells += [coefficient(f'{row}*{col}') for col in inputs[r:]]
        lines.append(f'{row:8}' + ''.join(_cell(c) for c in cells))
    for name in inputs:
        value = coefficient(f'{name}^3')
        if value is not None:
            label = (_MEMO_CUBE_NAMES.get(name, name) if memo_cube_names else name) + '**3'
            lines.append(f'{label:8}' + _cell(value))
    for j, term in enumerate(model.terms):
        if term.name not in shown:
            lines.append(
                f'{term.name:8}' + _cell(model.coefficients[k, j]) + '   (beyond TM-663 §2)'
            )
    return '\n'.join(lines)


def format_coefficient_tables(model: BalanceModel) -> str:
    """The whole matrix in the memo's layout (linear as Table 10, others as Tables 11-12)."""
    if all(
        t.degree <= 1
        and not any(f.absolute for f in t.factors)
        and set(t.variables) <= set(model.inputs)
        for t in model.terms
    ):
        return format_linear_table(model)
    return '\n\n'.join(format_component_table(model, c) for c in model.components)


def is_memo_term(term: Term, inputs) -> bool:
    return (
        set(term.variables) <= set(inputs)
        and not any(f.absolute for f in term.factors)
        and term.degree <= 3
    )
