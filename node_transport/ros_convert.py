"""Mirror <-> ROS 2 message conversion, QoS profiles and parameter values, as plain tested code.

The rclpy adapter (:mod:`node_transport.ros`) must stay thin because it cannot be run
on a machine without ROS 2; everything that is only data shuffling lives here instead, where the
tests drive it with fake message classes shaped like rosidl's (``__slots__``, type-checking
setters, ``get_fields_and_field_types``, ``array.array`` for numeric sequences).

Conversion is driven by the mirrors in :mod:`node_transport.msgs`: each names its ROS
type (``ROS_TYPE = "std_msgs/msg/String"``) and has the same field names.  Classes are looked up
through an injectable *resolver* (default: import ``std_msgs.msg`` and take ``String``), so tests
never need rclpy and a missing interface package fails with one clear message.  Values are
coerced to the exact Python type of the mirror's field (``float(1)``), because rosidl setters
reject an ``int`` for a ``float64`` field.
"""
from __future__ import annotations

import array
import dataclasses
import importlib
import re
import typing
from collections.abc import Callable, Iterable, Mapping
from functools import lru_cache
from typing import Any, TypeVar, get_args, get_origin

import numpy as np

from node_transport.msgs import ByteBuffer
from node_transport.port import ParameterValue, TransportError
from node_transport.qos import Durability, History, QoS, Reliability, rclpy_qos_kwargs

M = TypeVar("M")
Resolver = Callable[[str], type]

_ROS_TYPE = re.compile(r"^([a-z][a-z0-9_]*)/(msg|srv|action)/([A-Z][A-Za-z0-9]*)(?:_([A-Za-z_]+))?$")
#: Where rosidl's Python class of an action keeps each part rcl_action puts on the wire.
_ACTION_PARTS: dict[str, tuple[str, ...]] = {
    "Goal": ("Goal",), "Result": ("Result",), "Feedback": ("Feedback",),
    "FeedbackMessage": ("Impl", "FeedbackMessage"),
    **{f"{service}{suffix}": ("Impl", f"{service}Service", *([suffix[1:]] if suffix else []))
       for service in ("SendGoal", "GetResult") for suffix in ("", "_Request", "_Response")},
}

#: Parameters rclpy declares on every node by itself; they are not overrides meant for our code.
RCLPY_OWN_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service"})
_RCLPY_OWN_PREFIXES = ("qos_overrides.",)


# ------------------------------------------------------------------------------- resolving
def import_ros_type(ros_type: str) -> type:
    """The rosidl class of ``pkg/msg/Name``, ``pkg/srv/Name[_Request|_Response]`` or a part of an
    action, ``pkg/action/Name_<part>`` (``Goal``, ``SendGoal``, ``SendGoal_Request``, ``FeedbackMessage``...).

    Requests and responses are reached through their service class (``Trigger.Request``),
    because rosidl packages export the service, not always its parts; an action's services and
    feedback message through the action's ``Impl`` (``RunApplication.Impl.SendGoalService``).
    """
    match = _ROS_TYPE.match(ros_type)
    if match is None:
        raise TransportError(f"{ros_type!r} is not a ROS interface name like 'std_msgs/msg/String'")
    package, kind, name, part = match.groups()
    if kind == "action":
        if part not in _ACTION_PARTS:
            raise TransportError(f"{ros_type!r}: an action's part is one of {', '.join(_ACTION_PARTS)}")
        path: tuple[str, ...] = (name, *_ACTION_PARTS[part])
    elif part in (None, "Request", "Response"):
        path = (name, part) if part else (name,)
    else:
        raise TransportError(f"{ros_type!r} is not a ROS interface name like 'std_msgs/msg/String'")
    module_name = f"{package}.{kind}"
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        hint = (
            "build it with colcon: --base-paths <repo> <repo>/interfaces" if package == "dual_arm_executive_interfaces"
            else "is the ROS 2 environment sourced?"
        )
        raise TransportError(f"cannot import {module_name} for {ros_type}: {error} ({hint})") from None
    found: Any = module
    try:
        for attribute in path:
            found = getattr(found, attribute)
    except AttributeError:
        raise TransportError(f"{module_name} has no {'.'.join(path)} (for {ros_type})") from None
    return found  # type: ignore[no-any-return]


@lru_cache(maxsize=None)
def mirror_fields(mirror: type) -> tuple[tuple[str, Any], ...]:
    """(name, type hint) of each field of a mirror dataclass, in declaration order."""
    if not (dataclasses.is_dataclass(mirror) and isinstance(getattr(mirror, "ROS_TYPE", None), str)):
        raise TransportError(f"{mirror!r} is not a message mirror (a dataclass with ROS_TYPE)")
    hints = typing.get_type_hints(mirror)
    return tuple((f.name, hints[f.name]) for f in dataclasses.fields(mirror))


def sequence_item(hint: Any) -> Any | None:
    """The item type of ``tuple[T, ...]``, or None when ``hint`` is not a sequence."""
    if get_origin(hint) is tuple:
        args = get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return args[0]
        raise TransportError(f"mirror field type {hint!r}: only tuple[T, ...] maps to a ROS sequence")
    return None


def _is_mirror(hint: Any) -> bool:
    return isinstance(hint, type) and dataclasses.is_dataclass(hint)


_SCALARS: dict[Any, Callable[[Any], Any]] = {float: float, int: int, str: str}


def _scalar(hint: Any, value: Any, path: str) -> Any:
    if hint is bool:
        if not isinstance(value, bool):
            raise TransportError(f"field {path!r}: expected a bool, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise TransportError(f"field {path!r}: expected a string, got {type(value).__name__}")
        return value
    if hint is bytes:  # a ROS ``byte``: rosidl Python holds it as bytes of length 1 and refuses an int
        if not isinstance(value, (bytes, bytearray)) or len(value) != 1:
            raise TransportError(f"field {path!r}: expected one byte (bytes of length 1), got {value!r}")
        return bytes(value)
    convert = _SCALARS.get(hint)
    if convert is None:
        raise TransportError(f"field {path!r}: unsupported mirror field type {hint!r}")
    if isinstance(value, (np.integer, np.floating)):  # an item of rosidl's numpy array (a goal id's uint8[16])
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TransportError(f"field {path!r}: expected a number, got {type(value).__name__}")
    if hint is int and isinstance(value, float) and not value.is_integer():
        raise TransportError(f"field {path!r}: expected an integer, got {value!r}")
    return convert(value)


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


class MessageConverter:
    """Converts mirrors to rosidl messages and back, resolving and checking each class once."""

    def __init__(self, resolver: Resolver = import_ros_type) -> None:
        self._resolver = resolver
        self._classes: dict[type, type] = {}

    # ----------------------------------------------------------------------------- classes
    def ros_class(self, mirror: type) -> type:
        """The rosidl class for ``mirror``; TransportError when it lacks one of the mirror's fields."""
        cls = self._classes.get(mirror)
        if cls is not None:
            return cls
        fields = mirror_fields(mirror)
        ros_type: str = mirror.ROS_TYPE  # type: ignore[attr-defined]
        cls = self._resolver(ros_type)
        declared = _declared_fields(cls)
        if declared is not None:
            missing = [name for name, _ in fields if name not in declared]
            if missing:
                raise TransportError(
                    f"{ros_type} as installed has no field(s) {', '.join(missing)} that {mirror.__name__} carries"
                )
        for _, hint in fields:  # nested messages are checked up front too, not on first use
            nested = sequence_item(hint) or hint
            if _is_mirror(nested):
                self.ros_class(nested)
        self._classes[mirror] = cls
        return cls

    def service_classes(self, mirror_service: type) -> tuple[type, type, type]:
        """(service, request, response) rosidl classes for a service mirror such as ``Trigger``."""
        ros_type = getattr(mirror_service, "ROS_TYPE", None)
        request, response = getattr(mirror_service, "Request", None), getattr(mirror_service, "Response", None)
        if not isinstance(ros_type, str) or request is None or response is None:
            raise TransportError(f"{mirror_service!r} is not a service mirror (ROS_TYPE, Request, Response)")
        return self._resolver(ros_type), self.ros_class(request), self.ros_class(response)

    # ---------------------------------------------------------------------------- outbound
    def to_ros(self, msg: Any) -> Any:
        """The rosidl message for mirror instance ``msg``; TransportError names the field that failed."""
        return self._to_ros(msg, "")

    def _to_ros(self, msg: Any, path: str) -> Any:
        mirror = type(msg)
        cls = self.ros_class(mirror)
        kwargs: dict[str, Any] = {}
        for name, hint in mirror_fields(mirror):
            kwargs[name] = self._value_to_ros(hint, getattr(msg, name), _join(path, name))
        try:
            return cls(**kwargs)
        except (AssertionError, TypeError, ValueError, AttributeError) as error:
            raise TransportError(f"cannot build {mirror.ROS_TYPE} from {mirror.__name__}: {error or type(error).__name__}") from None

    def _value_to_ros(self, hint: Any, value: Any, path: str) -> Any:
        if hint is ByteBuffer:  # uint8[]: rosidl takes an array.array('B') as it is, without a check per byte
            if not isinstance(value, (bytes, bytearray)):
                raise TransportError(f"field {path!r}: expected bytes, got {type(value).__name__}")
            return array.array("B", value)
        item = sequence_item(hint)
        if item is not None:
            if not isinstance(value, (tuple, list)):
                raise TransportError(f"field {path!r}: expected a sequence, got {type(value).__name__}")
            return [self._value_to_ros(item, v, f"{path}[{i}]") for i, v in enumerate(value)]
        if _is_mirror(hint):
            if type(value) is not hint:
                raise TransportError(f"field {path!r}: expected {hint.__name__}, got {type(value).__name__}")
            return self._to_ros(value, path)
        return _scalar(hint, value, path)

    # ----------------------------------------------------------------------------- inbound
    def from_ros(self, mirror: type[M], ros_msg: Any) -> M:
        """The mirror of a received rosidl message; TransportError names the field that failed."""
        return self._from_ros(mirror, ros_msg, "")  # type: ignore[no-any-return]

    def _from_ros(self, mirror: type, ros_msg: Any, path: str) -> Any:
        kwargs: dict[str, Any] = {}
        for name, hint in mirror_fields(mirror):
            where = _join(path, name)
            try:
                raw = getattr(ros_msg, name)
            except AttributeError:
                raise TransportError(f"{mirror.ROS_TYPE}: received message has no field {where!r}") from None
            kwargs[name] = self._value_from_ros(hint, raw, where)
        return mirror(**kwargs)

    def _value_from_ros(self, hint: Any, value: Any, path: str) -> Any:
        if hint is ByteBuffer:
            return _byte_buffer(value, path)
        item = sequence_item(hint)
        if item is not None:  # fixed-size arrays (CameraInfo.k) arrive as numpy arrays
            if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, array.array, np.ndarray)):
                raise TransportError(f"field {path!r}: expected a sequence, got {type(value).__name__}")
            return tuple(self._value_from_ros(item, v, f"{path}[{i}]") for i, v in enumerate(value))
        if _is_mirror(hint):
            return self._from_ros(hint, value, path)
        return _scalar(hint, value, path)


def _byte_buffer(value: Any, path: str) -> ByteBuffer:
    """A received ``uint8[]`` (rclpy: ``array.array('B')``; bytes or a list of ints accepted too) as bytes."""
    if isinstance(value, array.array):
        if value.typecode != "B":
            raise TransportError(f"field {path!r}: expected an array of type code 'B', got {value.typecode!r}")
        return ByteBuffer(value.tobytes())
    if isinstance(value, (bytes, bytearray, memoryview)):
        return ByteBuffer(bytes(value))
    if isinstance(value, (list, tuple)):
        try:
            return ByteBuffer(bytes(value))
        except (TypeError, ValueError):
            raise TransportError(f"field {path!r}: expected integers in [0, 255]") from None
    raise TransportError(f"field {path!r}: expected a byte sequence, got {type(value).__name__}")


def _declared_fields(cls: type) -> set[str] | None:
    """Field names a rosidl class declares, or None if it does not say (then we trust the mirror)."""
    getter = getattr(cls, "get_fields_and_field_types", None)
    if getter is None:
        return None
    return set(getter())


# ----------------------------------------------------------------------------- responses
def failure_response(response_type: type[M], text: str) -> M:
    """A response that says the call failed: ``success=False`` and ``message`` where the type has them.

    Used when a service handler raised or timed out: rclpy must still answer the caller, and an
    exception out of an rclpy callback would stop the executor.
    """
    names = {f.name for f in dataclasses.fields(response_type)}  # type: ignore[arg-type]
    values: dict[str, Any] = {}
    if "success" in names:
        values["success"] = False
    if "message" in names:
        values["message"] = text
    return response_type(**values)


# ---------------------------------------------------------------------------------- QoS
def qos_profile(qos: QoS, policies: Any) -> Any:
    """``QoSProfile`` for ``qos``; ``policies`` is ``rclpy.qos`` (or a stand-in with the same names)."""
    kwargs = rclpy_qos_kwargs(qos)
    enums = {"reliability": policies.ReliabilityPolicy, "durability": policies.DurabilityPolicy, "history": policies.HistoryPolicy}
    resolved: dict[str, Any] = {"depth": kwargs["depth"]}
    for key, enum in enums.items():
        try:
            resolved[key] = getattr(enum, str(kwargs[key]))
        except AttributeError:
            raise TransportError(f"this rclpy has no {key} policy {kwargs[key]}") from None
    return policies.QoSProfile(**resolved)


def offered_qos(profile: Any) -> QoS:
    """Our QoS of an rclpy ``QoSProfile`` a publisher offers (``TopicEndpointInfo.qos_profile``):
    what a recorder needs to ask for no more than it gets."""
    reliability = getattr(getattr(profile, "reliability", None), "name", "RELIABLE")
    durability = getattr(getattr(profile, "durability", None), "name", "VOLATILE")
    return QoS(
        Reliability.BEST_EFFORT if reliability == "BEST_EFFORT" else Reliability.RELIABLE,
        Durability.TRANSIENT_LOCAL if durability == "TRANSIENT_LOCAL" else Durability.VOLATILE,
        History.KEEP_LAST,
        max(1, int(getattr(profile, "depth", 1) or 1)),
    )


# ---------------------------------------------------------------------------- parameters
def parameter_type_code(default: ParameterValue) -> int:
    """rcl_interfaces/ParameterType of a parameter declared with ``default`` (bool before int:
    a bool is an int in Python)."""
    if isinstance(default, bool):
        return 1  # PARAMETER_BOOL
    if isinstance(default, int):
        return 2  # PARAMETER_INTEGER
    if isinstance(default, float):
        return 3  # PARAMETER_DOUBLE
    if isinstance(default, str):
        return 4  # PARAMETER_STRING
    if isinstance(default, list):
        items = {type(v) for v in default}
        if items <= {bool} and items:
            return 6  # PARAMETER_BOOL_ARRAY
        if items <= {int} and items:
            return 7  # PARAMETER_INTEGER_ARRAY
        if items <= {float, int} and items:
            return 8  # PARAMETER_DOUBLE_ARRAY
        return 9  # PARAMETER_STRING_ARRAY (an empty list is declared as strings)
    raise TransportError(f"no ROS parameter type for {type(default).__name__}")


def plain_parameter_value(value: Any) -> ParameterValue:
    """A parameter value as the port expects it: sequences (rclpy gives ``array.array``) as lists."""
    if isinstance(value, (array.array, tuple, list)):
        return list(value)
    return value  # type: ignore[no-any-return]


def user_overrides(parameters: Mapping[str, Any] | Iterable[tuple[str, Any]]) -> dict[str, ParameterValue]:
    """The overrides meant for our code: every parameter but those rclpy declares by itself."""
    items = parameters.items() if isinstance(parameters, Mapping) else parameters
    return {
        name: plain_parameter_value(value)
        for name, value in items
        if name not in RCLPY_OWN_PARAMETERS and not name.startswith(_RCLPY_OWN_PREFIXES)
    }
