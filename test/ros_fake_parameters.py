"""A node's parameters in the fake rclpy: declaration, overrides, descriptors, ranges and the set callbacks, as rclpy 7.1.

The nodes read their settings as parameters, and rclpy is strict where a loose fake would hide bugs: a declared
type is kept (a value of another type is refused unless the descriptor allows dynamic typing), an override from
``--ros-args`` or a params file replaces the declared default, a parameter declared twice is an error,
``set_descriptor`` keeps the value only if it fits the descriptor, and a descriptor's ``floating_point_range`` or
``integer_range`` refuses a value outside it -- at declaration (an exception) and at every set (a result with
rclpy's reason) -- before any on-set callback sees it.  Pre-set callbacks may rewrite what is set.  The checks,
their order and their reasons follow rclpy's ``Node._apply_descriptor``, ``_apply_floating_point_range`` and
``_apply_integer_range`` (jazzy, rclpy 7.1.3).  :class:`NodeParameters` is the part of the fake ``Node``
(``ros_fake_node``) that does this.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from enum import Enum
from typing import Any

from ros_fake_msgs import ParameterDescriptor, SetParametersResult

#: rclpy's ``Node.PARAM_REL_TOL``: a double this close to an end of its range is in it.
PARAM_REL_TOL = 1e-6


class ParameterException(Exception):
    """rclpy's base: the message, then the parameter(s) concerned."""

    def __init__(self, error_msg: str, parameters: Any) -> None:
        super().__init__(f"{error_msg}: {parameters}")


class ParameterAlreadyDeclaredException(ParameterException):
    def __init__(self, parameters: Any) -> None:
        super().__init__("Parameter(s) already declared", parameters)


class ParameterNotDeclaredException(ParameterException):
    def __init__(self, parameters: Any) -> None:
        super().__init__("Invalid access to undeclared parameter(s)", parameters)


class ParameterImmutableException(ParameterException):
    def __init__(self, parameter_name: str) -> None:
        super().__init__("Attempted to modify read-only parameter", parameter_name)


class InvalidParameterValueException(ParameterException):
    def __init__(self, parameter: str, value: Any, reason: str) -> None:
        super().__init__(f"Invalid parameter value ({value}) for parameter. Reason: {reason}", parameter)


class InvalidParameterTypeException(ParameterException):
    def __init__(self, desired: Parameter, expected_type: str) -> None:
        super().__init__(
            f"Trying to set parameter '{desired.name}' to '{desired.value}' of type '{Parameter.Type.from_parameter_value(desired.value).name}'"
            f", expecting type '{expected_type}'",
            desired.name,
        )


class Parameter:
    class Type(Enum):
        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        BYTE_ARRAY = 5
        BOOL_ARRAY = 6
        INTEGER_ARRAY = 7
        DOUBLE_ARRAY = 8
        STRING_ARRAY = 9

        @classmethod
        def from_parameter_value(cls, value: Any) -> Parameter.Type:
            if value is None:
                return cls.NOT_SET
            for kind, code in ((bool, 1), (int, 2), (float, 3), (str, 4)):
                if isinstance(value, kind):
                    return cls(code)
            if isinstance(value, (list, tuple)) or hasattr(value, "typecode"):
                for kind, code in ((bool, 6), (int, 7), (float, 8), (str, 9)):
                    if all(isinstance(v, kind) for v in value):
                        return cls(code)
            raise TypeError(f"The given value is not one of the allowed types '{value}'.")

    def __init__(self, name: str, type_: Parameter.Type | None = None, value: Any = None) -> None:
        self.name = name
        self.type_ = type_ if type_ is not None else Parameter.Type.from_parameter_value(value)
        self.value = value


_TYPE_CODES = {bool: 1, int: 2, float: 3, str: 4}
#: rcl_interfaces/ParameterType -> the field of a ParameterValue that holds a value of that type.
_VALUE_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
                6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value", 9: "string_array_value"}


def type_code(value: Any) -> int:
    """rcl_interfaces/ParameterType of a Python value, as rclpy's Parameter.Type.from_parameter_value."""
    return Parameter.Type.from_parameter_value(value).value


def _integer_range(parameter: Parameter, bounds: Any) -> SetParametersResult:
    low, high = min(bounds.from_value, bounds.to_value), max(bounds.from_value, bounds.to_value)
    if parameter.value in (low, high):
        return SetParametersResult(successful=True)
    if not low < parameter.value < high:
        return SetParametersResult(successful=False, reason=f"Parameter {parameter.name} out of range. Min: {low}, Max: {high}, value: {parameter.value}")
    if bounds.step != 0 and (parameter.value - low) % bounds.step != 0:
        return SetParametersResult(successful=False, reason=(
            f"The parameter value for {parameter.name} is not a valid step. Min: {low}, max: {high}, value: {parameter.value}, step: {bounds.step}"))
    return SetParametersResult(successful=True)


def _floating_point_range(parameter: Parameter, bounds: Any) -> SetParametersResult:
    low, high = min(bounds.from_value, bounds.to_value), max(bounds.from_value, bounds.to_value)
    if math.isclose(parameter.value, low, rel_tol=PARAM_REL_TOL) or math.isclose(parameter.value, high, rel_tol=PARAM_REL_TOL):
        return SetParametersResult(successful=True)
    if not low < parameter.value < high:
        return SetParametersResult(successful=False, reason=f"Parameter {parameter.name} out of range Min: {low}, Max: {high}, value: {parameter.value}")
    if bounds.step != 0.0:
        steps = round((parameter.value - low) / bounds.step)
        if not math.isclose(low + steps * bounds.step, parameter.value, rel_tol=PARAM_REL_TOL):
            return SetParametersResult(successful=False, reason=(
                f"The parameter value for {parameter.name} is not close enough to a valid step. "
                f"Min: {low}, max: {high}, value: {parameter.value}, step: {bounds.step}"))
    return SetParametersResult(successful=True)


class NodeParameters:
    """The parameter API of rclpy's Node, over the overrides the node was given."""

    def __init__(self, overrides: dict[str, Parameter]) -> None:
        self._parameters: dict[str, Parameter] = {}
        self._descriptors: dict[str, Any] = {}
        self._callbacks: list[Callable[[list[Parameter]], Any]] = []
        self._pre_set_callbacks: list[Callable[[list[Parameter]], list[Parameter]]] = []
        self._overrides = overrides

    # ------------------------------------------------------------------ rclpy's checks
    def _apply_descriptor(self, parameter: Parameter, descriptor: Any, check_read_only: bool = True) -> SetParametersResult:
        descriptor.name = parameter.name
        if check_read_only and descriptor.read_only:
            return SetParametersResult(successful=False, reason=f"Trying to set a read-only parameter: {parameter.name}.")
        if descriptor.dynamic_typing:
            descriptor.type = parameter.type_.value
        elif parameter.name in self._parameters and parameter.type_ == Parameter.Type.NOT_SET:
            return SetParametersResult(successful=False, reason="Static parameter cannot be undeclared")
        elif parameter.type_ != Parameter.Type.NOT_SET and parameter.type_.value != descriptor.type:
            return SetParametersResult(successful=False, reason=(
                f"Wrong parameter type, expected '{Parameter.Type(descriptor.type)}' got '{parameter.type_}'"))
        if parameter.type_ == Parameter.Type.INTEGER and descriptor.integer_range:
            return _integer_range(parameter, descriptor.integer_range[0])
        if parameter.type_ == Parameter.Type.DOUBLE and descriptor.floating_point_range:
            return _floating_point_range(parameter, descriptor.floating_point_range[0])
        return SetParametersResult(successful=True)

    def _set_common(self, parameters: list[Parameter], descriptors: dict[str, Any] | None = None) -> SetParametersResult:
        """rclpy's ``_set_parameters_atomically_common``: descriptors, then the on-set callbacks, then store."""
        for parameter in parameters:
            if descriptors is not None:
                result = self._apply_descriptor(parameter, descriptors[parameter.name], False)
            elif parameter.name in self._descriptors:
                result = self._apply_descriptor(parameter, self._descriptors[parameter.name], True)
            else:
                continue
            if not result.successful:
                return result
        for callback in self._callbacks:
            result = callback(parameters)
            if not result.successful:
                return result
        for parameter in parameters:
            if descriptors is not None:
                self._descriptors[parameter.name] = descriptors[parameter.name]
            self._parameters[parameter.name] = parameter
        return SetParametersResult(successful=True)

    # -------------------------------------------------------------------- declaration
    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None, ignore_override: bool = False) -> Parameter:
        """rclpy: the type is the default's (the descriptor's own is ignored); the override, if any, must have it
        and lie in the descriptor's range; the on-set callbacks see it."""
        descriptor = descriptor if descriptor is not None else ParameterDescriptor()
        if not descriptor.dynamic_typing:
            descriptor.type = type_code(value)
            if descriptor.type == 0:
                raise ValueError("Cannot declare a statically typed parameter with default value of type PARAMETER_NOT_SET")
        if not ignore_override and name in self._overrides:
            value = self._overrides[name].value
        parameter = Parameter(name, value=value)
        if name in self._parameters:
            raise ParameterAlreadyDeclaredException([name])
        result = self._set_common([parameter], {name: descriptor})
        if not result.successful:
            if result.reason.startswith("Wrong parameter type"):
                raise InvalidParameterTypeException(parameter, Parameter.Type(descriptor.type).name)
            raise InvalidParameterValueException(name, value, result.reason)
        return self._parameters[name]

    def set_descriptor(self, name: str, descriptor: Any, alternative_value: Any = None) -> Any:
        """rclpy: keep the value if it fits the descriptor (type and range), else take the alternative; no callbacks."""
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        if self._descriptors[name].read_only:
            raise ParameterImmutableException(name)
        current = self._parameters[name]
        alternative = current
        if alternative_value is not None:
            field = _VALUE_FIELDS.get(alternative_value.type)
            raw = None if field is None else getattr(alternative_value, field)
            alternative = Parameter(name, value=list(raw) if isinstance(raw, (list, tuple)) or hasattr(raw, "typecode") else raw)
        for candidate in (current, alternative):
            result = self._apply_descriptor(candidate, descriptor, False)
            if result.successful:
                self._parameters[name] = candidate
                self._descriptors[name] = descriptor
                return alternative_value
        raise InvalidParameterValueException(name, alternative.value, result.reason)

    def describe_parameter(self, name: str) -> Any:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def describe_parameters(self, names: list[str]) -> list[Any]:
        return [self.describe_parameter(name) for name in names]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        return self._parameters[name]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        return {n: p for n, p in self._parameters.items() if n.startswith(prefix)}

    # ------------------------------------------------------------------------ setting
    def add_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        self._callbacks.append(callback)

    def add_pre_set_parameters_callback(self, callback: Callable[[list[Parameter]], list[Parameter]]) -> None:
        self._pre_set_callbacks.append(callback)

    def set_parameters(self, parameters: list[Parameter]) -> list[Any]:
        """rclpy: each parameter set atomically on its own (``ros2 param set`` goes through the parameter
        service, which does the same)."""
        return [self.set_parameters_atomically([parameter]) for parameter in parameters]

    def set_parameters_atomically(self, parameters: list[Parameter]) -> Any:
        """rclpy: the pre-set callbacks may rewrite the list, undeclared names raise, then the descriptors
        (read-only, type, range) and the on-set callbacks decide."""
        if self._pre_set_callbacks:
            parameters = [p for callback in self._pre_set_callbacks for p in callback(parameters)]
            if not parameters:
                return SetParametersResult(successful=False, reason=(
                    "parameter list cannot be empty, this might be due to pre_set_parameters_callback modifying the original parameters list."))
        undeclared = [p.name for p in parameters if p.name not in self._parameters]
        if undeclared:
            raise ParameterNotDeclaredException(undeclared)
        return self._set_common(parameters)
