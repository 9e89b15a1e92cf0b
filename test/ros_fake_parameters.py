"""A node's parameters in the fake rclpy: declaration, overrides, descriptors and on-set callbacks, as rclpy 7.1.

The nodes read their settings as parameters, and rclpy is strict where a loose fake would hide bugs: a declared
type is kept (a value of another type is refused unless the descriptor allows dynamic typing), an override from
``--ros-args`` or a params file replaces the declared default, a parameter declared twice is an error, and
``set_descriptor`` keeps the value only if it has the descriptor's type.  :class:`NodeParameters` is the part of
the fake ``Node`` (``ros_fake_node``) that does this.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ros_fake_msgs import ParameterDescriptor, SetParametersResult


class ParameterAlreadyDeclaredException(Exception):
    pass


class ParameterNotDeclaredException(Exception):
    pass


class InvalidParameterValueException(Exception):
    pass


class Parameter:
    def __init__(self, name: str, type_: Any = None, value: Any = None) -> None:
        self.name = name
        self.type_ = type_
        self.value = value


_TYPE_CODES = {bool: 1, int: 2, float: 3, str: 4}
#: rcl_interfaces/ParameterType -> the field of a ParameterValue that holds a value of that type.
_VALUE_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
                6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value", 9: "string_array_value"}


def type_code(value: Any) -> int:
    """rcl_interfaces/ParameterType of a Python value, as rclpy's Parameter.Type.from_parameter_value."""
    if value is None:
        return 0
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        return {bool: 6, int: 7, float: 8, str: 9}.get(next(iter(kinds)), 9) if len(kinds) == 1 else 9
    return _TYPE_CODES[type(value)]


class NodeParameters:
    """The parameter API of rclpy's Node, over the overrides the node was given."""

    def __init__(self, overrides: dict[str, Parameter]) -> None:
        self._parameters: dict[str, Parameter] = {}
        self._descriptors: dict[str, Any] = {}
        self._callbacks: list[Callable[[list[Parameter]], Any]] = []
        self._overrides = overrides

    def _set(self, name: str, value: Any) -> None:
        for callback in self._callbacks:
            result = callback([Parameter(name, value=value)])
            if not result.successful:
                raise InvalidParameterValueException(f"{name}: {result.reason}")
        self._parameters[name] = Parameter(name, value=value)

    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None, ignore_override: bool = False) -> Parameter:
        if name in self._parameters:
            raise ParameterAlreadyDeclaredException(name)
        if not ignore_override and name in self._overrides:
            value = self._overrides[name].value
        descriptor = descriptor if descriptor is not None else ParameterDescriptor()
        if descriptor.type not in (0, type_code(value)) and not descriptor.dynamic_typing:
            raise InvalidParameterValueException(f"{name}: Wrong parameter type, expected '{descriptor.type}' got '{type_code(value)}'")
        descriptor.type = type_code(value)
        descriptor.name = name
        self._set(name, value)
        self._descriptors[name] = descriptor
        return self._parameters[name]

    def set_descriptor(self, name: str, descriptor: Any, alternative_value: Any = None) -> Any:
        """rclpy: keep the value if it has the descriptor's type, else take the alternative; no callbacks."""
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        descriptor.name = name
        candidates = [self._parameters[name].value]
        if alternative_value is not None:
            field = _VALUE_FIELDS.get(alternative_value.type)
            candidates.append(None if field is None else getattr(alternative_value, field))
        for value in candidates:
            if descriptor.dynamic_typing or type_code(value) == descriptor.type:
                self._parameters[name] = Parameter(name, value=list(value) if isinstance(value, (list, tuple)) or hasattr(value, "typecode") else value)
                self._descriptors[name] = descriptor
                return alternative_value
        raise InvalidParameterValueException(f"{name}: Wrong parameter type, expected '{descriptor.type}'")

    def describe_parameter(self, name: str) -> Any:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        return self._parameters[name]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        return {n: p for n, p in self._parameters.items() if n.startswith(prefix)}

    def add_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        self._callbacks.append(callback)

    def set_parameters(self, parameters: list[Parameter]) -> list[Any]:
        results = []
        for param in parameters:
            result = SetParametersResult(successful=True)
            for callback in self._callbacks:
                result = callback([param])
                if not result.successful:
                    break
            if result.successful:
                self._parameters[param.name] = param
            results.append(result)
        return results
