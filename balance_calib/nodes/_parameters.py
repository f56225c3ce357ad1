"""Declaring a node's parameters from a table of Spec (live/parameters.py): description, range, checks.

rclpy shows the description and range (`ros2 param describe`); the table's own check runs first on
what the command line or a params file gave, so a bad value is refused with our one-line reason
rather than rclpy's, and an int given for a float parameter (tare_timeout_s:=5) means the float.
"""
from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter


def descriptor(spec) -> ParameterDescriptor:
    result = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.low is not None and isinstance(spec.default, int):
        result.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)]
    elif spec.low is not None:
        result.floating_point_range = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high))]
    return result


def declare_checked(node, table: dict, check, string_array: str) -> None:
    """Declare every parameter of `table`; check(name, value) raises ValueError with the reason.
    Raises ValueError or rclpy's ParameterException for a bad value."""
    overrides = getattr(node, '_parameter_overrides', {})     # command line and params files
    for name, spec in table.items():
        if name in overrides and spec.default != string_array:
            value = overrides[name].value
            check(name, value)
            if type(spec.default) is float and type(value) is int:
                overrides[name] = Parameter(name, value=float(value))
    for name, spec in table.items():
        default = Parameter.Type.STRING_ARRAY if spec.default == string_array else spec.default
        node.declare_parameter(name, default, descriptor(spec))
        if spec.default != string_array:
            check(name, node.get_parameter(name).value)


def value_getter(node):
    """name -> the parameter's current value (None for a string array never set)."""
    def value(name):
        try:
            return node.get_parameter(name).value
        except ParameterUninitializedException:
            return None
    return value
