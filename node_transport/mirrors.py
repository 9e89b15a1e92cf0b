"""Message mirrors generated from the interface files, so a new type is written once: in its .msg.

A mirror is what the port carries (:mod:`node_transport.msgs` holds the hand-written
ones of the common types): a frozen dataclass naming its ROS type in ``ROS_TYPE``, fields in file
order with their defaults, the file's constants as class attributes.  Field types follow the
converters' rules: integers ``int`` (``char`` too), ``byte`` one ``bytes`` as rosidl holds it,
floats ``float``, ``string`` ``str``, arrays and sequences ``tuple[T, ...]``, nested messages their
own mirrors.  Parsing needs no DDS library: the same mirrors serve every transport.
"""
from __future__ import annotations

import dataclasses
from functools import lru_cache
from typing import Any

from node_transport import msgs
from node_transport.idl import FieldSpec, InterfaceRegistry, literal_value

_PYTHON = {"bool": bool, "byte": bytes, "char": int, "float32": float, "float64": float, "string": str}


@lru_cache(maxsize=1)
def registry() -> InterfaceRegistry:
    """The interface files of this installation (parsed once per process)."""
    return InterfaceRegistry()


def _scalar_default(spec: FieldSpec) -> Any:
    if spec.base == "byte":
        return bytes([int(spec.default, 0)]) if spec.default else b"\x00"
    if spec.default is not None:
        return literal_value(spec)
    return {bool: False, float: 0.0, str: ""}.get(_PYTHON.get(spec.base, int), 0)


def _field(spec: FieldSpec) -> tuple[str, Any, Any]:
    nested = "/" in spec.base
    item: Any = mirror(spec.base) if nested else _PYTHON.get(spec.base, int)
    if spec.array is not None:
        size = int(spec.array) if spec.array and not spec.array.startswith("<=") else 0
        default: Any = tuple(mirror(spec.base)() if nested else _scalar_default(spec) for _ in range(size))
        return spec.name, tuple[item, ...], dataclasses.field(default=default)
    if nested:
        return spec.name, item, dataclasses.field(default_factory=item)
    return spec.name, item, dataclasses.field(default=_scalar_default(spec))


#: the hand-written mirrors of msgs.py are the ones used wherever their type appears (a stamp is a msgs.Time)
_WRITTEN = {
    cls.ROS_TYPE: cls for cls in vars(msgs).values()
    if isinstance(cls, type) and dataclasses.is_dataclass(cls) and isinstance(getattr(cls, "ROS_TYPE", None), str)
}


@lru_cache(maxsize=None)
def mirror(ros_type: str) -> type:
    """The mirror dataclass of ``pkg/msg/Name`` (or of a service or action part)."""
    if ros_type in _WRITTEN:
        return _WRITTEN[ros_type]
    spec = registry().spec(ros_type)
    cls = dataclasses.make_dataclass(ros_type.rsplit("/", 1)[1], [_field(f) for f in spec.fields], frozen=True)
    cls.ROS_TYPE = ros_type  # type: ignore[attr-defined]
    for constant in spec.constants:
        setattr(cls, constant.name, bytes([literal_value(constant)]) if constant.base == "byte" else literal_value(constant))
    return cls


@lru_cache(maxsize=None)
def service(ros_type: str) -> type:
    """``pkg/srv/Name`` (or an action's ``..._SendGoal``): a class with ``ROS_TYPE``, ``Request``, ``Response``."""
    return type(ros_type.rsplit("/", 1)[1], (), {
        "ROS_TYPE": ros_type, "Request": mirror(f"{ros_type}_Request"), "Response": mirror(f"{ros_type}_Response"),
    })


@lru_cache(maxsize=None)
def action(ros_type: str) -> type:
    """``pkg/action/Name``: Goal, Result, Feedback, the SendGoal and GetResult services and FeedbackMessage."""
    return type(ros_type.rsplit("/", 1)[1], (), {
        "ROS_TYPE": ros_type,
        "Goal": mirror(f"{ros_type}_Goal"),
        "Result": mirror(f"{ros_type}_Result"),
        "Feedback": mirror(f"{ros_type}_Feedback"),
        "SendGoal": service(f"{ros_type}_SendGoal"),
        "GetResult": service(f"{ros_type}_GetResult"),
        "FeedbackMessage": mirror(f"{ros_type}_FeedbackMessage"),
    })
