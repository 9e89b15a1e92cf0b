"""Parameter values as the code declared them, from values as a launch file or rcl typed them.

A ROS 2 user writes ``-p initial_pose:=off`` or ``speed: 2`` and expects it to work: rcl types
unquoted scalars by YAML 1.1 rules (``off`` is a bool, ``2`` an integer, ``0x10`` the integer 16)
before our code sees them.  The code declares each parameter with a default, and the default's
type is the parameter's type.  This module reconciles the two, once, for every transport:

* an integer where a float is declared is widened (``speed:=2`` is 2.0);
* a float with an integral value where an integer is declared is narrowed (``seed:=1e3``);
* where a string is declared, the text the user wrote is used when the transport knows it
  (:mod:`node_transport.ros_args` recovers it from the ROS arguments), and a number
  becomes its decimal text otherwise;
* anything else is refused with a message that says how to write the value, quoting included.
"""
from __future__ import annotations

import math

ParameterValue = bool | int | float | str | list[str] | list[float] | list[int]

_BOOL_WORDS = "yes/no/on/off/y/n/true/false"


class ParameterTypeError(ValueError):
    """An override that cannot be the declared type; the message says how to write it."""


def type_label(value: object) -> str:
    """How a message names the type of ``value``: the words of ``ros2 param describe``."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "double"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    return type(value).__name__


def _quote_hint(name: str, raw: str) -> str:
    return f"quote it: -p {name}:=\"'{raw}'\" on the command line, {name}: '{raw}' in a YAML file"


def coerce_parameter(
    node: str, name: str, default: ParameterValue, value: ParameterValue, raw: str | None = None
) -> ParameterValue:
    """``value`` converted to the type of ``default``; ParameterTypeError saying how to write it otherwise.

    ``raw`` is the text the user wrote for this parameter, when the transport knows it.
    """
    where = f"{node}: parameter {name!r}"
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        raise ParameterTypeError(f"{where} must be true or false, got {type_label(value)} {value!r}")
    if isinstance(default, str):
        if isinstance(value, str):
            return value
        if raw is not None and raw != "":
            return raw
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return repr(value) if isinstance(value, float) else str(value)
        text = str(value).lower()
        hint = f"(rcl reads unquoted {_BOOL_WORDS} as booleans); {_quote_hint(name, text)}" if isinstance(value, bool) else ""
        raise ParameterTypeError(f"{where} must be a string, got {type_label(value)} {value!r} {hint}".rstrip())
    if isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ParameterTypeError(f"{where} must be a number (double), got {type_label(value)} {value!r}: write it like {default!r}")
    if isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            return int(value)
        raise ParameterTypeError(f"{where} must be an integer, got {type_label(value)} {value!r}: write it like {default!r}")
    if isinstance(default, list):
        if isinstance(value, list):
            return value
        raise ParameterTypeError(f"{where} must be an array, got {type_label(value)} {value!r}: write it like {default!r}")
    raise ParameterTypeError(f"{where}: unsupported parameter type {type(default).__name__}")
