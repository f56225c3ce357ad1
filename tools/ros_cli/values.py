"""Values between the command line and ROS: parameter values (YAML text <-> ParameterValue),
messages as the plain data `topic echo` prints, message types by name.
"""

from __future__ import annotations

import importlib
import math

from .errors import ToolError

TYPE_NAMES = {
    1: 'bool',
    2: 'integer',
    3: 'double',
    4: 'string',
    5: 'byte array',
    6: 'bool array',
    7: 'integer array',
    8: 'double array',
    9: 'string array',
}


def parameter_value_to_python(value):
    """rcl_interfaces/ParameterValue -> a Python value (None when the parameter is not set)."""
    kind = value.type
    fields = {
        1: 'bool_value',
        2: 'integer_value',
        3: 'double_value',
        4: 'string_value',
        5: 'byte_array_value',
        6: 'bool_array_value',
        7: 'integer_array_value',
        8: 'double_array_value',
        9: 'string_array_value',
    }
    if kind not in fields:
        return None
    result = getattr(value, fields[kind])
    return list(result) if kind >= 5 else result


def python_to_parameter_value(text: str, current_type: int, name: str = ''):
    """VALUE as typed on the command line (YAML) -> ParameterValue, in the parameter's current type
    when it has one (so `set calibration_bags bag1` gives a one-element string array, and
    `set envelope_margin 2` stays a double). For a double, the words YAML 1.1 leaves as strings
    are numbers as Python spells them (`nan`, `inf`, `1e3`): the node, which knows the parameter's
    range, is the one to refuse a NaN, with its reason.
    """
    from rcl_interfaces.msg import ParameterType, ParameterValue
    import yaml

    try:
        value = yaml.safe_load(text) if text.strip() else ''
    except yaml.YAMLError:
        value = text
    out = ParameterValue()
    kind = current_type or _infer_type(value)
    try:
        if kind == ParameterType.PARAMETER_BOOL:
            if not isinstance(value, bool):
                raise ValueError
            out.bool_value = value
        elif kind == ParameterType.PARAMETER_INTEGER:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError
            out.integer_value = value
        elif kind == ParameterType.PARAMETER_DOUBLE:
            if isinstance(value, str):
                value = float(value)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError
            out.double_value = float(value)
        elif kind == ParameterType.PARAMETER_STRING:
            out.string_value = text if not isinstance(value, str) else value
        elif kind in (
            ParameterType.PARAMETER_STRING_ARRAY,
            ParameterType.PARAMETER_DOUBLE_ARRAY,
            ParameterType.PARAMETER_INTEGER_ARRAY,
            ParameterType.PARAMETER_BOOL_ARRAY,
        ):
            items = value if isinstance(value, list) else ([] if value in ('', None) else [value])
            if kind == ParameterType.PARAMETER_STRING_ARRAY:
                out.string_array_value = [str(v) for v in items]
            elif kind == ParameterType.PARAMETER_DOUBLE_ARRAY:
                out.double_array_value = [float(v) for v in items]
            elif kind == ParameterType.PARAMETER_INTEGER_ARRAY:
                out.integer_array_value = [int(v) for v in items]
            else:
                out.bool_array_value = [bool(v) for v in items]
        else:
            raise ValueError
    except (ValueError, TypeError):
        what = f' for {name}' if name else ''
        raise ToolError(
            f'value {text!r}{what} is not a {TYPE_NAMES.get(kind, "supported")} '
            "(the parameter's type)"
        ) from None
    out.type = kind
    return out


def _infer_type(value) -> int:
    if isinstance(value, bool):
        return 1
    if isinstance(value, int):
        return 2
    if isinstance(value, float):
        return 3
    if isinstance(value, list):
        if value and all(isinstance(v, bool) for v in value):
            return 6
        if value and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return 7
        if value and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return 8
        return 9
    return 4


def message_to_plain(message):
    """A ROS message -> nested dicts/lists of plain values (what `topic echo` prints as YAML)."""
    if hasattr(message, 'get_fields_and_field_types'):
        return {
            name: message_to_plain(getattr(message, name))
            for name in message.get_fields_and_field_types()
        }
    if isinstance(message, (list, tuple)) or type(message).__name__ == 'ndarray':
        return [message_to_plain(v) for v in message]
    if isinstance(message, float) and not math.isfinite(message):
        return str(message)
    if isinstance(message, (bytes, bytearray)):
        return list(message)
    return message


def message_class(type_name: str):
    """'geometry_msgs/msg/WrenchStamped' -> the class."""
    parts = type_name.split('/')
    if len(parts) != 3:
        raise ToolError(f'type {type_name!r}: expected package/msg/Name')
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise ToolError(f'type {type_name} is not installed in this environment') from None
