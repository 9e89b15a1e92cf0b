"""The dry-run back end: a simulator that notes every problem and goes on as if nothing happened.

Wrapped around a robot's simulator, it turns every :class:`BridgeError` of a primitive into a
finding and answers the group machine as if the primitive had succeeded without moving, so the
engine runs the whole application and *every* unreachable target, joint limit and unsupported
action is found in one pass, not just the first.  A replay of a trajectory nobody recorded is
caught by the trajectory store below, which hands the skill a trajectory that stays where the arm
is; its replay is then skipped here.

Nobody guides the arm through a taught trajectory in a dry run, so teaching records the pose the
arm holds: sampled at the start and the end instead of every sample period -- the same
trajectory, the same time, without thousands of identical samples.

A stop is not a finding (the engine stops groups on purpose), and a controller that fails the same
way twice in a row has stopped for good (an RSI stop must be re-armed on the controller): what
follows is answered without the simulator and the report says it was not checked.
"""
from __future__ import annotations

from dataclasses import replace

from cell_runner.dry_run.motions import GripRecord, MotionRecord, planned, straight
from cell_runner.dry_run.recorder import Recorder
from cell_runner.dry_run.report import Span
from core_functions.geometry import Pose
from core_functions.primitives import (
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
    FullBodyMove,
    IoResult,
    MasterSlaveMove,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    SetOutput,
    TrajectoryResult,
    Vision,
    VisionResult,
    WaitInput,
    describe,
)
from core_functions.trajectory_store import StoredTrajectory, TrajectoryStore
from node_transport.wire import CellSnapshot
from robot_bridges.backend import BridgeError, FaultKind, RobotBackend

MISSING_TRAJECTORY = "missing_trajectory"
#: The controller (or the link to it) failed rather than the application: the same one twice in a
#: row means it will not recover within this run.
_CONTROLLER_KINDS = (FaultKind.CONTROLLER, FaultKind.CONNECTION, FaultKind.TIMEOUT, FaultKind.PROTOCOL, FaultKind.INTERNAL)
#: Primitives that move joints: each is kept for the collision sweep (cell_runner/dry_run/collisions.py).
_MOTIONS = (MoveJoints, MoveCartesian, MoveRelative, ExecuteTrajectory, FullBodyMove, MasterSlaveMove)


class DryRunBackend(RobotBackend):
    """Decorates a simulator back end; every problem becomes a finding in ``recorder``."""

    def __init__(self, inner: RobotBackend, recorder: Recorder) -> None:
        self.inner = inner
        self.recorder = recorder
        self.name = inner.name
        self.world_frame = inner.world_frame
        self.stuck: str | None = None  # why the controller is given up on, once it is
        self.stuck_at: str | None = None  # the operation it stopped in
        self._last_controller_error: tuple[str, str | None] | None = None  # (message, operation) of the latest
        self._skip: set[tuple[str, str]] = set()  # (group, trajectory) replays to answer without moving
        self.motions: list[MotionRecord] = []  # every motion that ran, for the collision sweep
        self.grips: list[GripRecord] = []
        self._planned: dict[str, tuple[tuple[str, ...], object, float]] = {}  # group -> (joints, motion, duration)
        if hasattr(inner, "motion_observer"):  # a simulator that shows its planned motions: the exact path
            inner.motion_observer = self._observe
        if hasattr(inner, "collisions"):  # swept afterwards with the whole time line instead (dry_run/collisions.py)
            inner.collisions = None

    def _observe(self, groups: frozenset[str], joints: tuple[str, ...], motion: object, duration: float) -> None:
        for group in groups:
            self._planned[group] = (joints, motion, duration)

    @property
    def groups(self) -> tuple[str, ...]:
        return self.inner.groups

    async def start(self) -> None:
        await self.inner.start()

    async def close(self) -> None:
        await self.inner.close()

    def set_cell(self, cell: CellSnapshot) -> None:
        self.inner.set_cell(cell)

    def robot_description(self) -> str | None:
        return self.inner.robot_description()

    async def pause(self, group: str) -> None:
        await self.inner.pause(group)

    async def resume(self, group: str) -> None:
        await self.inner.resume(group)

    async def stop(self, group: str) -> None:
        await self.inner.stop(group)

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        return self.inner.joint_state()

    def tcp_pose(self, group: str) -> Pose | None:
        try:
            return self.inner.tcp_pose(group)
        except BridgeError:
            return None

    # ----------------------------------------------------------------------------- execute
    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        timing = self.recorder.timing
        what = describe(primitive)
        held = self._held(group, primitive)
        if self.stuck is not None:
            return self.as_if_done(group, primitive)  # not simulated: not on the timeline either
        if isinstance(primitive, ExecuteTrajectory) and (group, primitive.name) in self._skip:
            self._skip.discard((group, primitive.name))
            now = timing.now()
            self.recorder.span(group, held, what, now, now, MISSING_TRAJECTORY)
            return self.as_if_done(group, primitive)
        if isinstance(primitive, RecordTrajectory) and primitive.mode == "teach":
            primitive = replace(primitive, sample_period=primitive.duration)
        if isinstance(primitive, WaitInput):  # a signal the cell drives: the dry run checks its name, not when it comes
            primitive = replace(primitive, timeout=0.0)
        start = timing.now()
        before = self.inner.joint_state() if isinstance(primitive, _MOTIONS) else None
        self._planned.pop(group, None)
        try:
            result = await self.inner.execute(group, primitive)
        except BridgeError as error:
            if error.kind is FaultKind.STOPPED:
                raise  # the engine stopped the group: that is the run going on, not a problem of the application
            if error.kind is FaultKind.TIMEOUT and isinstance(primitive, WaitInput):
                self.recorder.span(group, held, what, start, timing.now())
                return self.as_if_done(group, primitive)
            target = primitive.target if isinstance(primitive, Vision) else ""
            if self.recorder.is_outcome(group, error.kind.value):  # the pass assumed this function's outcome
                self.recorder.outcome_met(group, error.kind.value, target, error.detail)
                self.recorder.span(group, held, what, start, timing.now())
                return self.as_if_done(group, primitive)
            joints = self.inner.joint_state() if before is not None else None  # where the arm stood when it was refused
            pose = primitive.target if isinstance(primitive, MoveCartesian) else None
            if self.recorder.defer(group, held, error.kind.value, what, target, error.detail, start, timing.now(), joints=joints, pose=pose):
                return self.as_if_done(group, primitive)  # on a side of an <if>, maybe the assumption's doing: the nominal pose
            self._note_controller(group, error)
            if self.stuck is None:
                span = self.recorder.span(group, held, what, start, timing.now(), error.kind.value)
                self.recorder.finding(group, error.kind.value, what, error.detail, span.end, joints=joints, target=pose)
            return self.as_if_done(group, primitive)
        span = self.recorder.span(group, held, what, start, timing.now())
        if before is not None:
            self._keep_motion(span, before)
        elif isinstance(primitive, EndEffector) and primitive.action in ("gripper_close", "gripper_open"):
            self.grips.append(GripRecord(group, span.operation, span.function, span.end, primitive.action == "gripper_close"))
        return result

    def _keep_motion(self, span: Span, before: tuple[tuple[str, ...], tuple[float, ...]]) -> None:
        plan = self._planned.pop(span.group, None)
        if plan is not None:
            joints, motion, duration = plan
            sampler = planned(motion, duration)
            span = replace(span, end=span.start + duration)
        else:
            names, after = self.inner.joint_state()
            moved = [k for k, (a, b) in enumerate(zip(before[1], after)) if a != b]
            if not moved:
                return
            joints = tuple(names[k] for k in moved)
            sampler = straight([before[1][k] for k in moved], [after[k] for k in moved], span.duration)
        self.motions.append(MotionRecord(span, joints, sampler))

    def _note_controller(self, group: str, error: BridgeError) -> None:
        """Give the controller up when it fails twice in a row with the same controller fault."""
        if error.kind not in _CONTROLLER_KINDS:
            self._last_controller_error = None
            return
        located = self.recorder.locate(group)
        last = self._last_controller_error
        if last is not None and last[0] == error.detail:
            self.stuck_at = last[1]
            self.stuck = f"the simulated controller stopped for good in operation {last[1]}; nothing after it was checked"
        self._last_controller_error = (error.detail, located[0] if located else None)

    def _held(self, group: str, primitive: Primitive) -> tuple[str, ...]:
        """The groups a primitive occupies: all whose joints a full-body move names, both arms of a master/slave move."""
        if isinstance(primitive, FullBodyMove):
            names = set(primitive.joint_names)
            return tuple(g.name for g in self.recorder.robot.groups if names & set(g.joint_names)) or (group,)
        if isinstance(primitive, MasterSlaveMove):
            return (primitive.master, primitive.slave)
        return (group,)

    # --------------------------------------------------------------------------- as if done
    def group_joints(self, group: str) -> tuple[tuple[str, ...], tuple[float, ...]]:
        """The group's joint names and where they are now."""
        names = self.recorder.robot.group(group).joint_names
        all_names, positions = self.inner.joint_state()
        where = dict(zip(all_names, positions))
        return names, tuple(float(where.get(n, 0.0)) for n in names)

    def as_if_done(self, group: str, primitive: Primitive) -> PrimitiveResult:
        """What the primitive would have answered had it succeeded without moving."""
        result_type = primitive.RESULT
        if result_type is EndEffectorResult:
            return EndEffectorResult()
        if isinstance(primitive, (SetOutput, WaitInput)):
            return IoResult({primitive.name: primitive.value})
        if result_type is VisionResult:
            nominal = primitive.nominal if isinstance(primitive, Vision) else None
            return VisionResult(pose=nominal, value=0.0)
        names, positions = self.group_joints(group)
        if result_type is TrajectoryResult:
            return TrajectoryResult(names, (positions,), (0.0,))
        return MotionResult(names, positions, self.tcp_pose(group))

    def missing_trajectory(self, group: str, name: str, recorded: list[str]) -> TrajectoryResult:
        """A skill replays ``name``, never recorded for ``group``: a finding, and a trajectory that stays put."""
        known = ", ".join(recorded) or "none"
        message = f"trajectory {name!r} is replayed but was never recorded for {group} (recorded by then: {known})"
        self.recorder.finding(group, MISSING_TRAJECTORY, f"execute_trajectory({name})", message)
        self._skip.add((group, name))
        names, positions = self.group_joints(group)
        return TrajectoryResult(names, (positions,), (0.0,))


class DryRunTrajectoryStore(TrajectoryStore):
    """The groups' shared throw-away store: a replay of a name nobody recorded is a finding, not a failure."""

    def __init__(self, path: str, backend: DryRunBackend) -> None:
        super().__init__(path)
        self.backend = backend

    def load(self, group: str, name: str) -> StoredTrajectory:
        try:
            return super().load(group, name)
        except KeyError:
            placeholder = self.backend.missing_trajectory(group, name, self.names(group))
            return StoredTrajectory(group, name, placeholder, "missing", 0.0)
