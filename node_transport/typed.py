"""Wire dataclasses <-> the typed messages of ``dual_arm_executive_interfaces``.

The nodes think in the dataclasses of :mod:`node_transport.wire` (optional fields,
enums, primitives as tagged unions); on the wire they travel as the ``.msg`` types of the
interface package, so ``ros2 topic echo``, PlotJuggler and Foxglove show and plot every field.
This module is the one place that maps between the two:

* an absent optional string is ``""`` in the message, an absent primitive index or count ``-1``;
* a run time ``t`` becomes the ROS time ``header.stamp`` (the clock's epoch plus ``t``, added in
  integer nanoseconds so that it comes back to within a nanosecond) and back, into the
  receiver's own run time;
* only a primitive's fields (``primitive_json``) and what a primitive returned (``result_json``)
  stay JSON: their shape depends on the primitive's kind;
* the cell model's maps (frame attributes, elements, joint poses, true and located poses) become
  lists of named entries (``diagnostic_msgs/KeyValue``, ``NamedPose``, ``NamedJointPose``), poses
  ``geometry_msgs/Pose``; a name listed twice is refused.

What arrives is checked exactly as the JSON codec checks it -- the received message is put back
into the dataclass's shape and validated by :func:`codec.from_primitive` -- so a message that is
out of contract (an unknown event, a fault kind nobody knows, a primitive that does not parse)
raises :class:`codec.WireError` naming the topic, the ROS type and the ``.msg`` field, and the
receiver reports and ignores it as before.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from core_functions.geometry import Pose
from node_transport.clock import Clock
from node_transport import codec, mirrors, msgs
from node_transport.msgs import Header, KeyValue, Time
from node_transport.wire import (
    BridgeCommand,
    BridgeFeedback,
    CellSnapshot,
    EngineEvent,
    EngineStatus,
    FaultKind,
    GroupProgress,
    LocatedFrames,
    SmRequest,
    SmResult,
    SmStatus,
    SmStructure,
    SyncMessage,
)

W = TypeVar("W")
T = TypeVar("T")

PACKAGE = "dual_arm_executive_interfaces"
# Items a received sequence may hold.  A typed message has no JSON text for codec.MAX_MESSAGE_BYTES
# to bound, so this is the receiver's own limit: well above what validate lets through (a cell
# within 4 MB of JSON has about 31,000 frames), well below what would tie a node up for seconds.
MAX_SEQUENCE_ITEMS = 100_000


def _mirror(name: str) -> type:
    return mirrors.mirror(f"{PACKAGE}/msg/{name}")


MachineStateMsg = _mirror("MachineState")
MachineRequestMsg = _mirror("MachineRequest")
MachineResultMsg = _mirror("MachineResult")
MachineStatusMsg = _mirror("MachineStatus")
MachineStructureMsg = _mirror("MachineStructure")
MachineTransitionMsg = _mirror("MachineTransition")
EngineStatusMsg = _mirror("EngineStatus")
EngineEventMsg = _mirror("EngineEvent")
OperatorActionMsg = _mirror("OperatorAction")
GroupProgressMsg = _mirror("GroupProgress")
BridgeCommandMsg = _mirror("BridgeCommand")
BridgeFeedbackMsg = _mirror("BridgeFeedback")
SyncMsg = _mirror("SyncMessage")
NamedPoseMsg = _mirror("NamedPose")
CellFrameMsg = _mirror("CellFrame")
CellElementMsg = _mirror("CellElement")
NamedJointPoseMsg = _mirror("NamedJointPose")
CellSnapshotMsg = _mirror("CellSnapshot")
LocatedFramesMsg = _mirror("LocatedFrames")
RunPlanMsg = _mirror("RunPlan")  # the dry run's plan of a run (execution_engine/run_plan.py)

#: every type of the interface package a node publishes (a recorder's discovery knows them)
MESSAGE_TYPES: tuple[type, ...] = (
    MachineStateMsg, MachineStatusMsg, MachineStructureMsg, MachineRequestMsg, MachineResultMsg, EngineStatusMsg, EngineEventMsg,
    BridgeCommandMsg, BridgeFeedbackMsg, SyncMsg, CellSnapshotMsg, LocatedFramesMsg, RunPlanMsg,
)
_NANO = 1_000_000_000


class Epoch(Protocol):
    """What converting times needs of a clock: the ROS time of its run time 0."""

    @property
    def epoch(self) -> float: ...


# ---------------------------------------------------------------------------------- time
_EPOCHS: dict[float, Time] = {}  # a clock's epoch as a Time: worked out once, stamps are made per state change


def _epoch_time(epoch: float) -> Time:
    time = _EPOCHS.get(epoch)
    if time is None:
        if len(_EPOCHS) >= 64:
            _EPOCHS.clear()
        time = _EPOCHS[epoch] = Time.from_seconds(epoch)
    return time


def stamp_of(clock: Epoch, t: float) -> Time:
    """The ROS time of run time ``t`` on ``clock`` (what :meth:`Node.now_stamp` gives at ``t``)."""
    epoch, whole = _epoch_time(clock.epoch), math.floor(t)
    nanosec = int(round((t - whole) * 1e9))  # as Time.from_seconds(t), without the Time
    if nanosec == _NANO:
        whole, nanosec = whole + 1, 0
    total = (epoch.sec + whole) * _NANO + epoch.nanosec + nanosec
    return Time(total // _NANO, total % _NANO)


def run_time(clock: Epoch, stamp: Any) -> float:
    """Run time on ``clock`` of a ROS time stamp (the inverse of :func:`stamp_of`)."""
    epoch = _epoch_time(clock.epoch)
    return (stamp.sec - epoch.sec) + (stamp.nanosec - epoch.nanosec) * 1e-9


def _header(clock: Clock, t: float) -> Header:
    return Header(stamp=stamp_of(clock, t))


def _text(value: str | None) -> str:
    return "" if value is None else value


def _opt(value: str) -> str | None:
    return value if value else None


def _fault(fault: FaultKind | None) -> str:
    return "" if fault is None else fault.value


def _json(value: Any) -> str:
    return "" if value is None else codec.encode(value)


# ------------------------------------------------------------------------------ outbound
def machine_state(group: str, state: str, clock: Clock) -> Any:
    """``<group>/sm/state``: the state a machine is in, stamped now."""
    return MachineStateMsg(header=_header(clock, clock.now()), group=group, state=state)


def _request_msg(r: SmRequest, clock: Clock) -> Any:
    return MachineRequestMsg(
        id=r.id, kind=r.kind, operation=r.operation, function=r.function, params=tuple(r.params), attempt=r.attempt,
        sync=r.sync, partners=tuple(r.partners), cell=r.cell,
    )


def _result_msg(r: SmResult, clock: Clock) -> Any:
    return MachineResultMsg(
        header=_header(clock, r.t_end), id=r.id, group=r.group, outcome=r.outcome, operation=r.operation,
        function=r.function, error=_text(r.error), fault=_fault(r.fault),
        start=stamp_of(clock, r.t_start), primitives=r.primitives,
    )


def _status_msg(s: SmStatus, clock: Clock) -> Any:
    return MachineStatusMsg(
        header=_header(clock, s.t), group=s.group, event=s.event, state=s.state,
        from_state=_text(s.from_state), to_state=_text(s.to_state), signal=_text(s.signal),
        operation=_text(s.operation), function=_text(s.function), request_id=_text(s.request_id),
        primitive=_text(s.primitive), index=-1 if s.index is None else s.index,
        count=-1 if s.count is None else s.count, outcome=_text(s.outcome), error=_text(s.error),
        result_json=_json(s.result),
    )


def _structure_msg(s: SmStructure, clock: Clock) -> Any:
    return MachineStructureMsg(
        group=s.group, initial=s.initial, states=tuple(s.states),
        transitions=tuple(MachineTransitionMsg(source=t.source, signal=t.signal, target=t.target) for t in s.transitions),
    )


def _engine_status_msg(s: EngineStatus, clock: Clock) -> Any:
    return EngineStatusMsg(
        header=_header(clock, s.t), app=s.app, state=s.state, operation_index=s.operation_index,
        operation_count=s.operation_count, operation_id=_text(s.operation_id),
        groups=tuple(
            GroupProgressMsg(group=g, state=p.state, operation=_text(p.operation), function=_text(p.function), position=p.position)
            for g, p in s.groups.items()
        ),
        message=s.message, speed_override=float(s.speed_override),
    )


def _engine_event_msg(e: EngineEvent, clock: Clock) -> Any:
    return EngineEventMsg(
        header=_header(clock, e.t), event=e.event, state=e.state, operation=_text(e.operation),
        from_state=_text(e.from_state), message=e.message,
        action=OperatorActionMsg(command=_text(e.command), source=_text(e.source), accepted=bool(e.accepted), answer=_text(e.answer)),
    )


def _command_msg(c: BridgeCommand, clock: Clock) -> Any:
    kind, fields = "", ""
    if c.primitive is not None:
        raw = codec.to_primitive(c.primitive)
        kind = raw.pop("kind")
        fields = codec.encode(raw)
    return BridgeCommandMsg(id=c.id, group=c.group, op=c.op, primitive_kind=kind, primitive_json=fields)


def _feedback_msg(f: BridgeFeedback, clock: Clock) -> Any:
    return BridgeFeedbackMsg(
        header=_header(clock, f.t), id=f.id, group=f.group, status=f.status, error=_text(f.error),
        fault=_fault(f.fault), result_json=_json(f.result),
    )


def _sync_msg(s: SyncMessage, clock: Clock) -> Any:
    return SyncMsg(
        header=_header(clock, s.t), group=s.group, key=s.key, event=s.event, state=s.state, error=_text(s.error),
        fault=_fault(s.fault),
    )


def _pose_msg(p: Pose) -> msgs.Pose:
    x, y, z, qx, qy, qz, qw = (float(v) for v in (p.x, p.y, p.z, p.qx, p.qy, p.qz, p.qw))
    return msgs.Pose(msgs.Point(x, y, z), msgs.Quaternion(qx, qy, qz, qw))


def _pairs(values: dict[str, str]) -> tuple[KeyValue, ...]:
    return tuple(KeyValue(key=k, value=v) for k, v in values.items())


def _named_poses(poses: dict[str, Pose]) -> tuple[Any, ...]:
    return tuple(NamedPoseMsg(name=name, pose=_pose_msg(pose)) for name, pose in poses.items())


def _cell_msg(c: CellSnapshot, clock: Clock) -> Any:
    return CellSnapshotMsg(
        name=c.name,
        frames=tuple(CellFrameMsg(name=f.name, pose=_pose_msg(f.pose), kind=f.kind, parent=f.parent, attributes=_pairs(f.attributes))
                     for f in c.frames),
        elements=tuple(CellElementMsg(name=name, attributes=_pairs(attributes)) for name, attributes in c.elements.items()),
        joint_poses=tuple(
            NamedJointPoseMsg(name=name, group=c.joint_pose_groups.get(name, ""), joint_names=tuple(joints),
                              positions=tuple(float(v) for v in joints.values()))
            for name, joints in c.joint_poses.items()
        ),
        truth=_named_poses(c.truth),
    )


def _located_msg(m: LocatedFrames, clock: Clock) -> Any:
    return LocatedFramesMsg(header=_header(clock, m.t), group=m.group, cell=m.cell, frames=_named_poses(m.frames))


_OUT: dict[type, tuple[type, Callable[[Any, Clock], Any]]] = {
    SmRequest: (MachineRequestMsg, _request_msg),
    SmResult: (MachineResultMsg, _result_msg),
    SmStatus: (MachineStatusMsg, _status_msg),
    SmStructure: (MachineStructureMsg, _structure_msg),
    EngineStatus: (EngineStatusMsg, _engine_status_msg),
    EngineEvent: (EngineEventMsg, _engine_event_msg),
    BridgeCommand: (BridgeCommandMsg, _command_msg),
    BridgeFeedback: (BridgeFeedbackMsg, _feedback_msg),
    SyncMessage: (SyncMsg, _sync_msg),
    CellSnapshot: (CellSnapshotMsg, _cell_msg),
    LocatedFrames: (LocatedFramesMsg, _located_msg),
}


def msg_type(wire_cls: type) -> type:
    """The message type that carries ``wire_cls`` on the wire (``SmStatus`` -> ``MachineStatus``)."""
    return _OUT[wire_cls][0]


def to_msg(obj: Any, clock: Clock) -> Any:
    """The typed message of a wire dataclass; run times become stamps on ``clock``."""
    return _OUT[type(obj)][1](obj, clock)


# ------------------------------------------------------------------------------- inbound
class _Bad(Exception):
    def __init__(self, reason: str, path: str) -> None:
        super().__init__(reason)
        self.reason, self.path = reason, path


def _str(msg: Any, name: str) -> str:
    value = getattr(msg, name, None)
    if not isinstance(value, str):
        raise _Bad(f"expected a string, got {type(value).__name__}", name)
    return value


def _int(msg: Any, name: str) -> int:
    value = getattr(msg, name, None)
    if isinstance(value, bool) or not isinstance(value, int):
        raise _Bad(f"expected an integer, got {type(value).__name__}", name)
    return value


def _time(value: Any, path: str, clock: Epoch) -> float:
    """Run time of a ``builtin_interfaces/Time`` field, refused naming ``path`` when it is none."""
    if not (isinstance(getattr(value, "sec", None), int) and isinstance(getattr(value, "nanosec", None), int)):
        raise _Bad("expected a builtin_interfaces/Time", path)
    return run_time(clock, value)


def _stamp(msg: Any, clock: Epoch) -> float:
    return _time(getattr(getattr(msg, "header", None), "stamp", None), "header.stamp", clock)


def _number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Bad(f"expected a number, got {type(value).__name__}", path)
    return float(value)


def _parsed(msg: Any, name: str, *, kind: str = "") -> Any:
    """A ``*_json`` field parsed (None when empty); a value that is no JSON object is refused."""
    text = _str(msg, name)
    if not text:
        return None
    try:
        value = codec.parse_json(text)
    except ValueError as error:
        raise _Bad(str(error), name) from None
    if not isinstance(value, dict):
        raise _Bad(f"expected a JSON object, got {type(value).__name__}", name)
    if kind:
        if value.get("kind", kind) != kind:
            raise _Bad(f"says kind {value.get('kind')!r}, primitive_kind says {kind!r}", name)
        value = {**value, "kind": kind}
    return value


def _opt_index(msg: Any, name: str) -> int | None:
    value = _int(msg, name)
    return None if value == -1 else value


def _request_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    return {
        "id": _str(m, "id"), "kind": _str(m, "kind"), "operation": _str(m, "operation"), "function": _str(m, "function"),
        "params": _items(m, "params"), "attempt": _int(m, "attempt"), "sync": _str(m, "sync"),
        "partners": _items(m, "partners"), "cell": _str(m, "cell"),
    }


def _result_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    return {
        "id": _str(m, "id"), "group": _str(m, "group"), "outcome": _str(m, "outcome"), "operation": _str(m, "operation"),
        "function": _str(m, "function"), "error": _opt(_str(m, "error")), "fault": _opt(_str(m, "fault")),
        "t_start": _time(getattr(m, "start", None), "start", clock), "t_end": _stamp(m, clock), "primitives": _int(m, "primitives"),
    }


def _status_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    raw: dict[str, Any] = {"group": _str(m, "group"), "event": _str(m, "event"), "state": _str(m, "state"), "t": _stamp(m, clock)}
    for name, key in (("from_state", "from"), ("to_state", "to"), ("signal", "signal"), ("operation", "operation"),
                      ("function", "function"), ("request_id", "request_id"), ("primitive", "primitive"),
                      ("outcome", "outcome"), ("error", "error")):
        raw[key] = _opt(_str(m, name))
    raw["index"], raw["count"] = _opt_index(m, "index"), _opt_index(m, "count")
    raw["result"] = _parsed(m, "result_json")
    return raw


def _items(m: Any, name: str) -> list[Any]:
    value = getattr(m, name, None)
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)):
        raise _Bad(f"expected a sequence, got {type(value).__name__}", name)
    if len(value) > MAX_SEQUENCE_ITEMS:
        raise _Bad(f"{len(value):,} items, over the limit of {MAX_SEQUENCE_ITEMS:,}", name)
    return list(value)


def _nested(items: list[Any], name: str, read: Callable[[Any], T]) -> list[T]:
    """Each item read, an error naming the item (``frames[3].pose``)."""
    out = []
    for i, item in enumerate(items):
        try:
            out.append(read(item))
        except _Bad as error:
            raise _Bad(error.reason, f"{name}[{i}].{error.path}") from None
    return out


def _structure_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    states = _items(m, "states")
    transitions = _nested(_items(m, "transitions"), "transitions",
                          lambda t: {"from": _str(t, "source"), "signal": _str(t, "signal"), "to": _str(t, "target")})
    return {"group": _str(m, "group"), "initial": _str(m, "initial"), "states": states, "transitions": transitions}


def _engine_status_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    groups = _nested(_items(m, "groups"), "groups", lambda g: {
        "group": _str(g, "group"), "state": _str(g, "state"),
        "operation": _opt(_str(g, "operation")), "function": _opt(_str(g, "function")), "position": _position(g),
    })
    by_group: dict[str, Any] = {}
    for i, g in enumerate(groups):
        if g["group"] in by_group:
            raise _Bad(f"group {g['group']!r} listed twice", f"groups[{i}].group")
        by_group[g.pop("group")] = g
    return {
        "app": _str(m, "app"), "state": _str(m, "state"), "operation_index": _int(m, "operation_index"),
        "operation_count": _int(m, "operation_count"), "t": _stamp(m, clock),
        "operation_id": _opt(_str(m, "operation_id")), "groups": by_group, "message": _str(m, "message"),
        "speed_override": _override(m),
    }


def _position(g: Any) -> str:
    """``in:N`` / ``before:N`` / ``finished:N`` or "" (also from an interface package built before the field)."""
    kind, colon, number = (value := "" if getattr(g, "position", None) is None else _str(g, "position")).partition(":")
    if value and not (colon and kind in ("in", "before", "finished") and number.isdecimal() and number.isascii() and len(number) <= 9):
        raise _Bad(f"expected in:N, before:N, finished:N or nothing, got {value[:40]!r}", "position")
    return value


def _override(m: Any) -> float:
    value = _number(getattr(m, "speed_override", None), "speed_override")
    if not 0.0 <= value <= 100.0:  # NaN too: a share of the planned speed no back end may take
        raise _Bad(f"expected a percentage in [0, 100], got {value!r}", "speed_override")
    return value


def _engine_event_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    event = _str(m, "event")
    action = getattr(m, "action", None)
    raw: dict[str, Any] = {
        "event": event, "t": _stamp(m, clock), "state": _str(m, "state"), "operation": _opt(_str(m, "operation")),
        "from": _opt(_str(m, "from_state")), "message": _str(m, "message"),
    }
    try:
        for name in ("command", "source", "answer"):
            raw[name] = _opt(_str(action, name))
        accepted = getattr(action, "accepted", None)
        if not isinstance(accepted, bool):
            raise _Bad(f"expected true or false, got {type(accepted).__name__}", "accepted")
    except _Bad as error:
        raise _Bad(error.reason, f"action.{error.path}") from None
    raw["accepted"] = accepted if event == "operator" else None
    return raw


def _command_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    kind = _str(m, "primitive_kind")
    primitive = _parsed(m, "primitive_json", kind=kind or "?")
    if primitive is None and kind:
        raise _Bad(f"primitive_kind {kind!r} without its fields", "primitive_json")
    return {"id": _str(m, "id"), "group": _str(m, "group"), "op": _str(m, "op"), "primitive": primitive}


def _feedback_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    return {
        "id": _str(m, "id"), "group": _str(m, "group"), "status": _str(m, "status"), "error": _opt(_str(m, "error")),
        "fault": _opt(_str(m, "fault")), "result": _parsed(m, "result_json"), "t": _stamp(m, clock),
    }


def _sync_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    return {
        "group": _str(m, "group"), "key": _str(m, "key"), "event": _str(m, "event"), "state": _str(m, "state"),
        "t": _stamp(m, clock), "error": _opt(_str(m, "error")), "fault": _opt(_str(m, "fault")),
    }


_POSE_FIELDS = (("x", "position", "x"), ("y", "position", "y"), ("z", "position", "z"),
                ("qx", "orientation", "x"), ("qy", "orientation", "y"), ("qz", "orientation", "z"), ("qw", "orientation", "w"))


def _pose_raw(m: Any, name: str) -> dict[str, float]:
    """A ``geometry_msgs/Pose`` field in the codec's pose shape; a non-finite value or a quaternion
    that is not of unit length is refused naming the field."""
    pose, values = getattr(m, name, None), {}
    for key, part, axis in _POSE_FIELDS:
        values[key] = _number(getattr(getattr(pose, part, None), axis, None), f"{name}.{part}.{axis}")
    try:
        Pose(**values)
    except ValueError as error:
        raise _Bad(str(error), f"{name}.orientation" if "quaternion" in str(error) else name) from None
    return values


def _by_name(m: Any, name: str, key: str, read: Callable[[Any], Any]) -> dict[str, Any]:
    """A sequence of named entries as the map the dataclass holds; a name listed twice is refused."""
    out: dict[str, Any] = {}
    for i, (entry, value) in enumerate(_nested(_items(m, name), name, lambda item: (_str(item, key), read(item)))):
        if entry in out:
            raise _Bad(f"{entry!r} listed twice", f"{name}[{i}].{key}")
        out[entry] = value
    return out


def _attributes(m: Any) -> dict[str, str]:
    return _by_name(m, "attributes", "key", lambda kv: _str(kv, "value"))


def _joints(m: Any) -> dict[str, float]:
    names, positions = _items(m, "joint_names"), _items(m, "positions")
    if len(names) != len(positions):
        raise _Bad(f"{len(positions)} positions for {len(names)} joint names", "positions")
    values = []
    for i, (joint, value) in enumerate(zip(names, positions)):
        if not isinstance(joint, str):
            raise _Bad(f"expected a string, got {type(joint).__name__}", f"joint_names[{i}]")
        values.append(_number(value, f"positions[{i}]"))
    if len(set(names)) != len(names):
        raise _Bad("a joint listed twice", "joint_names")
    return dict(zip(names, values))


def _cell_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    frames = _nested(_items(m, "frames"), "frames", lambda f: {
        "name": _str(f, "name"), "pose": _pose_raw(f, "pose"), "kind": _str(f, "kind"), "parent": _str(f, "parent"),
        "attributes": _attributes(f),
    })
    joint_poses = _by_name(m, "joint_poses", "name", lambda j: (_joints(j), _str(j, "group")))
    return {
        "name": _str(m, "name"), "frames": frames,
        "elements": _by_name(m, "elements", "name", _attributes),
        "joint_poses": {name: joints for name, (joints, _) in joint_poses.items()},
        "joint_pose_groups": {name: group for name, (_, group) in joint_poses.items() if group},
        "truth": _by_name(m, "truth", "name", lambda p: _pose_raw(p, "pose")),
    }


def _located_raw(m: Any, clock: Epoch) -> dict[str, Any]:
    return {
        "group": _str(m, "group"), "cell": _str(m, "cell"), "t": _stamp(m, clock),
        "frames": _by_name(m, "frames", "name", lambda p: _pose_raw(p, "pose")),
    }


#: reading a message back: its fields in the dataclass's JSON shape, and the dataclass keys whose
#: field has another name in the .msg (so an error names the .msg field)
_IN: dict[type, tuple[Callable[[Any, Epoch], dict[str, Any]], dict[str, str]]] = {
    SmRequest: (_request_raw, {}),
    SmResult: (_result_raw, {"t_start": "start", "t_end": "header.stamp"}),
    SmStatus: (_status_raw, {"from": "from_state", "to": "to_state", "result": "result_json"}),
    SmStructure: (_structure_raw, {}),
    EngineStatus: (_engine_status_raw, {}),
    EngineEvent: (_engine_event_raw, {"from": "from_state", "command": "action.command", "source": "action.source",
                                      "accepted": "action.accepted", "answer": "action.answer"}),
    BridgeCommand: (_command_raw, {"primitive": "primitive_json"}),
    BridgeFeedback: (_feedback_raw, {"result": "result_json"}),
    SyncMessage: (_sync_raw, {"t": "header.stamp"}),
    CellSnapshot: (_cell_raw, {"joint_pose_groups": "joint_poses"}),
    LocatedFrames: (_located_raw, {"t": "header.stamp"}),
}


def _of_type(msg: Any, expected: type, source: str) -> str:
    """The ROS name of ``expected``; WireError when ``msg`` is of another type."""
    type_name = str(expected.ROS_TYPE)  # type: ignore[attr-defined]
    if type(msg) is not expected:
        raise codec.WireError(f"expected {type_name}, got {type(msg).__name__}", source=source, type_name=type_name)
    return type_name


def from_msg(wire_cls: type[W], msg: Any, clock: Epoch, *, source: str = "") -> W:
    """The wire dataclass of a received typed message; :class:`codec.WireError` (naming ``source``,
    the ROS type and the .msg field) when it is of another type or out of contract."""
    _of_type(msg, msg_type(wire_cls), source)
    return from_fields(wire_cls, msg, clock, source=source)


def from_fields(wire_cls: type[W], msg: Any, clock: Epoch, *, source: str = "") -> W:
    """As :func:`from_msg` for any object with the message's fields as attributes (a message
    decoded from a recording by ``mcap-ros2-support``)."""
    type_name = str(msg_type(wire_cls).ROS_TYPE)  # type: ignore[attr-defined]
    read, renames = _IN[wire_cls]
    try:
        raw = read(msg, clock)
    except _Bad as error:
        raise codec.WireError(error.reason, source=source, type_name=type_name, path=error.path) from None
    try:
        return codec.from_primitive(wire_cls, raw, source=source)
    except codec.WireError as error:
        head, dot, rest = error.path.partition(".")
        head, bracket, index = head.partition("[")
        path = renames.get(head, head) + (bracket + index) + (dot + rest)
        raise codec.WireError(error.reason, source=source, type_name=type_name, path=path) from None


def read_state(msg: Any, *, source: str = "") -> str:
    """The state named by a received ``MachineState``; WireError when it names none."""
    type_name = _of_type(msg, MachineStateMsg, source)
    if not isinstance(msg.state, str) or not msg.state:
        raise codec.WireError("names no state", source=source, type_name=type_name, path="state")
    return msg.state
