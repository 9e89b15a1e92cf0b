"""Mirror <-> Cyclone DDS sample conversion: the rclpy converter's rules over the IDL types.

The mirrors of :mod:`node_transport.msgs` name their ROS type; the DDS types come
from the interface files (:class:`~node_transport.idl.InterfaceRegistry`).  Building
the class for a mirror checks, field by field, that the ``.msg`` file has every field the mirror
carries, so a mirror and its interface file cannot drift apart unnoticed.  The one difference to
rosidl's Python classes: a ROS ``byte`` is an ``int`` in a DDS sample, ``bytes`` of length 1 in a
mirror (as rosidl holds it).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from node_transport.dds_plans import PLAIN, Slow, Step, compile_inbound, compile_outbound, is_mirror
from node_transport.idl import InterfaceError, InterfaceRegistry
from node_transport.port import TransportError
from node_transport.ros_convert import MessageConverter, mirror_fields, sequence_item

M = TypeVar("M")


class DdsConverter(MessageConverter):
    """The rclpy converter's rules, with each mirror's fields planned once (issue 22): a value that
    already has its field's exact type (a ``str`` for a string, a ``float`` for a float64, a nested
    mirror of its declared class) goes through as it is; anything else takes the general path,
    which converts it or refuses it naming the field, as before."""

    def __init__(self, registry: InterfaceRegistry) -> None:
        self.registry = registry
        super().__init__(self._resolve)
        self._outbound: dict[type, Callable[[Any, str], Any]] = {}
        self._inbound: dict[type, Callable[[Any, str], Any]] = {}

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
        return self._plan_out(type(msg))(msg, "")

    def from_wire(self, mirror: type[M], sample: Any) -> M:
        return self._plan_in(mirror)(sample, "")  # type: ignore[no-any-return]

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

    # ------------------------------------------------------------------------ field plans
    def _plan_out(self, mirror: type) -> Callable[[Any, str], Any]:
        plan = self._outbound.get(mirror)
        if plan is None:
            cls = self.ros_class(mirror)  # checks the mirror against its interface file, once
            steps = [(name, self._step_out(hint)) for name, hint in mirror_fields(mirror)]
            ros_type = mirror.ROS_TYPE  # type: ignore[attr-defined]

            def general(msg: Any, path: str) -> Any:
                kwargs = {name: step(getattr(msg, name), f"{path}.{name}" if path else name) for name, step in steps}
                try:
                    return cls(**kwargs)
                except (AssertionError, TypeError, ValueError, AttributeError) as error:
                    raise TransportError(f"cannot build {ros_type} from {mirror.__name__}: {error or type(error).__name__}") from None

            fast = _compiled(lambda: compile_outbound(mirror, self.ros_class, self._step_out))

            def plan(msg: Any, path: str) -> Any:
                if fast is not None and not path:  # a whole message: the compiled path, unless a value needs the general one
                    try:
                        return fast(msg)
                    except (Slow, AssertionError, TypeError, ValueError, AttributeError):
                        pass
                return general(msg, path)

            self._outbound[mirror] = plan
        return plan

    def _step_out(self, hint: Any) -> Step:
        return _step(hint, self._value_to_ros, lambda value, path: self._plan_out(hint)(value, path) if type(value) is hint
                     else self._value_to_ros(hint, value, path), tuple, list)

    def _plan_in(self, mirror: type) -> Callable[[Any, str], Any]:
        plan = self._inbound.get(mirror)
        if plan is None:
            steps = [(name, self._step_in(hint)) for name, hint in mirror_fields(mirror)]
            ros_type = mirror.ROS_TYPE  # type: ignore[attr-defined]

            def general(sample: Any, path: str) -> Any:
                kwargs = {}
                for name, step in steps:
                    where = f"{path}.{name}" if path else name
                    try:
                        raw = getattr(sample, name)
                    except AttributeError:
                        raise TransportError(f"{ros_type}: received message has no field {where!r}") from None
                    kwargs[name] = step(raw, where)
                return mirror(**kwargs)

            fast = _compiled(lambda: compile_inbound(mirror, self._step_in))

            def plan(sample: Any, path: str) -> Any:
                if fast is not None and not path:  # a whole message: the compiled path, unless a value needs the general one
                    try:
                        return fast(sample)
                    except (Slow, AttributeError):
                        pass
                return general(sample, path)

            self._inbound[mirror] = plan
        return plan

    def _step_in(self, hint: Any) -> Step:
        return _step(hint, self._value_from_ros, lambda value, path: self._plan_in(hint)(value, path), list, tuple)

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


def _compiled(compile_plan: Callable[[], Callable[[Any], Any]]) -> Callable[[Any], Any] | None:
    """The compiled path of a mirror, or None when it cannot be compiled (a nested mirror that does
    not match its interface file: the general plan says so when such a message is sent)."""
    try:
        return compile_plan()
    except Exception:  # noqa: BLE001 - the general plan reports it, naming the field
        return None


def _step(hint: Any, general: Callable[[Any, Any, str], Any], nested: Step, arrives: type, leaves: Callable[[Any], Any]) -> Step:
    """One field's conversion: ``nested`` for a mirror, a plain value or a sequence of plain
    values (``arrives`` as a tuple or list) of exactly its type as it is, the rest by ``general``."""
    if hint in PLAIN:
        return lambda value, path: value if type(value) is hint else general(hint, value, path)
    if is_mirror(hint):
        return nested
    item = sequence_item(hint) if hint is not bytes else None
    if item in PLAIN:
        return lambda value, path: (
            leaves(value) if type(value) is arrives and all(type(v) is item for v in value) else general(hint, value, path)
        )
    return lambda value, path: general(hint, value, path)
