"""Cyclone DDS types built from ROS 2 ``.msg``/``.srv``/``.action`` files, without a ROS install.

The interface files are the one source of every type on the wire: the project's own in
``interfaces/dual_arm_executive_interfaces`` (which colcon builds into rclpy types) and copies of
the standard ones in ``interfaces/ros2_jazzy``.  This module parses them and makes
``cyclonedds.idl.IdlStruct`` dataclasses with the names and layout rosidl gives them, so a sample
written here is byte for byte what ``rmw_cyclonedds_cpp`` writes:

* type names ``pkg::msg::dds_::Name_`` (``pkg::srv::dds_::Name_Request_``,
  ``pkg::action::dds_::Name_SendGoal_Request_``...), fields in file order, final extensibility,
  plain CDR (XCDR1: 8-byte alignment, which cyclonedds-python writes for such types);
* ROS ``char`` and ``byte`` are octets, ``string<=N`` a bounded string, ``T[N]`` an array,
  ``T[]``/``T[<=N]`` a sequence; an empty structure gets rosidl's
  ``uint8 structure_needs_at_least_one_member``;
* a service's request and reply on the wire start with rmw_cyclonedds_cpp's request header
  (``uint64 guid; int64 seq``): :meth:`InterfaceRegistry.wire_service` builds those variants.

Only the grammar ROS interface files use is accepted; anything else is an :class:`InterfaceError`
naming the file and line.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core_functions.resources import share_roots

MAX_FILE = 64 * 1024  # bytes of one interface file; ROS's largest are a few kB
# the parts of an action, longest suffix first: what rosidl generates for pkg/action/Name
_ACTION_PARTS = ("SendGoal_Request", "SendGoal_Response", "GetResult_Request", "GetResult_Response", "FeedbackMessage", "Goal", "Result", "Feedback")

_PRIMITIVES: dict[str, str] = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "float32": "float32", "float64": "float64",
    "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16", "int32": "int32",
    "uint32": "uint32", "int64": "int64", "uint64": "uint64", "string": "string",
}
_FIELD = re.compile(
    r"^(?P<type>[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*)?)(?:<=(?P<strbound>\d+))?"
    r"(?:\[(?P<array>(?:<=)?\d*)\])?\s+(?P<name>[A-Za-z][A-Za-z0-9_]*)(?:\s*(?P<eq>=)?\s*(?P<value>.+))?$"
)


class InterfaceError(ValueError):
    """An interface file that cannot be read or parsed; the message names file and line."""


@dataclass(frozen=True)
class FieldSpec:
    """One field (or constant) of a ROS interface."""

    base: str  # primitive name, or "pkg/msg/Name" for a nested message
    name: str
    string_bound: int | None = None
    array: str | None = None  # None: scalar; "": unbounded sequence; "<=N": bounded; "N": fixed
    default: str | None = None


@dataclass(frozen=True)
class MessageSpec:
    ros_type: str  # pkg/msg/Name, pkg/srv/Name_Request, pkg/action/Name_Goal
    fields: tuple[FieldSpec, ...]
    constants: tuple[FieldSpec, ...] = ()


def parse_message(text: str, ros_type: str, source: str = "<text>", line_offset: int = 0) -> MessageSpec:
    """The fields and constants of one message section, resolving unqualified types in its package."""
    package = ros_type.split("/")[0]
    fields: list[FieldSpec] = []
    constants: list[FieldSpec] = []
    for number, raw in enumerate(text.splitlines(), start=1 + line_offset):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        match = _FIELD.match(line)
        if match is None:
            raise InterfaceError(f"{source}:{number}: cannot parse {raw.strip()!r}")
        base = match["type"]
        value = match["value"]
        if base in _PRIMITIVES or base == "wstring":
            if base == "wstring":
                raise InterfaceError(f"{source}:{number}: wstring is not supported")
        elif "/" in base:
            pkg, name = base.split("/")
            base = f"{pkg}/msg/{name}"
        elif base == "Header":
            base = "std_msgs/msg/Header"
        else:
            base = f"{package}/msg/{base}"
        if value is not None and match["eq"] is None:
            value = value.split("#")[0].strip() if base != "string" else value.strip()
        elif value is not None:
            value = value.strip() if base == "string" else value.split("#")[0].strip()
        spec = FieldSpec(
            base=base, name=match["name"],
            string_bound=int(match["strbound"]) if match["strbound"] else None,
            array=match["array"], default=value,
        )
        if match["eq"]:
            if not spec.name.isupper() and not re.fullmatch(r"[A-Z][A-Z0-9_]*", spec.name):
                raise InterfaceError(f"{source}:{number}: constant {spec.name!r} must be upper case")
            if spec.array is not None or base not in _PRIMITIVES:
                raise InterfaceError(f"{source}:{number}: constants must be primitive scalars")
            constants.append(spec)
        else:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", spec.name):
                raise InterfaceError(f"{source}:{number}: field {spec.name!r} must be lower case")
            fields.append(spec)
    if not fields:
        fields.append(FieldSpec("uint8", "structure_needs_at_least_one_member"))
    return MessageSpec(ros_type, tuple(fields), tuple(constants))


def _sections(text: str, count: int, source: str) -> list[tuple[str, int]]:
    """Split a .srv (2) or .action (3) file on its ``---`` lines, with each section's line offset."""
    parts: list[tuple[str, int]] = []
    current: list[str] = []
    start = 0
    for index, line in enumerate(text.splitlines()):
        if line.strip() == "---":
            parts.append(("\n".join(current), start))
            current, start = [], index + 1
        else:
            current.append(line)
    parts.append(("\n".join(current), start))
    if len(parts) != count:
        raise InterfaceError(f"{source}: expected {count} sections separated by '---', found {len(parts)}")
    return parts


def dds_type_name(ros_type: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (rosidl's DDS name)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def interface_roots() -> list[Path]:
    """Folders holding ``<pkg>/<msg|srv|action>/<Name>.<ext>``: the project's and the standard copies."""
    roots: list[Path] = []
    for share in share_roots():
        base = share / "interfaces"
        for sub in (base, base / "ros2_jazzy"):
            if sub.is_dir() and sub not in roots:
                roots.append(sub)
    return roots


@dataclass
class InterfaceRegistry:
    """Parses interface files on first use and builds (and caches) one IdlStruct class per type."""

    roots: list[Path] = field(default_factory=interface_roots)
    _specs: dict[str, MessageSpec] = field(default_factory=dict)
    _classes: dict[str, type] = field(default_factory=dict)

    # ------------------------------------------------------------------------------ files
    def _read(self, package: str, kind: str, name: str) -> tuple[str, str]:
        ext = {"msg": "msg", "srv": "srv", "action": "action"}[kind]
        for root in self.roots:
            path = root / package / kind / f"{name}.{ext}"
            if path.is_file():
                data = path.read_bytes()
                if len(data) > MAX_FILE:
                    raise InterfaceError(f"{path}: larger than {MAX_FILE} bytes")
                return data.decode("utf-8"), str(path)
        raise InterfaceError(
            f"no interface file for {package}/{kind}/{name} in {', '.join(map(str, self.roots)) or '(no interface folder found)'}"
        )

    def file_text(self, package: str, kind: str, name: str) -> str:
        """The text of ``<package>/<kind>/<name>.<kind>`` (a recorder stores it as the schema)."""
        return self._read(package, kind, name)[0]

    def spec(self, ros_type: str) -> MessageSpec:
        """The parsed spec of ``pkg/msg/Name``, ``pkg/srv/Name_Request|_Response`` or
        ``pkg/action/Name_Goal|_Result|_Feedback``."""
        cached = self._specs.get(ros_type)
        if cached is not None:
            return cached
        try:
            package, kind, name = ros_type.split("/")
        except ValueError:
            raise InterfaceError(f"{ros_type!r} is not an interface name like 'std_msgs/msg/String'") from None
        if kind == "msg":
            text, source = self._read(package, kind, name)
            self._specs[ros_type] = parse_message(text, ros_type, source)
        elif kind == "srv":
            base, _, part = name.rpartition("_")
            if part not in ("Request", "Response"):
                raise InterfaceError(f"{ros_type}: a srv part is Request or Response")
            text, source = self._read(package, kind, base)
            for section_name, (section, offset) in zip(("Request", "Response"), _sections(text, 2, source)):
                key = f"{package}/{kind}/{base}_{section_name}"
                self._specs[key] = parse_message(section, key, source, offset)
        elif kind == "action":
            base = next((name[: -len(p) - 1] for p in _ACTION_PARTS if name.endswith("_" + p)), None)
            if not base:
                raise InterfaceError(f"{ros_type}: an action part is one of {', '.join(_ACTION_PARTS)}")
            self._register_action(package, base)
        else:
            raise InterfaceError(f"{ros_type}: kind must be msg, srv or action")
        return self._specs[ros_type]

    # ---------------------------------------------------------------------------- classes
    def message(self, ros_type: str) -> type:
        """The IdlStruct class of ``ros_type`` (nested types built first)."""
        cls = self._classes.get(ros_type)
        if cls is None:
            spec = self.spec(ros_type)
            cls = self._build(ros_type, dds_type_name(ros_type), spec.fields, spec.constants)
            self._classes[ros_type] = cls
        return cls

    def wire_service(self, ros_type: str) -> tuple[type, type]:
        """(request, reply) classes of ``pkg/srv/Name`` as rmw_cyclonedds_cpp puts them on the
        wire: the request header (``uint64 guid; int64 seq``) first, then the fields."""
        key = f"{ros_type}#wire"
        cached = self._classes.get(key + "Request")
        if cached is not None:
            return cached, self._classes[key + "Response"]
        header = (FieldSpec("uint64", "guid"), FieldSpec("int64", "seq"))
        made: list[type] = []
        for part in ("Request", "Response"):
            spec = self.spec(f"{ros_type}_{part}")
            cls = self._build(f"{ros_type}_{part}", dds_type_name(f"{ros_type}_{part}"), header + spec.fields, spec.constants)
            self._classes[key + part] = cls
            made.append(cls)
        return made[0], made[1]

    def _register_action(self, package: str, name: str) -> None:
        """The specs of an action's Goal, Result, Feedback and of the types rosidl derives from them."""
        text, source = self._read(package, "action", name)
        prefix = f"{package}/action/{name}"
        for section_name, (section, offset) in zip(("Goal", "Result", "Feedback"), _sections(text, 3, source)):
            self._specs[f"{prefix}_{section_name}"] = parse_message(section, f"{prefix}_{section_name}", source, offset)
        uuid = FieldSpec("unique_identifier_msgs/msg/UUID", "goal_id")
        derived: dict[str, tuple[FieldSpec, ...]] = {
            "SendGoal_Request": (uuid, FieldSpec(f"{prefix}_Goal", "goal")),
            "SendGoal_Response": (FieldSpec("bool", "accepted"), FieldSpec("builtin_interfaces/msg/Time", "stamp")),
            "GetResult_Request": (uuid,),
            "GetResult_Response": (FieldSpec("int8", "status"), FieldSpec(f"{prefix}_Result", "result")),
            "FeedbackMessage": (uuid, FieldSpec(f"{prefix}_Feedback", "feedback")),
        }
        for part, fields in derived.items():
            self._specs[f"{prefix}_{part}"] = MessageSpec(f"{prefix}_{part}", fields)

    def wire_action(self, ros_type: str) -> dict[str, type]:
        """The wire classes of action ``pkg/action/Name``, as rcl_action puts it on DDS: its services
        (``SendGoal``, ``GetResult``, ``CancelGoal``) as ``<service>_Request``/``_Response`` with the
        request header, ``FeedbackMessage`` and ``GoalStatusArray``."""
        out: dict[str, type] = {}
        for service in ("SendGoal", "GetResult"):
            out[f"{service}_Request"], out[f"{service}_Response"] = self.wire_service(f"{ros_type}_{service}")
        out["CancelGoal_Request"], out["CancelGoal_Response"] = self.wire_service("action_msgs/srv/CancelGoal")
        out["FeedbackMessage"] = self.message(f"{ros_type}_FeedbackMessage")
        out["GoalStatusArray"] = self.message("action_msgs/msg/GoalStatusArray")
        return out

    def _build(self, ros_type: str, typename: str, fields: Iterable[FieldSpec], constants: Iterable[FieldSpec]) -> type:
        from cyclonedds.idl import make_idl_struct  # optional: pip extra 'dds', only when DDS types are built

        annotations: dict[str, Any] = {}
        for spec in fields:
            annotations[spec.name] = self._annotation(spec)
        class_name = typename.replace("::", "__")
        cls = make_idl_struct(class_name, typename, annotations)
        for spec in constants:
            setattr(cls, spec.name, literal_value(spec))
        cls.ROS_TYPE = ros_type  # type: ignore[attr-defined]
        return cls

    def _annotation(self, spec: FieldSpec) -> Any:
        from cyclonedds.idl import types  # optional: pip extra 'dds', only when DDS types are built

        if spec.base in _PRIMITIVES:
            primitive = _PRIMITIVES[spec.base]
            if primitive == "string":
                item: Any = types.bounded_str[spec.string_bound] if spec.string_bound else str
            elif primitive == "bool":
                item = bool
            elif primitive == "float64":
                item = types.float64
            else:
                item = getattr(types, primitive)
        else:
            item = self.message(spec.base)
        if spec.array is None:
            return item
        if spec.array == "":
            return types.sequence[item]
        if spec.array.startswith("<="):
            return types.sequence[item, int(spec.array[2:])]
        return types.array[item, int(spec.array)]


def literal_value(spec: FieldSpec) -> Any:
    """The value a ``.msg`` default or constant's text stands for (its base type says how to read it)."""
    text = spec.default or ""
    if spec.base == "string":
        return text[1:-1] if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"" else text
    if spec.base == "bool":
        return text.lower() in ("true", "1")
    if spec.base.startswith("float"):
        return float(text)
    return int(text, 0)
