"""The 3D view's scene of a recording (``run --record``): what the robot's joints did, the goals, the located
frames and the cell, read from the MCAP file's own messages.

The file is outside input and is read as ``report`` reads it (:func:`~execution_engine.recorder.reading.iter_messages`:
sizes not trusted, a damaged tail ends the reading there); a message out of contract (a JointState whose names
and positions differ in number, a value that is not finite) is skipped and counted, never drawn.  Times are run
times: the header stamps (the log time for a command, which has no header) less the run clock's epoch the file
states.  The joint states are thinned evenly to at most :data:`MAX_SAMPLES` so a long recording stays within
the station's memory; a short one keeps every message, so the view at a slider position is the recording's
joint state at that instant.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from core_functions.robots import RobotModel
from execution_engine.app_model.document import read_document
from execution_engine.recorder.reading import Recording, is_mcap, iter_messages
from node_transport import codec, typed
from node_transport.wire import BridgeCommand, CellSnapshot, LocatedFrames
from operator_station.feed import MAX_JOINT_SAMPLES, Feed
from operator_station.scene3d import SceneLog, head_scene, scene_log, snapshot_cell

#: Joint samples a replay keeps (the feed's ring holds as many).
MAX_SAMPLES = MAX_JOINT_SAMPLES
#: Joints a recording may name in all (a cell of several robots has a few dozen).
MAX_JOINTS = 256
_NS = r"^(?:/[A-Za-z0-9_]+)*"
_JOINTS = re.compile(_NS + r"/joint_states$")
_COMMAND = re.compile(_NS + r"/([A-Za-z0-9_]+)/bridge/command$")
_LOCATED = re.compile(_NS + r"/([A-Za-z0-9_]+)/sm/located$")
_CELL = re.compile(_NS + r"/execution_engine/cell$")
_META = "dual_arm_executive"


@dataclass
class RecordedScene:
    """What a recording holds for the 3D view; ``samples`` rows are ``[t, *positions]`` in ``joint_names`` order."""

    joint_names: list[str] = field(default_factory=list)
    samples: list[list[float]] = field(default_factory=list)
    robot: RobotModel | None = None
    cell: dict[str, Any] | None = None
    events: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Epoch:
    epoch: float


class _Thinned:
    """Joint samples, evenly thinned: past the bound every other one goes and the stride doubles."""

    def __init__(self, bound: int) -> None:
        self.bound = bound
        self.rows: list[tuple[int, list[float]]] = []  # (stamp ns, positions)
        self.stride = 1
        self.seen = 0

    def add(self, ns: int, positions: list[float]) -> None:
        if self.seen % self.stride == 0:
            self.rows.append((ns, positions))
            if len(self.rows) > self.bound:
                self.rows = self.rows[::2]
                self.stride *= 2
        self.seen += 1


def _ns(stamp: Any) -> int | None:
    sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if not isinstance(sec, int) or not isinstance(nanosec, int) or not 0 <= nanosec < 1_000_000_000:
        return None
    return sec * 1_000_000_000 + nanosec


def _wanted(topic: str, ros_type: str) -> bool:
    return bool(_JOINTS.match(topic) or _COMMAND.match(topic) or _LOCATED.match(topic) or _CELL.match(topic))


def read_scene(path: Path) -> RecordedScene:
    """The recording's scene (NotARecording or OverLimit, one line naming the file, as ``report`` refuses it)."""
    recording = Recording(str(path))
    scene = RecordedScene()
    index: dict[str, int] = {}
    thinned = _Thinned(MAX_SAMPLES)
    last: list[float] = []
    raw: list[tuple[int, str, Any]] = []  # (ns, kind, message) for commands, located frames and the cell
    bad = 0
    for message in iter_messages(path, recording, wanted=_wanted):
        topic, msg = message.topic, message.msg
        if _JOINTS.match(topic):
            ns = _ns(getattr(getattr(msg, "header", None), "stamp", None))
            names, positions = list(getattr(msg, "name", []) or []), list(getattr(msg, "position", []) or [])
            if ns is None or len(names) != len(positions) or not all(isinstance(p, float) and math.isfinite(p) for p in positions):
                bad += 1
                continue
            for name in names:
                if name not in index and isinstance(name, str) and len(index) < MAX_JOINTS:
                    index[name] = len(index)
                    last.append(math.nan)
            for name, value in zip(names, positions):
                if name in index:
                    last[index[name]] = value
            thinned.add(ns, list(last))
        else:
            raw.append((message.log_time_ns, topic, msg))
    epoch = _epoch(recording, thinned, raw)
    clock = _Epoch(epoch)
    scene.joint_names = list(index)
    scene.samples = [[typed.run_time(clock, _stamp(ns)), *row, *([math.nan] * (len(index) - len(row)))] for ns, row in thinned.rows]
    log = SceneLog()
    for ns, topic, msg in raw:
        try:
            if _CELL.match(topic):
                scene.cell = snapshot_cell(typed.from_fields(CellSnapshot, msg, clock, source=topic))
            elif _LOCATED.match(topic):
                located = typed.from_fields(LocatedFrames, msg, clock, source=topic)
                log.located(located.t, located.group, located.frames)
            else:
                command = typed.from_fields(BridgeCommand, msg, clock, source=topic)
                if command.op == "execute" and command.primitive is not None:
                    log.goal(typed.run_time(clock, _stamp(ns)), command.group, command.primitive)
        except (codec.WireError, ValueError):
            bad += 1
    scene.events = sorted(log.events, key=lambda e: e["t"])
    scene.robot, cell, notes = _robot(path, recording)
    scene.cell = scene.cell or cell
    scene.notes = notes + ([f"{path.name}: {bad} message(s) out of contract were skipped by the 3D view"] if bad else [])
    if thinned.stride > 1:
        scene.notes.append(f"{path.name}: every {thinned.stride}th joint state is shown (the recording has {thinned.seen:,})")
    return scene


def _stamp(ns: int) -> SimpleNamespace:
    return SimpleNamespace(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _epoch(recording: Recording, thinned: _Thinned, raw: list[tuple[int, str, Any]]) -> float:
    """The run clock's epoch the file states, else its first message's time (a cut file has no end)."""
    try:
        stated = float(recording.metadata.get(_META, {}).get("clock_epoch", ""))
        if math.isfinite(stated) and abs(stated) < 1e12:
            return stated
    except ValueError:
        pass
    first = [ns for ns, _ in thinned.rows[:1]] + [ns for ns, _, _ in raw[:1]] + [recording.start_ns or 0]
    return min(first) * 1e-9


def _robot(path: Path, recording: Recording) -> tuple[RobotModel | None, dict[str, Any] | None, list[str]]:
    """The recorded robot by the name the file states; a cell of several robots from the application it names
    (beside the recording or where it was run), whose cell places them."""
    meta = recording.metadata.get(_META, {})
    name = meta.get("robot", "")
    robot, cell, _ = head_scene(name, None) if name else (None, None, [])
    if robot is not None:
        return robot, cell, []
    application = meta.get("application_path", "")
    for folder in (path.parent, Path.cwd()):
        candidate = folder / application if application else None
        if candidate is not None and candidate.is_file():
            doc, _ = read_document(candidate)
            if doc is not None:
                found, cell, more = head_scene(doc.robot, (candidate.parent / doc.cell) if doc.cell else None)
                if found is not None:
                    return found, cell, more
    return None, None, [f"{path.name}: its robot {name!r} has no model here: the 3D view shows the cell alone"]


def load_scene(feed: Feed, path: Path) -> RecordedScene | None:
    """Put a recording's scene and joint states into the 3D view of the replay ``feed`` shows (after
    :meth:`Feed.begin`); the scene, or None for a trace (it holds none: the view draws the joints its records
    report, as the joint plots do -- the plots show a recording as its trace, the view its every joint state)."""
    if not is_mcap(path):
        return None
    scene = read_scene(path)
    log = scene_log(feed)
    log.begin(feed.snapshot.run, scene.robot, scene.cell)
    log.notes.extend(scene.notes)
    for event in scene.events:
        log.add(event)
    log.set_joints(scene.joint_names, scene.samples)
    return scene
