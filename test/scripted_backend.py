"""A scripted robot back end for machine and engine tests: exact timing, injectable failures.

Every primitive takes a fixed run-time duration (``durations[kind]``, a Dwell its own seconds)
and advances in small steps on the injected clock, so pause really holds mid-primitive and
resume finishes the remaining time.  It honours the bridge port's contract (robot_bridges.backend)
without any kinematics, so tests of the state machine and the engine do not depend on IK.
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MotionResult,
    MoveJoints,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    TrajectoryResult,
    Vision,
    VisionResult,
)
from core_functions.robots import RobotModel
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind, RobotBackend

STEP = 0.01
VISION_OFFSET = 0.001


@dataclass
class Executed:
    group: str
    kind: str
    t_start: float
    primitive: Primitive
    t_end: float | None = None
    outcome: str = "running"


@dataclass
class _Failure:
    kind: FaultKind
    after: float  # fraction of the primitive's duration
    message: str
    while_paused: bool = False
    on: str | None = None  # only a primitive of this KIND (None: the next one, whatever it is)


@dataclass
class _GroupState:
    paused: bool = False
    stopped: bool = False
    busy: bool = False
    resumed: asyncio.Event = field(default_factory=asyncio.Event)


class ScriptedBackend(RobotBackend):
    name = "scripted"

    def __init__(self, clock: Clock, robot: RobotModel, durations: dict[str, float] | None = None) -> None:
        self.clock = clock
        self.robot = robot
        self.durations = {"default": 1.0, **(durations or {})}
        self.joints = {j.name: 0.0 for j in robot.joints}
        self.log: list[Executed] = []
        self._state = {g: _GroupState() for g in robot.group_names}
        self._failures: dict[str, list[_Failure]] = {g: [] for g in robot.group_names}
        self.io: dict[str, dict[str, bool]] = {g: {} for g in robot.group_names}
        self.cell = None

    @property
    def groups(self) -> tuple[str, ...]:
        return self.robot.group_names

    # ------------------------------------------------------------------------ scripting
    def fail_next(
        self, group: str, kind: FaultKind = FaultKind.JOINT_LIMIT, after: float = 0.5, message: str = "injected", *, while_paused: bool = False, on: str | None = None
    ) -> None:
        """Fail the group's next primitive (of KIND ``on``, if given) with ``kind`` at ``after`` x its duration."""
        self._failures[group].append(_Failure(kind, after, message, while_paused, on))

    def _take_failure(self, group: str, primitive: Primitive) -> _Failure | None:
        for index, failure in enumerate(self._failures[group]):
            if failure.on is None or failure.on == primitive.KIND:
                return self._failures[group].pop(index)
        return None

    def duration(self, primitive: Primitive) -> float:
        if isinstance(primitive, Dwell):
            return primitive.seconds
        return self.durations.get(primitive.KIND, self.durations["default"])

    def executed(self, group: str | None = None) -> list[Executed]:
        return [e for e in self.log if group is None or e.group == group]

    # --------------------------------------------------------------------------- port
    def set_cell(self, cell: object) -> None:
        self.cell = cell

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        state = self._state[group]
        if state.busy:
            raise BridgeError(FaultKind.BUSY, f"{group} busy")
        state.busy, state.stopped, state.paused = True, False, False
        entry = Executed(group, primitive.KIND, self.clock.now(), primitive)
        self.log.append(entry)
        try:
            await self._run(group, primitive)
        except BridgeError as error:
            entry.outcome = error.kind.value
            raise
        finally:
            entry.t_end = self.clock.now()
            state.busy = False
        entry.outcome = "done"
        return self._result(group, primitive)

    async def _run(self, group: str, primitive: Primitive) -> None:
        state = self._state[group]
        total = self.duration(primitive)
        failure = self._take_failure(group, primitive)
        elapsed = 0.0
        while elapsed < total or state.paused:
            if state.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{group}: {primitive.KIND} stopped")
            if state.paused:
                if failure is not None and failure.while_paused:
                    raise BridgeError(failure.kind, f"{group}: {failure.message}")
                state.resumed.clear()
                await state.resumed.wait()
                continue
            if failure is not None and not failure.while_paused and elapsed >= failure.after * total:
                raise BridgeError(failure.kind, f"{group}: {failure.message}")
            step = min(STEP, total - elapsed)
            await self.clock.sleep(step)
            elapsed += step
        if failure is not None and not failure.while_paused:
            raise BridgeError(failure.kind, f"{group}: {failure.message}")

    def _result(self, group: str, primitive: Primitive) -> PrimitiveResult:
        if isinstance(primitive, (MoveJoints, FullBodyMove)):
            names = primitive.joint_names or self.robot.group(group).joint_names
            for name, value in zip(names, primitive.positions):
                self.joints[name] = value
        if isinstance(primitive, EndEffector):
            self.io[group][primitive.action] = True
            return EndEffectorResult(dict(self.io[group]))
        if isinstance(primitive, Vision):  # the part is 1 mm off its nominal place along x
            return VisionResult(pose=(primitive.nominal or Pose()).translated(dx=VISION_OFFSET), value=1.0)
        if isinstance(primitive, RecordTrajectory):
            names = self.robot.group(group).joint_names
            return TrajectoryResult(names, (tuple(0.0 for _ in names), tuple(0.1 for _ in names)), (0.0, 1.0))
        if isinstance(primitive, (ExecuteTrajectory, MasterSlaveMove)):
            return MotionResult()
        names = self.robot.group(group).joint_names
        return MotionResult(names, tuple(self.joints[n] for n in names), None)

    async def pause(self, group: str) -> None:
        state = self._state[group]
        if state.busy:
            state.paused = True

    async def resume(self, group: str) -> None:
        state = self._state[group]
        state.paused = False
        state.resumed.set()

    async def stop(self, group: str) -> None:
        state = self._state[group]
        if state.busy:
            state.stopped = True
            state.paused = False
            state.resumed.set()

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        return tuple(self.joints), tuple(self.joints.values())

    def tcp_pose(self, group: str) -> Pose | None:
        return Pose() if self.robot.group(group).kind == "arm" else None
