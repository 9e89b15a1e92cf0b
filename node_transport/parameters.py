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

A numeric parameter may carry its range the ROS way (:class:`NumericRange`: rcl_interfaces' FloatingPointRange
or IntegerRange in its descriptor), so ``ros2 param describe`` shows it and rclpy refuses a value outside it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

ParameterValue = bool | int | float | str | list[str] | list[float] | list[int]

_BOOL_WORDS = "yes/no/on/off/y/n/true/false"


class ParameterTypeError(ValueError):
    """An override that cannot be the declared type; the message says how to write it."""


#: rclpy's relative tolerance for a double at the edge of its range (``Node.PARAM_REL_TOL``).
RANGE_REL_TOL = 1e-6


@dataclass(frozen=True)
class NumericRange:
    """The range a numeric parameter carries in its ROS descriptor: ``floating_point_range`` for a double,
    ``integer_range`` for an integer (rcl_interfaces' FloatingPointRange / IntegerRange).

    ``step`` 0 means any value in [from_value, to_value]; otherwise the values from_value + k * step and
    to_value.  :meth:`refusal` is rclpy 7.1's own check (``Node._apply_floating_point_range`` and
    ``_apply_integer_range``) with its reasons, so a transport without rcl refuses what rclpy refuses and
    says it the same way."""

    from_value: float
    to_value: float
    step: float = 0

    def refusal(self, name: str, value: ParameterValue) -> str:
        """rclpy's reason for refusing ``value`` for parameter ``name`` ("" when it lies in the range).

        Only a number is checked, as rclpy checks a range only against a value of the parameter's type."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return ""
        low, high = min(self.from_value, self.to_value), max(self.from_value, self.to_value)
        if isinstance(value, int):
            if value in (low, high):
                return ""
            if not low < value < high:
                return f"Parameter {name} out of range. Min: {low}, Max: {high}, value: {value}"
            if self.step != 0 and (value - low) % self.step != 0:
                return (f"The parameter value for {name} is not a valid step. "
                        f"Min: {low}, max: {high}, value: {value}, step: {self.step}")
            return ""
        if math.isclose(value, low, rel_tol=RANGE_REL_TOL) or math.isclose(value, high, rel_tol=RANGE_REL_TOL):
            return ""
        if not low < value < high:
            return f"Parameter {name} out of range Min: {low}, Max: {high}, value: {value}"
        if self.step != 0:
            steps = round((value - low) / self.step)
            if not math.isclose(low + steps * self.step, value, rel_tol=RANGE_REL_TOL):
                return (f"The parameter value for {name} is not close enough to a valid step. "
                        f"Min: {low}, max: {high}, value: {value}, step: {self.step}")
        return ""

    def for_type(self, default: ParameterValue) -> NumericRange:
        """This range as a parameter of ``default``'s type carries it: integers for an integer parameter, doubles
        for a double (rclpy checks an IntegerRange only against integers, a FloatingPointRange only against doubles).
        ValueError for a parameter that is not a number."""
        if isinstance(default, bool) or not isinstance(default, (int, float)):
            raise ValueError(f"a range needs an integer or double parameter, not {type_label(default)} {default!r}")
        if isinstance(default, int):
            step = int(self.step)
            return NumericRange(math.ceil(self.from_value), math.floor(self.to_value), 0 if step == 1 else step)  # step 1: every integer, as 0 says
        return NumericRange(float(self.from_value), float(self.to_value), float(self.step))


def descriptor_range(numeric_range: NumericRange | None, floating_point_range: type, integer_range: type) -> dict[str, list[Any]]:
    """The ``floating_point_range`` or ``integer_range`` field of a ParameterDescriptor holding ``numeric_range`` (a
    bounded sequence of one), built with the transport's classes of those messages; ``{}`` without a range."""
    if numeric_range is None:
        return {}
    if isinstance(numeric_range.from_value, int):
        low, high, step = int(numeric_range.from_value), int(numeric_range.to_value), int(numeric_range.step)
        return {"integer_range": [integer_range(from_value=low, to_value=high, step=step)]}
    low_f, high_f, step_f = float(numeric_range.from_value), float(numeric_range.to_value), float(numeric_range.step)
    return {"floating_point_range": [floating_point_range(from_value=low_f, to_value=high_f, step=step_f)]}


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
