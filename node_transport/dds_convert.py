"""Mirror <-> Cyclone DDS sample conversion: the rclpy converter's rules over the IDL types.

The mirrors of :mod:`node_transport.msgs` name their ROS type; the DDS types come
from the interface files (:class:`~node_transport.idl.InterfaceRegistry`).  Building
the class for a mirror checks, field by field, that the ``.msg`` file has every field the mirror
carries, so a mirror and its interface file cannot drift apart unnoticed.  The one difference to
rosidl's Python classes: a ROS ``byte`` is an ``int`` in a DDS sample, ``bytes`` of length 1 in a
mirror (as rosidl holds it).
"""
from __future__ import annotations

from typing import Any, TypeVar

from node_transport.idl import InterfaceError, InterfaceRegistry
from node_transport.port import TransportError
from node_transport.ros_convert import MessageConverter, mirror_fields, sequence_item

M = TypeVar("M")


class DdsConverter(MessageConverter):
    def __init__(self, registry: InterfaceRegistry) -> None:
        self.registry = registry
        super().__init__(self._resolve)

    def _resolve(self, ros_type: str) -> type:
        try:
            return self.registry.message(ros_type)
        except InterfaceError as error:
            raise TransportError(str(error)) from None

    def wire_class(self, mirror: type) -> type:
        """The DDS type of a message mirror; TransportError when its .msg lacks a mirror field."""
        cls = self.ros_class(mirror)
        declared = set(getattr(cls, "__annotations__", {}))
        missing = [name for name, _ in mirror_fields(mirror) if name not in declared]
        if missing:
            raise TransportError(f"{mirror.ROS_TYPE} (interface file) has no field(s) {', '.join(missing)} that {mirror.__name__} carries")  # type: ignore[attr-defined]
        return cls

    def to_wire(self, msg: Any) -> Any:
        return self.to_ros(msg)

    def from_wire(self, mirror: type[M], sample: Any) -> M:
        return self.from_ros(mirror, sample)

    def to_wire_service(self, wire_type: type, msg: Any, guid: int, seq: int) -> Any:
        """A request or reply sample with rmw_cyclonedds_cpp's header."""
        fields: dict[str, Any] = {"guid": guid, "seq": seq}
        for name, hint in mirror_fields(type(msg)):
            fields[name] = self._value_to_ros(hint, getattr(msg, name), name)
        if "structure_needs_at_least_one_member" in getattr(wire_type, "__annotations__", {}):
            fields["structure_needs_at_least_one_member"] = 0
        try:
            return wire_type(**fields)
        except TypeError as error:
            raise TransportError(f"cannot build {wire_type.__name__} from {type(msg).__name__}: {error}") from None

    # ------------------------------------------------------------------ byte <-> bytes
    def _value_to_ros(self, hint: Any, value: Any, path: str) -> Any:
        if hint is bytes:
            if not isinstance(value, (bytes, bytearray)) or len(value) != 1:
                raise TransportError(f"field {path!r}: expected one byte (bytes of length 1), got {value!r}")
            return value[0]
        return super()._value_to_ros(hint, value, path)

    def _value_from_ros(self, hint: Any, value: Any, path: str) -> Any:
        if isinstance(value, (bytes, bytearray)) and sequence_item(hint) is int:
            return tuple(value)  # cyclonedds gives an octet array (uint8[16] of a goal id) as bytes
        if hint is bytes:
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
                raise TransportError(f"field {path!r}: expected an octet, got {value!r}")
            return bytes([value])
        return super()._value_from_ros(hint, value, path)
