"""Declaring a node's parameters from its table (parameter_table.Spec): descriptor and checks.

Every node calls `declare_table` once. rclpy gets each parameter's description, range and
read-only flag (`ros2 param describe` shows them; a set of a read-only parameter is refused by
rclpy). The table's own check runs first on what the command line or a params file gave, so a bad
value is refused with our one-line reason rather than rclpy's (or a traceback), and an int given
for a double parameter (tare_timeout_s:=5) means the double. A node that takes changes at runtime
(balance_calibrator) checks them in its own on-set callback with the same check.
"""

from __future__ import annotations

import difflib
import math
from typing import Callable, Mapping

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.parameter import Parameter

from balance_calib.parameter_table import (
    DOUBLE,
    DOUBLE_ARRAY,
    INT64_MAX,
    INTEGER,
    ParameterError,
    range_text,
    Spec,
    table_checker,
)

Check = Callable[[str, object], object]
HELD_AS = {DOUBLE: Parameter.Type.DOUBLE, DOUBLE_ARRAY: Parameter.Type.DOUBLE_ARRAY}


def descriptor(spec: Spec) -> ParameterDescriptor:
    """The ParameterDescriptor of a Spec: description, read-only, range, other constraints."""
    result = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    bounded = spec.low is not None or spec.high is not None
    if bounded and spec.kind == INTEGER:
        low = -INT64_MAX - 1 if spec.low is None else int(spec.low) + int(spec.low_open)
        high = INT64_MAX if spec.high is None else int(spec.high)
        result.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
    elif bounded and spec.kind == DOUBLE:
        low = -math.inf if spec.low is None else float(spec.low)
        high = math.inf if spec.high is None else float(spec.high)
        result.floating_point_range = [FloatingPointRange(from_value=low, to_value=high)]
    if spec.choices or spec.low_open:  # what a range cannot say: rclpy's ranges are closed
        result.additional_constraints = range_text(spec)
    return result


def declare_table(node, table: Mapping[str, Spec], check: Check | None = None) -> dict:
    """Declare every parameter of `table` on `node`; name -> its value (None: a list not set).

    check(name, value) returns the value as the parameter holds it or raises ValueError with
    the reason (default: the table's check_value). Raises ParameterError (one line naming the
    parameter) for a bad value from the command line or a params file.
    """
    check = check or table_checker(table)
    overrides = getattr(node, '_parameter_overrides', {})  # command line and params files
    for name, spec in table.items():
        if name in overrides:
            value = _checked(check, name, overrides[name].value)
            if spec.kind in HELD_AS:
                overrides[name] = Parameter(name, HELD_AS[spec.kind], value)
    values = {}
    for name, spec in table.items():
        default = Parameter.Type.STRING_ARRAY if not spec.has_default else spec.default
        try:
            declared = node.declare_parameter(name, default, descriptor(spec))
        except ParameterException as err:  # what our check let through and rclpy did not
            raise ParameterError(f'parameter {name}: {err}') from None
        values[name] = _checked(check, name, declared.value)
    warning = undeclared_overrides_warning(node.get_name(), overrides, node.has_parameter, table)
    if warning:
        node.get_logger().warning(warning)
    return values


def undeclared_overrides_warning(
    node_name: str, overrides: Mapping[str, object], declared: Callable[[str], bool], table
) -> str:
    """One line naming every override (command line, params file) the node does not declare,
    with the nearest declared name; '' when there is none. rclpy drops such an override without
    a word (a misspelled `calibraton_file` left the nominal matrix running).
    """
    unknown = [name for name in overrides if not declared(name)]
    if not unknown:
        return ''
    named = []
    for name in unknown:
        near = difflib.get_close_matches(name, list(table), n=1, cutoff=0.6)
        named.append(f'{name} (did you mean {near[0]}?)' if near else name)
    return (
        f'ignoring parameter{"s" if len(named) > 1 else ""} it does not declare: '
        f'{", ".join(named)}; `{node_name} --help` lists its parameters'
    )


def _checked(check: Check, name: str, value: object) -> object:
    try:
        return check(name, value)
    except ParameterError:
        raise
    except ValueError as err:  # a check of the node's own (a file, a unit)
        raise ParameterError(str(err)) from None


def value_getter(node):
    """value(name): the parameter's current value (None for a string array never set)."""

    def value(name):
        try:
            return node.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    return value
