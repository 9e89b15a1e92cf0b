"""What the page's 3D view draws, as JSON: the robots (their URDFs, where each base stands), the cell, and
what happened in it over time -- each group's motion goals and the frames vision located -- for a live run
and for a replayed recording alike.

The robots are the URDFs the bridges publish as ``robot_description`` (the files the collision model reads,
:data:`robot_bridges.collision.robots.MODELS`), one per robot of a mixed cell, placed at its ``<robot xyz
rpy>``; the cell is the engine's :class:`~node_transport.wire.CellSnapshot` (frames already in the world
frame, zones among them).  Over time: every ``execute`` command a machine sends its bridge carries the
primitive, so its goal (a pose, joint values, a trajectory's points) is known as the motion starts, which no
trace record says; and every ``<group>/sm/located`` message gives the measured frames.  A live run collects
them from its transport (:func:`observe`), a replay from the recording's messages
(:mod:`operator_station.scene3d_recording`); the page keeps them with the run's records and draws the view at
its cursor from both, so the time slider moves the 3D view as it moves the rest.
"""
from __future__ import annotations

import threading
import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cell_runner.dry_run.report import DryRunReport
from core_functions.cell_index import CellFrame
from core_functions.cell_robots import CELL_ROBOT, CellNames, CellRobotModel, cell_robot_model
from core_functions.geometry import Pose
from core_functions.primitives import ExecuteTrajectory, FullBodyMove, MoveCartesian, MoveJoints, MoveRelative, RecordTrajectory
from core_functions.robots import RobotModel, find_robot
from execution_engine.app_model import Application
from execution_engine.app_model.cell import read_cell
from node_transport.wire import CellSnapshot
from operator_station.feed import Feed
from operator_station.scene3d_findings import dry_run_finding
from robot_bridges.collision.robots import MODELS

#: Events (goals and located frames) kept per run; a day of a busy cell sends far fewer.
MAX_EVENTS = 200_000
#: Events sent in one answer at most (the page asks again from where it got to).
MAX_BATCH = 5000
#: Frames of a cell drawn at most (a cell that runs fits in one message: far fewer).
MAX_FRAMES = 20_000
#: Points of a trajectory goal kept for its path (evenly chosen; the last point always).
MAX_PATH_POINTS = 200
#: The dry run's findings placed at most (each with every joint of the robot; the report's diagnostics are capped lower).
MAX_FINDINGS = 500
#: The named pose a robot is drawn in before any joint state has come (its simulator's start), the first one it has.
REST_POSES = ("initial", "home")


def pose_json(pose: Pose) -> list[float]:
    """``[x, y, z, qx, qy, qz, qw]``: metres and a unit quaternion, as three.js takes them."""
    return [pose.x, pose.y, pose.z, pose.qx, pose.qy, pose.qz, pose.qw]


@dataclass(frozen=True)
class RobotView:
    """One robot as the page loads it: its URDF, where its base stands in the cell, its TCP per arm."""

    name: str  # its name in the cell ("assembler"), or the model's for a one-robot application
    model: str
    urdf: str
    base: Pose
    prefix: str  # how the dry run's collision model names its links ("assembler/"), "" for one robot
    joints: tuple[str, ...]  # as /joint_states names them: the cell's names (with joint_prefix)
    tcps: Mapping[str, tuple[str, Pose]]  # group -> (link, tool pose in it)
    rest: Mapping[str, float] = field(default_factory=dict)  # drawn before any joint state: the model's initial pose
    joint_prefix: str = ""  # what the cell puts before the URDF's joint names (<robot prefix="viper_">)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "model": self.model, "urdf": self.urdf, "base": pose_json(self.base), "prefix": self.prefix,
                "joints": list(self.joints), "tcps": {g: {"link": link, "tool": pose_json(tool)} for g, (link, tool) in self.tcps.items()},
                "rest": dict(self.rest), "joint_prefix": self.joint_prefix}


def robot_views(robot: RobotModel) -> tuple[list[RobotView], list[str]]:
    """The robots to draw for ``robot`` (every member of a mixed cell), and a note for each without a URDF."""
    members = ([(m.name, m.cell_model, m.base, f"{m.name}/", m.names) for m in robot.members] if isinstance(robot, CellRobotModel)
               else [(robot.name, robot, Pose(), "", CellNames())])
    views: list[RobotView] = []
    notes: list[str] = []
    for name, model, base, prefix, names in members:  # model: under the cell's names, as /joint_states and the groups carry them
        known = MODELS.get(model.name)
        if known is None:
            notes.append(f"{name}: no URDF is known for {model.name}: the 3D view shows its frames, not its links")
            continue
        urdf, tcps = known
        rest = next((model.poses[p] for p in (*REST_POSES, *model.poses) if p in model.poses), {})
        views.append(RobotView(name, model.name, urdf.read_text(encoding="utf-8"), base, prefix, tuple(model.joint_names),
                               {names.group(g): (tcp.frame, tcp.tool) for g, tcp in tcps.items()}, rest, names.prefix))
    return views, notes


def cell_json(name: str, frames: Iterable[CellFrame]) -> dict[str, Any]:
    """The cell's frames in the world, each with its kind, parent and the attributes the view draws
    (a fixture's or tray's ``box``/``box_xyz``, a hole's ``diameter``, a zone's ``size``)."""
    out: list[dict[str, Any]] = []
    for frame in frames:
        if len(out) >= MAX_FRAMES:
            break
        shown = {k: v for k, v in frame.attributes.items() if k in ("box", "box_xyz", "diameter", "size", "element")}
        out.append({"name": frame.name, "kind": frame.kind, "parent": frame.parent, "pose": pose_json(frame.pose), "attributes": shown})
    return {"name": name, "frames": out}


def snapshot_cell(snapshot: CellSnapshot) -> dict[str, Any]:
    return cell_json(snapshot.name, snapshot.frames)


def goal_json(primitive: Any) -> dict[str, Any] | None:
    """Where a primitive takes its group, or None for one that does not move it (a gripper, a look, a dwell)."""
    if isinstance(primitive, MoveCartesian):
        return {"kind": "pose", "target": pose_json(primitive.target), "label": primitive.frame, "interpolation": primitive.interpolation}
    if isinstance(primitive, MoveRelative):
        return {"kind": "relative", "delta": pose_json(primitive.delta), "reference": primitive.reference, "interpolation": primitive.interpolation}
    if isinstance(primitive, (MoveJoints, FullBodyMove)):
        return {"kind": "joints", "names": list(primitive.joint_names), "positions": list(primitive.positions),
                "relative": bool(getattr(primitive, "relative", False))}
    if isinstance(primitive, ExecuteTrajectory):
        points = list(primitive.points)
        if len(points) > MAX_PATH_POINTS:
            step = len(points) / (MAX_PATH_POINTS - 1)
            points = [points[int(k * step)] for k in range(MAX_PATH_POINTS - 1)] + [points[-1]]
        return {"kind": "trajectory", "names": list(primitive.joint_names), "points": [list(p) for p in points], "label": primitive.name}
    if isinstance(primitive, RecordTrajectory) and primitive.waypoints:
        return {"kind": "waypoints", "poses": [pose_json(p) for p in primitive.waypoints[:MAX_PATH_POINTS]], "label": primitive.name}
    return None


@dataclass
class SceneLog:
    """One run's scene: what the route answers.  Written by the run's thread, read by the server's."""

    run: int = -1
    robots: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    cell: dict[str, Any] | None = None
    events: list[dict[str, Any]] = field(default_factory=list)
    dropped: int = 0
    dry_run: dict[str, Any] | None = None  # the refused run's dry run: where it started the robot, when it ended
    joint_names: list[str] = field(default_factory=list)  # a recording's joint states (a live run's are the feed's)
    joint_samples: list[list[float]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def begin(self, run: int, robot: RobotModel | None, cell: dict[str, Any] | None) -> None:
        """A new run (or replay): its robots and cell; no events yet.  A run older than the one shown is ignored
        (the server's idle scene made while the page's run began)."""
        views, notes = robot_views(robot) if robot is not None else ([], [])
        with self.lock:
            if run < self.run:
                return
            self.run, self.robots, self.notes, self.cell, self.events, self.dropped = run, [v.to_json() for v in views], notes, cell, [], 0
            self.joint_names, self.joint_samples, self.dry_run = [], [], None

    def set_cell(self, cell: dict[str, Any]) -> None:
        with self.lock:
            self.cell = cell

    def add(self, event: dict[str, Any]) -> None:
        with self.lock:
            if len(self.events) < MAX_EVENTS:
                self.events.append(event)
            else:
                self.dropped += 1

    def goal(self, t: float, group: str, primitive: Any) -> None:
        """A machine sent its bridge ``primitive`` at run time ``t``: its goal, if it moves the group."""
        goal = goal_json(primitive)
        if goal is not None:  # at the trace's resolution (a microsecond), on the records' time line
            self.add({"t": round(t, 6), "event": "goal", "group": group, "primitive": type(primitive).KIND, **goal})

    def located(self, t: float, group: str, frames: Mapping[str, Pose]) -> None:
        """Every frame ``group`` has located so far (the message is cumulative), measured, in the world."""
        self.add({"t": round(t, 6), "event": "located", "group": group, "frames": {name: pose_json(p) for name, p in list(frames.items())[:MAX_FRAMES]}})

    def read(self, start: int) -> tuple[int, list[dict[str, Any]], int]:
        """The run, its events from ``start`` (at most :data:`MAX_BATCH`), how many there are in all."""
        with self.lock:
            return self.run, self.events[start:start + MAX_BATCH], len(self.events)

    def set_dry_run(self, dry_run: dict[str, Any]) -> None:
        """What the view needs of the dry run that refused this run (:func:`keep_dry_run`)."""
        with self.lock:
            self.dry_run = dry_run

    def set_joints(self, names: list[str], samples: list[list[float]]) -> None:
        """A recording's joint states: rows ``[t, *positions]`` in ``names`` order."""
        with self.lock:
            self.joint_names, self.joint_samples = list(names), samples

    def read_joints(self, start: int) -> tuple[int, list[str], list[list[float]], int]:
        """The run, the joint names, the recorded samples from ``start`` (at most :data:`MAX_BATCH`), how many in all."""
        with self.lock:
            return self.run, list(self.joint_names), self.joint_samples[start:start + MAX_BATCH], len(self.joint_samples)

    def static(self) -> dict[str, Any]:
        """Everything but the events and a recording's joint states: what ``GET /api/scene3d`` answers."""
        with self.lock:
            notes = list(self.notes) + ([f"{self.dropped} later goal(s) and located frames are not shown (more than {MAX_EVENTS})"] if self.dropped else [])
            return {"run": self.run, "robots": list(self.robots), "cell": self.cell, "notes": notes, "recorded_joints": len(self.joint_samples),
                    "dry_run": self.dry_run}


_LOGS: weakref.WeakKeyDictionary[Feed, SceneLog] = weakref.WeakKeyDictionary()
_LOGS_LOCK = threading.Lock()


def scene_log(feed: Feed) -> SceneLog:
    """The scene of the run ``feed`` shows: one per feed, made on first use (the run writes, the server reads)."""
    with _LOGS_LOCK:
        log = _LOGS.get(feed)
        if log is None:
            log = _LOGS[feed] = SceneLog()
        return log


def cell_of_application(app: Application) -> dict[str, Any] | None:
    """An application's cell as the view draws it (None without a cell): the frames and zones its snapshot holds."""
    return snapshot_cell(app.cell.to_snapshot(app.robot)) if app.cell is not None else None


def begin_run(feed: Feed, app: Application) -> None:
    """A run of ``app`` begins on ``feed`` (after :meth:`Feed.begin`): the view shows its robot and cell at once,
    also when the dry run then refuses it and nothing moves."""
    scene_log(feed).begin(feed.snapshot.run, app.robot, cell_of_application(app))


def head_scene(robot_name: str, cell_path: Path | None) -> tuple[RobotModel | None, dict[str, Any] | None, list[str]]:
    """The robot and cell an application's head names (``robot="cell"``: its cell's robots), with what could not
    be read said in one line each -- for a station that has run nothing yet, and a recording that names its file."""
    notes: list[str] = []
    cell = None
    if cell_path is not None:
        cell, problems = read_cell(cell_path, display=cell_path.name)
        if cell is None:
            notes.append(str(problems[0]) if problems else f"{cell_path.name}: the cell cannot be read")
    robot: RobotModel | None = None
    if robot_name == CELL_ROBOT:
        if cell is not None and cell.robots:
            robot = cell_robot_model(cell.name, cell.robots)
    else:
        try:
            robot = find_robot(robot_name)
        except KeyError as error:
            notes.append(str(error.args[0]))
    drawn = cell_json(cell.name, cell.snapshot_parts(robot)["frames"]) if cell is not None else None
    return robot, drawn, notes


def keep_dry_run(feed: Feed, report: DryRunReport, app: Application) -> None:
    """The dry run that refused the run of ``app`` on ``feed``: nothing moved, so there is no joint state to draw; the
    view draws the robot where the run would have started (where the dry run started it: where the robot is) and each
    finding at its moment -- the robot at the finding's joints, the bodies it names, its time (``findings``, from the
    report's data) --, and marks the cell frames the calls of each finding work at (``places``: where the arms would
    meet)."""
    start = report.start
    cell = app.cell
    places: dict[str, list[dict[str, Any]]] = {}
    if cell is not None:
        wanted = {(f.operation, f.group) for f in report.findings}
        for operation in app.operations:
            for group, call in operation.calls.items():
                if (operation.id, group) in wanted:
                    named = [p for p in call.params if isinstance(p, str) and p in cell.frames]
                    places[f"{operation.id}/{group}"] = [{"name": n, "pose": pose_json(cell.pose(n))} for n in named[:8]]
    found = [f for finding in report.findings[:MAX_FINDINGS] if (f := dry_run_finding(finding)) is not None]
    scene_log(feed).set_dry_run({"t_end": report.cycle_time, "joints": dict(zip(start[0], start[1])) if start is not None else {}, "places": places,
                                 "findings": found})
