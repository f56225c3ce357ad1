"""A node's parameter table: name, type, default, range, description, read-only; and its check.

Each node declares its parameters from one table of `Spec` (a dict name -> Spec, in a pure module
beside the node's core), and everything else derives from that table: the declaration with a
ParameterDescriptor (nodes/_parameters.py), the check of every value at start-up and, where the
node takes changes at runtime, on every set (`check_value`), the node's `--help` (nodes/_help.py)
and docs/parameters.md (node_parameters.py). No rclpy here: tests and docs read the tables alone.

The type of a parameter is the type of its default (bool, integer, double, string, or a list of
strings or doubles); `STRING_ARRAY` as the default is a string list without a default value.
"""

from __future__ import annotations

import array
from dataclasses import dataclass
import math
from typing import Callable, Mapping

STRING_ARRAY = 'string_array'  # the default of a string list that has none (rclpy: not set)

BOOL, INTEGER, DOUBLE, STRING = 'bool', 'integer', 'double', 'string'
DOUBLE_ARRAY = 'double_array'
INT64_MAX = 2**63 - 1


class ParameterError(ValueError):
    """A parameter value a node refuses; the message is one line naming the parameter."""


@dataclass(frozen=True)
class Spec:
    """One parameter: its default (which gives its type), what it is, and the values it takes.

    low, high: inclusive range of a number (None: unbounded on that side); low_open: low itself
    is refused too (a value must exceed it, e.g. a period > 0). choices: the strings a string
    parameter takes, exactly. read_only: fixed once the node is up (set at start-up only).
    """

    default: object
    description: str
    low: float | None = None
    high: float | None = None
    read_only: bool = False
    choices: tuple[str, ...] = ()
    low_open: bool = False
    inf_allowed: bool = False  # a list of doubles whose items may be +-inf (a limit left open)

    @property
    def kind(self) -> str:
        """The parameter's type as `ros2 param describe` names it: bool, integer, double..."""
        return type_of(self.default)

    @property
    def has_default(self) -> bool:
        return not (isinstance(self.default, str) and self.default == STRING_ARRAY)


def startup(
    default: object,
    description: str,
    low: float | None = None,
    high: float | None = None,
    **options,
) -> Spec:
    """A parameter the node reads once, at start-up: read-only (a set while it runs is refused)."""
    return Spec(default, description, low, high, read_only=True, **options)


def type_of(default: object) -> str:
    """The parameter type of a default value; ValueError for one no parameter can have."""
    if isinstance(default, bool):
        return BOOL
    if isinstance(default, int):
        return INTEGER
    if isinstance(default, float):
        return DOUBLE
    if isinstance(default, str):
        return STRING_ARRAY if default == STRING_ARRAY else STRING
    if isinstance(default, (list, tuple)) and default:
        if all(isinstance(item, str) for item in default):
            return STRING_ARRAY
        if all(isinstance(item, float) for item in default):
            return DOUBLE_ARRAY
    raise ValueError(
        f'no parameter type for the default {default!r}: give a bool, int, float, '
        'str, or a non-empty list of str or of float'
    )


def range_text(spec: Spec) -> str:
    """'[10, 1e+06]', '(0, inf)', 'one of mV, mV/V'; '' when any value of the type is taken."""
    if spec.choices:
        return 'one of ' + ', '.join(spec.choices)
    if spec.low is None and spec.high is None:
        return ''
    low = '-inf' if spec.low is None else f'{spec.low:g}'
    high = 'inf' if spec.high is None else f'{spec.high:g}'
    opening = '(' if spec.low_open or spec.low is None else '['
    return f'{opening}{low}, {high}{")" if spec.high is None else "]"}'


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_number(name: str, spec: Spec, value: float) -> None:
    span = range_text(spec)
    if not math.isfinite(value):
        inside = f' in {span}' if span else ''
        raise ParameterError(f'parameter {name} must be a finite number{inside}, not {value}')
    too_low = spec.low is not None and (value <= spec.low if spec.low_open else value < spec.low)
    too_high = spec.high is not None and value > spec.high
    if too_low or too_high:
        raise ParameterError(f'parameter {name} must be in {span}, not {value:g}')


def check_value(name: str, spec: Spec, value: object) -> object:
    """The value as the parameter holds it (an integer given for a double is that double);
    ParameterError with one line naming the parameter, the values it takes and `value`.
    """
    kind = spec.kind
    if kind == BOOL:
        if not isinstance(value, bool):
            raise ParameterError(f'parameter {name} must be true or false, not {value!r}')
        return value
    if kind in (INTEGER, DOUBLE):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f'parameter {name} must be a number, not {value!r}')
        if kind == INTEGER and not isinstance(value, int):
            raise ParameterError(f'parameter {name} must be an integer, not {value!r}')
        _check_number(name, spec, value)
        return float(value) if kind == DOUBLE else value
    if kind == STRING:
        if not isinstance(value, str):
            raise ParameterError(f'parameter {name} must be a string, not {value!r}')
        if spec.choices and value not in spec.choices:
            raise ParameterError(
                f'parameter {name} must be one of {", ".join(spec.choices)} '
                f'({name} = {value!r} given)'
            )
        return value
    items = list(value) if isinstance(value, (list, tuple, array.array)) else None
    if kind == STRING_ARRAY:
        if value is None and not spec.has_default:  # a list without default, not set yet
            return None
        if items is None or not all(isinstance(item, str) for item in items):
            raise ParameterError(f'parameter {name} must be a list of strings, not {value!r}')
        return items
    if spec.inf_allowed:
        if items is None or not all(_is_number(item) and not math.isnan(item) for item in items):
            raise ParameterError(f'parameter {name} must be a list of numbers, not {value!r}')
    elif items is None or not all(_is_number(item) and math.isfinite(item) for item in items):
        raise ParameterError(f'parameter {name} must be a list of finite numbers, not {value!r}')
    return [float(item) for item in items]


def table_checker(table: Mapping[str, Spec]) -> Callable[[str, object], object]:
    """check(name, value) for a node's table: check_value of its Spec (names not in it pass)."""

    def check(name: str, value: object) -> object:
        spec = table.get(name)
        return value if spec is None else check_value(name, spec, value)

    return check


def defaults(table: Mapping[str, Spec]) -> dict[str, object]:
    """The default of every parameter that has one, by name."""
    return {name: spec.default for name, spec in table.items() if spec.has_default}


def show_default(spec: Spec) -> str:
    """The default as a params file writes it: 100, 1.0, true, 'upright', [0.0, 1.0], ''."""

    def show(value: object) -> str:
        if isinstance(value, bool):
            return 'true' if value else 'false'
        if isinstance(value, str):
            return "'" + value.replace("'", "''") + "'"
        if isinstance(value, (list, tuple)):
            return '[' + ', '.join(show(item) for item in value) + ']'
        return repr(value)

    return show(spec.default) if spec.has_default else '(none: a string list)'


def problems(table: Mapping[str, Spec]) -> list[str]:
    """What is wrong with a table itself (a default outside its range, a range on a string...)."""
    found = []
    for name, spec in table.items():
        try:
            kind = spec.kind
            if spec.has_default:
                check_value(name, spec, spec.default)
        except ValueError as err:
            found.append(f'{name}: {err}')
            continue
        if (spec.low is not None or spec.high is not None) and kind not in (INTEGER, DOUBLE):
            found.append(f'{name}: a range on a {kind} parameter')
        if spec.choices and kind != STRING:
            found.append(f'{name}: choices on a {kind} parameter')
        if spec.inf_allowed and kind != DOUBLE_ARRAY:
            found.append(f'{name}: inf_allowed on a {kind} parameter')
        if len(spec.description) < 10:
            found.append(f'{name}: no description')
    return found
