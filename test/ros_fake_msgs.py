"""Fake rosidl interface packages (message and service classes shaped like rosidl's), for the fake rclpy.

Classes have ``__slots__``, keyword constructors that refuse unknown fields, setters that refuse
a wrong Python type (an ``int`` for a ``float64``), numeric sequences stored as ``array.array``
and ``get_fields_and_field_types()``; services expose ``Request`` / ``Response`` on the service
class only.  :data:`INTERFACE_MODULES` maps each module (``std_msgs.msg``) to its classes;
:func:`ros_fakes.install` puts them in ``sys.modules``.
"""
from __future__ import annotations

import array
from collections.abc import Callable
from typing import Any

import numpy as np

from node_transport.idl import interface_roots
from node_transport.mirrors import registry

# ================================================================================= messages
_DEFAULTS: dict[str, Callable[[], Any]] = {
    "string": str,
    "boolean": bool,
    "octet": lambda: bytes([0]),  # a ROS ``byte``: rosidl's default is bytes([0])
    "double": float,
    "int32": int,
    "uint32": int,
    "uint8": int,
    "uint16": int,
    "int8": int,
    "uint8[16]": lambda: np.zeros(16, dtype=np.uint8),
    "sequence<double>": lambda: array.array("d"),
    "sequence<string>": list,
    "int64": int,
    "uint64": int,
    "sequence<boolean>": list,
    "sequence<int64>": lambda: array.array("q"),
    "sequence<uint8>": lambda: array.array("B"),  # uint8[] (image data): array.array('B')
    "double[9]": lambda: np.zeros(9),  # fixed-size arrays are numpy arrays in rosidl Python
    "double[12]": lambda: np.zeros(12),
}
_INT_RANGES = {"int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1), "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1), "uint16": (0, 65535), "uint8": (0, 255), "int8": (-128, 127)}


class FakeMessage:
    """Base of rosidl-shaped fake messages; subclasses set ``_fields_and_field_types``."""

    __slots__: tuple[str, ...] = ()
    _fields_and_field_types: dict[str, str] = {}
    _nested: dict[str, type] = {}
    _field_defaults: dict[str, Any] = {}

    def __init__(self, **kwargs: Any) -> None:
        assert all("_" + key in self.__slots__ for key in kwargs), f"Invalid arguments passed to constructor: {sorted(kwargs)}"
        for name, kind in self._fields_and_field_types.items():
            if name in kwargs:
                setattr(self, name, kwargs[name])
            elif name in self._nested:  # a sequence of messages starts empty, a sub-message default-built
                setattr(self, name, [] if kind.startswith("sequence<") else self._nested[name]())
            elif name in self._field_defaults:
                setattr(self, name, self._field_defaults[name])
            else:
                setattr(self, name, _DEFAULTS[kind]())

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        return dict(cls._fields_and_field_types)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and all(_same(getattr(self, n), getattr(other, n)) for n in self._fields_and_field_types)

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n in self._fields_and_field_types)
        return f"{type(self).__name__}({inner})"


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


def _check(kind: str, nested: type | None, name: str, value: Any) -> Any:
    if nested is not None and kind.startswith("sequence<"):  # rosidl keeps the sequence it is given
        assert isinstance(value, (list, tuple)) and all(isinstance(v, nested) for v in value), (
            f"The '{name}' field must be a set or sequence and each value of type '{nested.__name__}'"
        )
        bound = kind[:-1].rpartition(", ")[2] if ", " in kind else ""  # a bounded sequence: sequence<T, N>
        assert not bound or len(value) <= int(bound), (
            f"The '{name}' field must be a set or sequence with length <= {bound} and each value of type '{nested.__name__}'"
        )
        return value
    if nested is not None:
        assert isinstance(value, nested), f"The '{name}' field must be a sub message of type '{nested.__name__}'"
        return value
    if kind == "octet":
        assert isinstance(value, (bytes, bytearray)) and len(value) == 1, f"The '{name}' field must be of type 'bytes' or 'ByteString' with length 1"
        return value
    if kind == "string":
        assert isinstance(value, str), f"The '{name}' field must be of type 'str'"
    elif kind == "boolean":
        assert isinstance(value, bool), f"The '{name}' field must be of type 'bool'"
    elif kind == "double":
        assert isinstance(value, float), f"The '{name}' field must be of type 'float'"
    elif kind in _INT_RANGES:
        low, high = _INT_RANGES[kind]
        assert isinstance(value, int) and low <= value <= high, f"The '{name}' field must be an integer in [{low}, {high}]"
    elif kind == "sequence<double>":
        if isinstance(value, array.array):
            assert value.typecode == "d", f"The '{name}' array.array() must have the type code of 'd'"
            return value
        assert all(isinstance(v, float) for v in value), f"The '{name}' field must be a sequence of 'float'"
        return array.array("d", value)
    elif kind == "sequence<string>":
        assert all(isinstance(v, str) for v in value), f"The '{name}' field must be a sequence of 'str'"
        return list(value)
    elif kind == "sequence<boolean>":
        assert all(isinstance(v, bool) for v in value), f"The '{name}' field must be a sequence of 'bool'"
        return list(value)
    elif kind == "sequence<uint8>":
        if isinstance(value, array.array):
            assert value.typecode == "B", f"The '{name}' array.array() must have the type code of 'B'"
            return value
        assert not isinstance(value, str) and all(isinstance(v, int) and 0 <= v < 256 for v in value), (
            f"The '{name}' field must be a set or sequence and each value of type 'int' and each unsigned integer in [0, 255]"
        )
        return array.array("B", value)
    elif kind == "uint8[16]":  # a goal id (unique_identifier_msgs/UUID): rosidl holds a numpy array
        if isinstance(value, np.ndarray):
            assert value.dtype == np.uint8 and value.size == 16, f"The '{name}' numpy.ndarray() must have the dtype of 'numpy.uint8' and a size of 16"
            return value
        assert len(value) == 16 and all(isinstance(v, int) and 0 <= v < 256 for v in value), (
            f"The '{name}' field must be a set or sequence with length 16 and each value of type 'int' and each unsigned integer in [0, 255]"
        )
        return np.array(value, dtype=np.uint8)
    elif kind in ("double[9]", "double[12]"):
        size = int(kind[7:-1])
        if isinstance(value, np.ndarray):
            assert value.dtype == np.float64 and value.size == size, f"The '{name}' numpy.ndarray() must have the dtype of 'numpy.float64' and a size of {size}"
            return value
        assert len(value) == size and all(isinstance(v, float) for v in value), f"The '{name}' field must be a set or sequence with length {size} and each value of type 'float'"
        return np.array(value, dtype=np.float64)
    elif kind == "sequence<int64>":
        assert all(isinstance(v, int) and not isinstance(v, bool) for v in value), f"The '{name}' field must be a sequence of 'int'"
        return array.array("q", value)
    else:
        raise AssertionError(f"unknown field kind {kind}")
    return value


def message_class(name: str, fields: dict[str, str], nested: dict[str, type] | None = None, defaults: dict[str, Any] | None = None) -> type:
    """A rosidl-shaped class: slots ``_<field>``, checking properties, keyword constructor."""
    nested = nested or {}
    namespace: dict[str, Any] = {
        "__slots__": tuple("_" + f for f in fields),
        "_fields_and_field_types": dict(fields),
        "_nested": dict(nested),
        "_field_defaults": dict(defaults or {}),
    }
    for field_name, kind in fields.items():
        def getter(self: Any, _n: str = field_name) -> Any:
            return object.__getattribute__(self, "_" + _n)

        def setter(self: Any, value: Any, _n: str = field_name, _k: str = kind, _t: type | None = nested.get(field_name)) -> None:
            object.__setattr__(self, "_" + _n, _check(_k, _t, _n, value))

        namespace[field_name] = property(getter, setter)
    return type(name, (FakeMessage,), namespace)


Time = message_class("Time", {"sec": "int32", "nanosec": "uint32"})
Duration = message_class("Duration", {"sec": "int32", "nanosec": "uint32"})
ClockMessage = message_class("Clock", {"clock": "builtin_interfaces/Time"}, {"clock": Time})
Header = message_class("Header", {"stamp": "builtin_interfaces/Time", "frame_id": "string"}, {"stamp": Time})
String = message_class("String", {"data": "string"})
Bool = message_class("Bool", {"data": "boolean"})
JointState = message_class(
    "JointState",
    {"header": "std_msgs/Header", "name": "sequence<string>", "position": "sequence<double>", "velocity": "sequence<double>", "effort": "sequence<double>"},
    {"header": Header},
)
Point = message_class("Point", {"x": "double", "y": "double", "z": "double"})
Quaternion = message_class("Quaternion", {"x": "double", "y": "double", "z": "double", "w": "double"}, defaults={"w": 1.0})
Pose = message_class("Pose", {"position": "geometry_msgs/Point", "orientation": "geometry_msgs/Quaternion"}, {"position": Point, "orientation": Quaternion})
PoseStamped = message_class("PoseStamped", {"header": "std_msgs/Header", "pose": "geometry_msgs/Pose"}, {"header": Header, "pose": Pose})
Vector3 = message_class("Vector3", {"x": "double", "y": "double", "z": "double"})
Transform = message_class(
    "Transform", {"translation": "geometry_msgs/Vector3", "rotation": "geometry_msgs/Quaternion"}, {"translation": Vector3, "rotation": Quaternion}
)
Twist = message_class("Twist", {"linear": "geometry_msgs/Vector3", "angular": "geometry_msgs/Vector3"}, {"linear": Vector3, "angular": Vector3})
TransformStamped = message_class(
    "TransformStamped",
    {"header": "std_msgs/Header", "child_frame_id": "string", "transform": "geometry_msgs/Transform"},
    {"header": Header, "transform": Transform},
)
TFMessage = message_class("TFMessage", {"transforms": "sequence<geometry_msgs/TransformStamped>"}, {"transforms": TransformStamped})
KeyValue = message_class("KeyValue", {"key": "string", "value": "string"})
DiagnosticStatus = message_class(
    "DiagnosticStatus",
    {"level": "octet", "name": "string", "message": "string", "hardware_id": "string", "values": "sequence<diagnostic_msgs/KeyValue>"},
    {"values": KeyValue},
)
DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR, DiagnosticStatus.STALE = b"\x00", b"\x01", b"\x02", b"\x03"  # type: ignore[attr-defined]
DiagnosticArray = message_class(
    "DiagnosticArray", {"header": "std_msgs/Header", "status": "sequence<diagnostic_msgs/DiagnosticStatus>"}, {"header": Header, "status": DiagnosticStatus}
)

RegionOfInterest = message_class(
    "RegionOfInterest", {"x_offset": "uint32", "y_offset": "uint32", "height": "uint32", "width": "uint32", "do_rectify": "boolean"}
)
Image = message_class(
    "Image",
    {"header": "std_msgs/Header", "height": "uint32", "width": "uint32", "encoding": "string", "is_bigendian": "uint8", "step": "uint32", "data": "sequence<uint8>"},
    {"header": Header},
)
CameraInfo = message_class(
    "CameraInfo",
    {"header": "std_msgs/Header", "height": "uint32", "width": "uint32", "distortion_model": "string", "d": "sequence<double>",
     "k": "double[9]", "r": "double[9]", "p": "double[12]", "binning_x": "uint32", "binning_y": "uint32", "roi": "sensor_msgs/RegionOfInterest"},
    {"header": Header, "roi": RegionOfInterest},
)


class Trigger:
    """std_srvs/srv/Trigger: an empty request still has one placeholder field, as rosidl generates."""

    Request = message_class("Trigger_Request", {"structure_needs_at_least_one_member": "uint8"})
    Response = message_class("Trigger_Response", {"success": "boolean", "message": "string"})


FloatingPointRange = message_class("FloatingPointRange", {"from_value": "double", "to_value": "double", "step": "double"})
IntegerRange = message_class("IntegerRange", {"from_value": "int64", "to_value": "int64", "step": "uint64"})
ParameterDescriptor = message_class(
    "ParameterDescriptor",
    {"name": "string", "type": "uint8", "description": "string", "additional_constraints": "string", "read_only": "boolean",
     "dynamic_typing": "boolean", "floating_point_range": "sequence<rcl_interfaces/FloatingPointRange, 1>",
     "integer_range": "sequence<rcl_interfaces/IntegerRange, 1>"},
    {"floating_point_range": FloatingPointRange, "integer_range": IntegerRange},
)
ParameterValue = message_class(
    "ParameterValue",
    {"type": "uint8", "bool_value": "boolean", "integer_value": "int64", "double_value": "double", "string_value": "string",
     "bool_array_value": "sequence<boolean>", "integer_array_value": "sequence<int64>", "double_array_value": "sequence<double>",
     "string_array_value": "sequence<string>"},
)
SetParametersResult = message_class("SetParametersResult", {"successful": "boolean", "reason": "string"})

# ============================================================ the project's own interface package
_ROSIDL_NAMES = {"bool": "boolean", "float64": "double", "float32": "float", "byte": "octet", "char": "uint8"}


def _rosidl_package(package: str, known: dict[str, type]) -> dict[str, dict[str, Any]]:
    """Classes of ``package`` as rosidl generates them from its .msg/.srv files: field types named as
    ``get_fields_and_field_types`` names them (``string``, ``uint32``, ``sequence<pkg/Name>``),
    nested messages by their classes; ``known`` holds the fake classes of the packages it uses."""
    folder = next(root / package for root in interface_roots() if (root / package).is_dir())
    classes: dict[str, type] = {}
    built: dict[str, type] = {}  # every class made, by ROS type: one class per type, as rosidl has

    def build(ros_type: str, name: str) -> type:
        if ros_type in built:
            return built[ros_type]
        fields: dict[str, str] = {}
        nested: dict[str, type] = {}
        for spec in registry().spec(ros_type).fields:
            if "/" in spec.base:
                pkg, _, short = spec.base.split("/")
                kind = f"{pkg}/{short}"
                nested[spec.name] = known.get(spec.base) or built.get(spec.base) or build(spec.base, short)
            else:
                kind = _ROSIDL_NAMES.get(spec.base, spec.base)
            fields[spec.name] = kind if spec.array is None else f"{kind}[{spec.array}]" if spec.array.isdigit() else f"sequence<{kind}>"
        cls = built[ros_type] = message_class(name, fields, nested)
        if ros_type.split("/")[1] == "msg":
            classes[name] = cls
        return cls

    for path in sorted((folder / "msg").glob("*.msg")):
        if path.stem not in classes:
            build(f"{package}/msg/{path.stem}", path.stem)
    services: dict[str, type] = {}
    for path in sorted((folder / "srv").glob("*.srv")):
        base = f"{package}/srv/{path.stem}"
        services[path.stem] = type(path.stem, (), {
            "Request": build(f"{base}_Request", f"{path.stem}_Request"), "Response": build(f"{base}_Response", f"{path.stem}_Response"),
        })
    actions: dict[str, type] = {}
    for path in sorted((folder / "action").glob("*.action")):
        base, stem = f"{package}/action/{path.stem}", path.stem

        def part(name: str, base: str = base, stem: str = stem) -> type:
            return build(f"{base}_{name}", f"{stem}_{name}")

        def service(name: str, stem: str = stem, part: Any = part) -> type:
            return type(f"{stem}_{name}", (), {"Request": part(f"{name}_Request"), "Response": part(f"{name}_Response")})

        # rosidl: Goal, Result, Feedback on the class, what rcl_action sends in its Impl
        impl = type("Impl", (), {"SendGoalService": service("SendGoal"), "GetResultService": service("GetResult"), "FeedbackMessage": part("FeedbackMessage")})
        actions[stem] = type(stem, (), {"Goal": part("Goal"), "Result": part("Result"), "Feedback": part("Feedback"), "Impl": impl})
    return {f"{package}.msg": classes, f"{package}.srv": services, **({f"{package}.action": actions} if actions else {})}


INTERFACE_MODULES: dict[str, dict[str, Any]] = {
    "builtin_interfaces.msg": {"Time": Time, "Duration": Duration},
    "rosgraph_msgs.msg": {"Clock": ClockMessage},
    "std_msgs.msg": {"Header": Header, "String": String, "Bool": Bool},
    "sensor_msgs.msg": {"JointState": JointState, "Image": Image, "CameraInfo": CameraInfo, "RegionOfInterest": RegionOfInterest},
    "geometry_msgs.msg": {
        "Point": Point, "Quaternion": Quaternion, "Pose": Pose, "PoseStamped": PoseStamped,
        "Vector3": Vector3, "Transform": Transform, "TransformStamped": TransformStamped, "Twist": Twist,
    },
    "tf2_msgs.msg": {"TFMessage": TFMessage},
    "diagnostic_msgs.msg": {"KeyValue": KeyValue, "DiagnosticStatus": DiagnosticStatus, "DiagnosticArray": DiagnosticArray},
    "std_srvs.srv": {"Trigger": Trigger},
    "rcl_interfaces.msg": {
        "ParameterDescriptor": ParameterDescriptor, "FloatingPointRange": FloatingPointRange, "IntegerRange": IntegerRange,
        "ParameterValue": ParameterValue, "SetParametersResult": SetParametersResult,
    },
}
INTERFACE_MODULES.update(_rosidl_package("unique_identifier_msgs", {}))
INTERFACE_MODULES.update(_rosidl_package("action_msgs", {
    "builtin_interfaces/msg/Time": Time, "unique_identifier_msgs/msg/UUID": INTERFACE_MODULES["unique_identifier_msgs.msg"]["UUID"],
}))
INTERFACE_MODULES.update(_rosidl_package("dual_arm_executive_interfaces", {
    "std_msgs/msg/Header": Header, "builtin_interfaces/msg/Time": Time, "geometry_msgs/msg/Pose": Pose, "diagnostic_msgs/msg/KeyValue": KeyValue,
    "unique_identifier_msgs/msg/UUID": INTERFACE_MODULES["unique_identifier_msgs.msg"]["UUID"],
}))

_STANDARD = {
    "std_msgs/msg/Header": Header, "builtin_interfaces/msg/Time": Time, "builtin_interfaces/msg/Duration": Duration,
    "geometry_msgs/msg/Transform": Transform, "geometry_msgs/msg/Twist": Twist,
    "unique_identifier_msgs/msg/UUID": INTERFACE_MODULES["unique_identifier_msgs.msg"]["UUID"],
}
INTERFACE_MODULES.update(_rosidl_package("trajectory_msgs", _STANDARD))  # control_msgs' FollowJointTrajectory (the bridges)
INTERFACE_MODULES.update(_rosidl_package("control_msgs", {
    **_STANDARD, **{f"trajectory_msgs/msg/{n}": c for n, c in INTERFACE_MODULES["trajectory_msgs.msg"].items()},
}))

for _action in [*INTERFACE_MODULES["dual_arm_executive_interfaces.action"].values(), *INTERFACE_MODULES["control_msgs.action"].values()]:  # rosidl: rcl_action's own parts
    _action.Impl.CancelGoalService = INTERFACE_MODULES["action_msgs.srv"]["CancelGoal"]
    _action.Impl.GoalStatusMessage = INTERFACE_MODULES["action_msgs.msg"]["GoalStatusArray"]


#: Where rosidl's Python class of an action keeps each part rcl_action puts on the wire (written out here, not
#: taken from node_transport.ros_convert, so that the fake checks the transport's own table).
ACTION_LAYOUT: dict[str, tuple[str, ...]] = {
    "Goal": ("Goal",),
    "Result": ("Result",),
    "Feedback": ("Feedback",),
    "FeedbackMessage": ("Impl", "FeedbackMessage"),
    "SendGoal": ("Impl", "SendGoalService"),
    "SendGoal_Request": ("Impl", "SendGoalService", "Request"),
    "SendGoal_Response": ("Impl", "SendGoalService", "Response"),
    "GetResult": ("Impl", "GetResultService"),
    "GetResult_Request": ("Impl", "GetResultService", "Request"),
    "GetResult_Response": ("Impl", "GetResultService", "Response"),
}


def resolve(ros_type: str) -> type:
    """A resolver over the fake interface packages (what import_ros_type does with real ones)."""
    package, kind, name = ros_type.split("/")
    service, _, part = name.partition("_")
    cls = INTERFACE_MODULES[f"{package}.{kind}"][service if part else name]
    for attribute in (ACTION_LAYOUT[part] if kind == "action" else (part,) if part else ()):
        cls = getattr(cls, attribute)
    return cls  # type: ignore[no-any-return]
