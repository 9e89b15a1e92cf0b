"""The Nextage Open kinematic simulator as a :class:`RobotBackend`.

Groups ``left_arm``, ``right_arm`` and ``torso_head``; world frame ``WAIST``.  Every primitive of
:mod:`core_functions.primitives` is executed the way the real robot would: planned completely
first (IK, limits, continuity -- so a bad request fails before anything moves), then played on
the injected :class:`~execution_engine.clock.Clock`, one control period at a time, so that
``joint_state()`` and ``tcp_pose()`` show the motion in progress and the simulation runs at real
time, 10x, or in virtual time purely by the choice of clock.

A running primitive is a *job* holding one group, or several (FullBodyMove: all three;
MasterSlaveMove: both arms).  ``pause`` freezes the job's own clock (the arm holds where it is),
``resume`` continues the very same planned motion to its original target, ``stop`` abandons it
and its ``execute`` raises ``BridgeError(STOPPED)``.  Faults can be injected per group
(:mod:`robot_bridges.nextage_sim.faults`) to exercise error handling.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np

from core_functions.geometry import Pose
from core_functions.linear_path import LineTolerance
from core_functions import option_ranges
from core_functions.primitives import (
    Dwell,
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    SetSpeed,
    TrajectoryResult,
    Vision,
    VisionResult,
    describe,
)
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.clock import Clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind, RobotBackend
from robot_bridges.camera.sources import RenderedCamera
from robot_bridges.camera.spec import parse_mount
from robot_bridges.camera.vision import CameraVision
from robot_bridges.collision import CollisionScene, cell_boxes, held_part, scene_for
from robot_bridges.nextage_sim import vision
from robot_bridges.nextage_sim.faults import FaultPlan, FaultSpec, parse_fault
from robot_bridges.nextage_sim.hands import HandIO
from robot_bridges.nextage_sim.model import WORLD_FRAME, ArmKinematics, NextageModel, describe_target
from robot_bridges.nextage_sim.trajectory import (
    CartesianLimits,
    Chain,
    LinearLeg,
    Motion,
    plan_joint_move,
    plan_linear,
    plan_replay,
    plan_straight,
    sample,
    straight_leg,
)

if TYPE_CHECKING:
    from execution_engine.transport.wire import CellSnapshot

GROUPS: tuple[str, ...] = ("left_arm", "right_arm", "torso_head")
_DONE = 1e-9  # s: a motion this close to a mark has reached it


class _Job:
    """One primitive in execution and the groups it holds; pause/resume/stop act on it."""

    def __init__(self, groups: frozenset[str], primitive: Primitive, loop: asyncio.AbstractEventLoop) -> None:
        self.groups = groups
        self.primitive = primitive
        self.paused_by: set[str] = set()
        self.stopped = False
        self.wake = asyncio.Event()
        self.finished: asyncio.Future[None] = loop.create_future()
        self.error: BaseException | None = None
        self.progress = 0.0  # s of the primitive's own time elapsed (pauses excluded)
        self.horizon = 0.0  # the next instant the runner must act at (end, fault, sample)
        self.duration = 0.0
        self.tick: Callable[[float], None] = lambda t: None
        self.teaching = False
        self._last = 0.0

    @property
    def paused(self) -> bool:
        return bool(self.paused_by)

    def restart(self, now: float) -> None:
        self.progress = 0.0
        self._last = now

    def advance(self, now: float) -> None:
        """Count the time since the last call unless paused, never past the horizon."""
        if not self.paused:
            self.progress = min(self.progress + (now - self._last), self.horizon)
        self._last = now


class NextageSimBackend(RobotBackend):
    """Kinematic simulation of a Kawada Nextage Open (15 joints, two 6-DOF arms, torso, head)."""

    name = "nextage_sim"
    world_frame = WORLD_FRAME

    def __init__(
        self,
        clock: Clock,
        initial_pose: str = "initial",
        control_period: float = 0.01,
        seed: int = 0,
        *,
        tools: Mapping[str, Pose] | None = None,
        cartesian_limits: CartesianLimits | None = None,
        faults: Iterable[FaultSpec] = (),
        model: NextageModel | None = None,
        camera_mounts: Mapping[str, Pose] | None = None,
        check_collisions: bool = False,
    ) -> None:
        control_period = option_ranges.check("control_period", control_period)
        self.clock = clock
        self.control_period = float(control_period)
        self.model = model or NextageModel()
        self.cartesian_limits = cartesian_limits or CartesianLimits()
        #: Told of every motion as it starts: (groups, joint names, motion with ``at(t)``, duration).
        self.motion_observer: Callable[[frozenset[str], tuple[str, ...], Any, float], None] | None = None
        #: The collision model checked every control period (None: not checked; the dry run sweeps instead).
        #: ``run`` turns it on (the ``collision_check`` option); a bare simulator for kinematics tests has it off.
        self.collisions: CollisionScene | None = scene_for(NEXTAGE_OPEN) if check_collisions else None
        self._cell: CellSnapshot | None = None
        self._work: dict[str, tuple[Pose, ...]] = {}  # arm -> where its current motion starts and ends
        self._q = self.model.named_pose(initial_pose)
        self._speed = dict.fromkeys(GROUPS, 1.0)
        self._jobs: dict[str, _Job] = {}
        self._hands = {g: HandIO() for g in self.model.arms}
        self._vision = vision.SimulatedVision(seed)
        #: This robot's cameras: the simulator's, with the hand-eye mounts given instead of the defaults.
        self.camera_specs = vision.cameras_with(camera_mounts or {})
        #: The cameras: images rendered from the cell, detected and placed in the world (robot_bridges.camera).
        real = {n: c for n, c in self.camera_specs.items() if n not in vision.STEREO}
        self.cameras = CameraVision(RenderedCamera(lambda: self.cameras.scene(), seed, clock.now), self._vision.fallback, real)
        self._faults = FaultPlan()
        for spec in faults:
            self.inject(spec)
        for group, tool in (tools or {}).items():
            self.set_tool(group, tool)
        self._handlers: dict[type, Callable[[str, Any], Any]] = {
            MoveJoints: self._move_joints,
            MoveCartesian: self._move_cartesian,
            MoveRelative: self._move_relative,
            SetSpeed: self._set_speed,
            Dwell: self._dwell,
            EndEffector: self._end_effector,
            Vision: self._look,
            RecordTrajectory: self._record,
            ExecuteTrajectory: self._execute_trajectory,
            FullBodyMove: self._full_body,
            MasterSlaveMove: self._master_slave,
        }

    # ------------------------------------------------------------------------ the port
    @property
    def groups(self) -> tuple[str, ...]:
        return GROUPS

    async def close(self) -> None:
        jobs = {id(j): j for j in self._jobs.values()}.values()
        for job in jobs:
            job.stopped = True
            job.wake.set()
        await asyncio.gather(*(asyncio.shield(j.finished) for j in jobs), return_exceptions=True)

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self._check_group(group)
        handler = self._handlers.get(type(primitive))
        if handler is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name} cannot execute {type(primitive).__name__}")
        result: PrimitiveResult = await handler(group, primitive)
        return result

    async def pause(self, group: str) -> None:
        self._check_group(group)
        job = self._jobs.get(group)
        if job is None or job.stopped:
            return
        job.advance(self.clock.now())
        job.paused_by.add(group)
        job.tick(job.progress)  # hold exactly where the motion is now

    async def resume(self, group: str) -> None:
        self._check_group(group)
        job = self._jobs.get(group)
        if job is None or group not in job.paused_by:
            return
        job.advance(self.clock.now())
        job.paused_by.discard(group)
        job.wake.set()

    async def stop(self, group: str) -> None:
        self._check_group(group)
        job = self._jobs.get(group)
        if job is None:
            return
        job.stopped = True
        job.wake.set()
        await asyncio.shield(job.finished)

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names = NEXTAGE_OPEN.joint_names
        return names, tuple(float(self._q[self.model.index(n)]) for n in names)

    def tcp_pose(self, group: str) -> Pose | None:
        self._check_group(group)
        arm = self.model.arms.get(group)
        return None if arm is None else arm.tcp_pose(self._q)

    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell
        if self.collisions is not None:
            self.collisions.set_cell(cell_boxes(cell))
        self._vision.set_cell(cell)
        self.cameras.set_cell(cell)

    def robot_description(self) -> str | None:
        return self.model.urdf_path.read_text(encoding="utf-8")

    # ----------------------------------------------------------------- simulator extras
    def set_tool(self, group: str, tool: Pose) -> None:
        """Make the arm's TCP ``tool`` (a pose in ``*ARM_JOINT5_Link``) instead of the flange."""
        self._arm(group).tool = tool
        if self.collisions is not None:
            self.collisions.set_tool(group, tool)

    def inject(self, spec: FaultSpec) -> None:
        """Queue ``spec``; the group's next primitive it applies to fails with it."""
        self._check_group(spec.group)
        self._faults.add(spec)

    def inject_fault(self, group: str, kind: FaultKind, after: float | None = None) -> None:
        """Shorthand for :meth:`inject`: ``after`` defaults to 0 for UNREACHABLE, 0.5 otherwise."""
        if after is None:
            after = 0.0 if kind is FaultKind.UNREACHABLE else 0.5
        self.inject(FaultSpec(group, kind, after))

    @property
    def pending_faults(self) -> tuple[FaultSpec, ...]:
        return self._faults.pending

    def speed(self, group: str) -> float:
        self._check_group(group)
        return self._speed[group]

    def hand_io(self, group: str) -> dict[str, bool]:
        return self._hand(group).snapshot()

    def guide(self, group: str, positions: Sequence[float]) -> None:
        """Move the group's joints by hand while it is teaching (lead-through programming)."""
        job = self._jobs.get(group)
        if job is None or not job.teaching:
            raise ValueError(f"{group} is not teaching a trajectory; it can only be guided while it is")
        idx = self._group_indices(group)
        if len(positions) != len(idx):
            raise ValueError(f"{group} has {len(idx)} joints, got {len(positions)} positions")
        values = np.array(positions, dtype=float)
        problem = self._violation(idx, values)
        if problem:
            raise ValueError(f"{group} cannot be guided there: {problem}")
        self._q[idx] = values

    # --------------------------------------------------------------------- primitives
    async def _set_speed(self, group: str, primitive: SetSpeed) -> MotionResult:
        with self._job(frozenset({group}), primitive):
            self._speed[group] = primitive.fraction
        return self._result(group)

    async def _move_joints(self, group: str, primitive: MoveJoints) -> MotionResult:
        spec = NEXTAGE_OPEN.group(group)
        names = primitive.joint_names or spec.joint_names
        foreign = [n for n in names if n not in spec.joint_names]
        if foreign:
            raise BridgeError(
                FaultKind.UNSUPPORTED, f"{group}: {', '.join(foreign)} not among its joints {', '.join(spec.joint_names)}"
            )
        if len(primitive.positions) != len(names):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group}: {len(names)} joint positions needed, got {len(primitive.positions)}")
        idx = self.model.indices(names)
        goal = np.array(primitive.positions, dtype=float)
        if primitive.relative:
            goal = goal + self._q[idx]
        self._require_within_limits(group, idx, goal, "target")
        with self._job(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group)
            motion = plan_joint_move(idx, self._q[idx], goal, *self._limits(idx), self._job_speed(job))
            await self._play(job, motion, fault)
        return self._result(group)

    async def _move_cartesian(self, group: str, primitive: MoveCartesian) -> MotionResult:
        return await self._cartesian(group, primitive, lambda current: primitive.target, primitive.interpolation)

    async def _move_relative(self, group: str, primitive: MoveRelative) -> MotionResult:
        return await self._cartesian(group, primitive, primitive.goal, primitive.interpolation)

    async def _cartesian(
        self, group: str, primitive: MoveCartesian | MoveRelative, target_of: Callable[[Pose], Pose], interpolation: str
    ) -> MotionResult:
        arm = self._arm(group)
        with self._job(frozenset({group}), primitive) as job:
            start = arm.tcp_pose(self._q)
            target = target_of(start)
            fault = self._take_fault(job, group, target)
            speed = self._job_speed(job)
            velocity, acceleration = self._limits(arm.indices)
            motion: Motion
            if interpolation == "linear":
                leg = straight_leg(group, self._q[arm.indices], start, target, self._solver(arm), arm.joint_names)
                limits = self.cartesian_limits
                motion = plan_straight(arm.indices, leg, self._forward(arm), velocity, acceleration, limits, limits.tolerance, speed)
            else:
                solution = arm.solve(target, self._q)
                motion = plan_joint_move(arm.indices, self._q[arm.indices], solution.positions, velocity, acceleration, speed)
            await self._play(job, motion, fault)
        return self._result(group)

    async def _dwell(self, group: str, primitive: Dwell) -> MotionResult:
        with self._job(frozenset({group}), primitive) as job:
            await self._run(job, primitive.seconds, lambda t: None)
        return self._result(group)

    async def _end_effector(self, group: str, primitive: EndEffector) -> EndEffectorResult:
        hand = self._hand(group)
        with self._job(frozenset({group}), primitive) as job:
            action = hand.apply(primitive.action)  # the output switches now; the hardware takes a moment
            await self._run(job, action.duration, lambda t: None)
        if self.collisions is not None and primitive.action in ("gripper_close", "gripper_open"):
            tcp = self._arm(group).tcp_pose(self._q)
            closed = primitive.action == "gripper_close" and self._cell is not None
            self.collisions.set_held(group, held_part(self._cell, tcp) if closed and self._cell is not None else None)
        return EndEffectorResult(io=hand.snapshot())

    async def _look(self, group: str, primitive: Vision) -> VisionResult:
        cameras = vision.taking_part(primitive.camera or NEXTAGE_OPEN.group(group).camera, self.camera_specs)
        with self._job(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group)
            # The images are taken now, with the cameras where the kinematics put them now.
            placed = [(cam, Pose.from_matrix(self.model.frame_matrix(self._q, cam.link) @ cam.mount.matrix())) for cam in cameras]
            observation: VisionResult | BridgeError
            try:
                self._check_range(primitive, placed)
                observation = await self.cameras.observe(primitive, placed)
            except BridgeError as error:
                observation = error
            await self._run(job, vision.VISION_TIME, lambda t: None, fault)
        if isinstance(observation, BridgeError):
            raise observation
        return observation

    def _check_range(self, primitive: Vision, placed: Sequence[tuple[vision.CameraSpec, Pose]]) -> None:
        """A feature beyond a camera's working range is not seen (VISION naming distance and range)."""
        nominal = primitive.nominal or self._vision.frame_pose(primitive.target)
        if nominal is None:
            return
        for cam, pose in placed:
            distance = pose.distance_to(nominal)
            if distance > cam.max_range:
                raise BridgeError(
                    FaultKind.VISION,
                    f"{primitive.target or 'the feature'} is {distance:.3f} m from {cam.name}, beyond its {cam.max_range:.2f} m working range",
                )

    async def _record(self, group: str, primitive: RecordTrajectory) -> TrajectoryResult:
        if primitive.mode == "teach":
            return await self._teach(group, primitive)
        arm = self._arm(group)
        with self._job(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group, primitive.waypoints[0])
            if fault is not None and fault.kind is FaultKind.UNREACHABLE:
                raise self._fault_error(job, fault, primitive.waypoints[0])
            segments: list[Motion] = []
            pose = arm.tcp_pose(self._q)
            current = self._q[arm.indices]
            velocity, acceleration = self._limits(arm.indices)
            tolerance = LineTolerance(primitive.tolerance, primitive.angle_tolerance)
            for waypoint in primitive.waypoints:
                if primitive.interpolation == "linear":
                    leg = straight_leg(group, current, pose, waypoint, self._solver(arm), arm.joint_names)
                    segments.append(
                        plan_straight(arm.indices, leg, self._forward(arm), velocity, acceleration, self.cartesian_limits, tolerance, 1.0)
                    )
                else:
                    base = self._q.copy()
                    base[arm.indices] = current
                    goal = arm.solve(waypoint, base).positions
                    segments.append(plan_joint_move(arm.indices, current, goal, velocity, acceleration, 1.0))
                current, pose = segments[-1].end, waypoint
            times, points = sample(Chain(segments), primitive.sample_period)
        return TrajectoryResult(arm.joint_names, tuple(tuple(map(float, p)) for p in points), tuple(map(float, times)))

    async def _teach(self, group: str, primitive: RecordTrajectory) -> TrajectoryResult:
        idx = self._group_indices(group)
        period = primitive.sample_period
        count = max(1, math.ceil(primitive.duration / period - 1e-9))
        marks = [min(k * period, primitive.duration) for k in range(count + 1)]
        times: list[float] = []
        points: list[tuple[float, ...]] = []

        def tick(t: float) -> None:
            while len(times) < len(marks) and t >= marks[len(times)] - _DONE:
                times.append(marks[len(times)])
                points.append(tuple(float(v) for v in self._q[idx]))

        with self._job(frozenset({group}), primitive) as job:
            job.teaching = True
            await self._run(job, primitive.duration, tick, marks=marks)
        return TrajectoryResult(NEXTAGE_OPEN.group(group).joint_names, tuple(points), tuple(times))

    async def _execute_trajectory(self, group: str, primitive: ExecuteTrajectory) -> MotionResult:
        spec = NEXTAGE_OPEN.group(group)
        foreign = [n for n in primitive.joint_names if n not in spec.joint_names]
        if foreign or not primitive.joint_names:
            raise BridgeError(
                FaultKind.UNSUPPORTED,
                f"{group}: trajectory {primitive.name!r} names joints {', '.join(foreign) or '(none)'} "
                f"outside {', '.join(spec.joint_names)}",
            )
        idx = self.model.indices(primitive.joint_names)
        points = np.array(primitive.points, dtype=float)
        for k, point in enumerate(points):
            self._require_within_limits(group, idx, point, f"point {k} of trajectory {primitive.name!r}")
        with self._job(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group)
            motion = plan_replay(
                idx, primitive.joint_names, self._q[idx], np.array(primitive.times, dtype=float), points,
                *self._limits(idx), self._job_speed(job),
            )
            await self._play(job, motion, fault)
        return self._result(group)

    async def _full_body(self, group: str, primitive: FullBodyMove) -> MotionResult:
        unknown = [n for n in primitive.joint_names if n not in NEXTAGE_OPEN.joint_names]
        if unknown:
            raise BridgeError(FaultKind.UNSUPPORTED, f"full-body move names unknown joints: {', '.join(unknown)}")
        joined = await self._join(group, primitive)
        if not joined:
            idx = self.model.indices(primitive.joint_names)
            goal = np.array(primitive.positions, dtype=float)
            self._require_within_limits(group, idx, goal, "full-body target")
            with self._job(frozenset(GROUPS), primitive) as job:
                fault = self._take_fault(job, group)
                motion = plan_joint_move(idx, self._q[idx], goal, *self._limits(idx), self._job_speed(job))
                await self._play(job, motion, fault)
        names, positions = self.joint_state()
        return MotionResult(names, positions, self.tcp_pose(group))

    async def _master_slave(self, group: str, primitive: MasterSlaveMove) -> MotionResult:
        pair = (primitive.master, primitive.slave)
        for g in pair:
            self._arm(g)
        if group not in pair:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group} is neither master nor slave of this master/slave move {pair}")
        if not primitive.master_path:
            raise BridgeError(
                FaultKind.UNSUPPORTED,
                f"{group}: master/slave move without a master path (only the master's copy, with the path, is executed)",
            )
        if not await self._join(group, primitive):
            with self._job(frozenset(pair), primitive) as job:
                fault = self._take_fault(job, group, primitive.master_path[0])
                motion = self._plan_master_slave(primitive, self._job_speed(job))
                await self._play(job, motion, fault)
        return self._result(group)

    def _plan_master_slave(self, primitive: MasterSlaveMove, speed: float) -> Motion:
        """Both TCPs along straight segments, the slave rigidly at ``offset`` from the master.

        Without an explicit offset the TCPs keep the one they have at the start (a part held by
        both hands stays held).  If the slave does not hold the offset at the start, its first
        segment is its own straight line onto ``slave_path[0]``; from then on it follows
        ``master * offset``.
        """
        master, slave = self._arm(primitive.master), self._arm(primitive.slave)
        indices = np.concatenate([master.indices, slave.indices])
        velocity, acceleration = self._limits(indices)
        m_pose, s_pose = master.tcp_pose(self._q), slave.tcp_pose(self._q)
        offset = primitive.offset or m_pose.inverse().compose(s_pose)
        m_q, s_q = self._q[master.indices], self._q[slave.indices]
        rigid = s_pose.distance_to(m_pose.compose(offset)) < 1e-3 and s_pose.angle_to(m_pose.compose(offset)) < math.radians(0.5)
        lever = float(np.linalg.norm(offset.position))
        segments: list[Motion] = []
        for k, (m_target, s_target) in enumerate(zip(primitive.master_path, primitive.slave_path(offset))):
            m_leg = straight_leg(primitive.master, m_q, m_pose, m_target, self._solver(master), master.joint_names)
            if rigid or k > 0:
                s_leg = LinearLeg(
                    primitive.slave, s_q, lambda s, leg=m_leg: leg.pose_at(s).compose(offset), self._solver(slave),
                    slave.joint_names, m_leg.length + lever * m_leg.angle, m_leg.angle,
                )
            else:
                s_leg = straight_leg(primitive.slave, s_q, s_pose, s_target, self._solver(slave), slave.joint_names)
            segment = plan_linear(indices, [m_leg, s_leg], velocity, acceleration, self.cartesian_limits, speed)
            segments.append(segment)
            m_q, s_q = segment.end[:6], segment.end[6:]
            m_pose, s_pose = m_target, s_target
        return Chain(segments)

    # ------------------------------------------------------------------- the runner
    async def _play(self, job: _Job, motion: Motion, fault: FaultSpec | None) -> None:
        """Drive the joints along ``motion`` on the clock, checking limits every period."""
        group = sorted(job.groups)[0]
        if self.motion_observer is not None:  # the dry run keeps the exact path for its collision sweep
            self.motion_observer(job.groups, tuple(self.model.joint_names[int(i)] for i in motion.indices), motion, motion.duration)

        self._note_work(job.groups, motion)

        def tick(t: float) -> None:
            positions = motion.at(t)
            problem = self._violation(motion.indices, positions)
            if problem:
                raise BridgeError(FaultKind.JOINT_LIMIT, f"{group}: {describe(job.primitive)} at t = {t:.3f} s: {problem}")
            self._q[motion.indices] = positions
            self._check_collisions(job, t)

        await self._run(job, motion.duration, tick, fault)

    async def _run(
        self,
        job: _Job,
        duration: float,
        tick: Callable[[float], None],
        fault: FaultSpec | None = None,
        marks: Sequence[float] = (),
    ) -> None:
        """Advance the job's own time over ``[0, duration]`` every control period.

        ``tick(t)`` applies the state at job time ``t``; it runs at every period, at every mark,
        when a pause starts (so the hold is exact) and at the end.  A stop, an injected fault at
        its fraction of ``duration`` or an error out of ``tick`` ends the run by raising.
        """
        clock = self.clock
        fail_at = None if fault is None else fault.after * duration
        stops = sorted({*(m for m in marks if 0.0 < m < duration), *([fail_at] if fail_at is not None else []), duration})
        job.duration = duration
        job.tick = tick
        job.restart(clock.now())
        job.horizon = stops[0]
        tick(0.0)
        while True:
            if job.stopped:
                raise BridgeError(
                    FaultKind.STOPPED,
                    f"{', '.join(sorted(job.groups))}: {describe(job.primitive)} stopped after {job.progress:.3f} of {duration:.3f} s",
                )
            if job.progress >= job.horizon - _DONE:
                tick(job.horizon)
                if fault is not None and job.horizon >= fault.after * duration - _DONE:
                    raise self._fault_error(job, fault)
                if job.horizon >= duration - _DONE:
                    return
                job.horizon = next(s for s in stops if s > job.horizon + _DONE)
                continue
            if job.paused:
                job.wake.clear()
                await job.wake.wait()
                job.advance(clock.now())
                continue
            tick(job.progress)
            await clock.sleep(min(self.control_period, job.horizon - job.progress))
            job.advance(clock.now())

    def _note_work(self, groups: frozenset[str], motion: Motion) -> None:
        """Where each arm of a motion starts and ends: the work its hand may touch (robot_bridges/collision)."""
        end = self._q.copy()
        end[motion.indices] = motion.end
        for g in groups:
            arm = self.model.arms.get(g)
            if arm is not None:
                self._work[g] = (arm.tcp_pose(self._q), arm.tcp_pose(end))

    def _check_collisions(self, job: _Job, t: float) -> None:
        """Stop the motion when two bodies touch (a vision-corrected target the dry run never saw, say)."""
        if self.collisions is None:
            return
        hits = [c for c in self.collisions.contacts(self._q, self._work) if c.collision]
        if hits:
            worst = min(hits, key=lambda c: c.distance)
            raise BridgeError(
                FaultKind.COLLISION,
                f"{', '.join(sorted(job.groups))}: {describe(job.primitive)} at t = {t:.3f} s: {worst.describe(self.collisions.margin)}",
            )

    # -------------------------------------------------------------------- job control
    @contextmanager
    def _job(self, groups: frozenset[str], primitive: Primitive) -> Iterator[_Job]:
        """Hold ``groups`` for ``primitive`` (BUSY if any is held), release them afterwards."""
        busy = sorted(g for g in groups if g in self._jobs)
        if busy:
            running = self._jobs[busy[0]].primitive
            raise BridgeError(FaultKind.BUSY, f"{', '.join(busy)} already executing {describe(running)}")
        job = _Job(groups, primitive, asyncio.get_running_loop())
        for g in groups:
            self._jobs[g] = job
        try:
            yield job
        except BaseException as error:
            job.error = error
            raise
        finally:
            for g in groups:
                if self._jobs.get(g) is job:
                    del self._jobs[g]
            if not job.finished.done():
                job.finished.set_result(None)

    async def _join(self, group: str, primitive: Primitive) -> bool:
        """If ``group`` is already held by this very multi-group primitive, wait for it instead.

        Both arms' machines may send the same FullBodyMove / MasterSlaveMove; the first starts
        it, the second rides along and gets the same outcome.
        """
        job = self._jobs.get(group)
        if job is None or job.primitive != primitive:
            return False
        await asyncio.shield(job.finished)
        if isinstance(job.error, BridgeError):
            raise BridgeError(job.error.kind, job.error.detail)
        if job.error is not None:
            raise BridgeError(FaultKind.INTERNAL, f"{describe(primitive)} failed: {job.error!r}")
        return True

    def _take_fault(self, job: _Job, group: str, target: Pose | None = None) -> FaultSpec | None:
        """The injected fault for this job, raised at once when it strikes before any motion."""
        fault = self._faults.take(job.groups, job.primitive)
        if fault is not None and fault.after <= 0.0:
            raise self._fault_error(job, fault, target)
        return fault

    def _fault_error(self, job: _Job, fault: FaultSpec, target: Pose | None = None) -> BridgeError:
        share = 0.0 if job.duration <= 0 else 100.0 * job.progress / job.duration
        where = f"{share:.0f}% into {describe(job.primitive)}"
        if fault.kind is FaultKind.UNREACHABLE:
            what = f"no IK solution for TCP target {describe_target(target)}" if target is not None else "IK failed"
            return BridgeError(FaultKind.UNREACHABLE, f"{fault.group}: {what} ({where}; injected fault)")
        if fault.kind is FaultKind.JOINT_LIMIT:
            idx = self._group_indices(fault.group)
            name = self.model.joint_names[int(idx[0])]
            value = float(self._q[idx[0]])
            return BridgeError(
                FaultKind.JOINT_LIMIT,
                f"{fault.group}: {name} at {value:.4f} rad ({math.degrees(value):.2f} deg) tripped its limit switch "
                f"({where}; injected fault)",
            )
        return BridgeError(fault.kind, f"{fault.group}: {fault.kind.value} fault ({where}; injected fault)")

    # ----------------------------------------------------------------------- helpers
    def _check_group(self, group: str) -> None:
        if group not in GROUPS:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name} has no group {group!r} (groups: {', '.join(GROUPS)})")

    def _arm(self, group: str) -> ArmKinematics:
        self._check_group(group)
        arm = self.model.arms.get(group)
        if arm is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group} has no TCP: Cartesian primitives need left_arm or right_arm")
        return arm

    def _hand(self, group: str) -> HandIO:
        self._check_group(group)
        hand = self._hands.get(group)
        if hand is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group} has no hand: end-effector actions need left_arm or right_arm")
        return hand

    def _group_indices(self, group: str) -> np.ndarray:
        return self.model.indices(NEXTAGE_OPEN.group(group).joint_names)

    def _limits(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.model.velocity[idx], self.model.acceleration[idx]

    def _job_speed(self, job: _Job) -> float:
        """A job over several groups moves at the slowest of their speeds."""
        return min(self._speed[g] for g in job.groups)

    def _violation(self, idx: np.ndarray, values: np.ndarray) -> str | None:
        probe = self._q.copy()
        probe[idx] = values
        return self.model.limit_violation(probe, idx, tolerance=1e-7)

    def _require_within_limits(self, group: str, idx: np.ndarray, values: np.ndarray, what: str) -> None:
        problem = self._violation(idx, values)
        if problem:
            raise BridgeError(FaultKind.JOINT_LIMIT, f"{group}: {what}: {problem}")

    def _solver(self, arm: ArmKinematics) -> Callable[[Pose, np.ndarray], np.ndarray]:
        """IK along a path: warm-started from the previous sample, no restarts (no branch hopping)."""
        base = self._q.copy()

        def solve(target: Pose, seed: np.ndarray) -> np.ndarray:
            base[arm.indices] = seed
            return arm.solve(target, base, restarts=False).positions

        return solve

    def _forward(self, arm: ArmKinematics) -> Callable[[np.ndarray], Pose]:
        """The TCP pose for the arm's joints, the rest of the robot as it is now (the line's frame)."""
        base = self._q.copy()

        def forward(q_arm: np.ndarray) -> Pose:
            base[arm.indices] = q_arm
            return arm.tcp_pose(base)

        return forward

    def _result(self, group: str) -> MotionResult:
        names = NEXTAGE_OPEN.group(group).joint_names
        return MotionResult(names, tuple(float(self._q[self.model.index(n)]) for n in names), self.tcp_pose(group))


#: The default TCP: at the wrist flange (origin of ``*ARM_JOINT5_Link``), z pointing out of the hand
#: (the flange's -x, the wrist roll axis), so a frame whose z points into a hole is approached along
#: +z by the tool -- the convention of the cell models and skills.
HAND_TOOL = Pose.from_xyz_rpy(0.0, 0.0, 0.0, 0.0, -math.pi / 2, 0.0)
#: ``<camera>_mount``: a camera's hand-eye calibration, its optical frame in its link (x y z roll pitch yaw; m, rad).
_EXTRAS = ("initial_pose", "control_period", "tool", "collision_check", *(f"{name}_mount" for name in vision.REAL_CAMERAS))


def parse_tool(text: str) -> Pose:
    """``"x y z roll pitch yaw"`` (m, rad) in the flange frame, or ``flange`` for the bare flange."""
    if text.strip() == "flange":
        return Pose()
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"nextage-sim: tool must be 'flange' or six numbers x y z roll pitch yaw (m, rad), got {text!r}")
    return Pose.from_xyz_rpy(*values)


async def create(clock: Clock, options: BackendOptions) -> NextageSimBackend:
    """Registry factory (``nextage-sim``): the simulator from CLI / launch options.

    Understands ``faults``, ``seed`` and the extras ``initial_pose``, ``control_period``,
    ``tool`` (the TCP in the flange frame; default :data:`HAND_TOOL`), ``collision_check`` (``on``, the
    default: two bodies touching stop the motion with a ``collision`` fault; ``off``) and ``<camera>_mount`` (a
    camera's hand-eye calibration, six numbers x y z roll pitch yaw in its link); a controller address makes
    no sense for a simulator and is refused rather than ignored.  ``control_period`` lies in its range
    (core_functions.option_ranges: [0.001, 0.5] s): a longer step would let a motion pass a joint limit or a
    collision between two checks.
    """
    options.check("nextage-sim", NEXTAGE_OPEN, _EXTRAS)
    given = [n for n, v in (("host", options.host), ("port", options.port), ("rsi_listen", options.rsi_listen)) if v is not None]
    if given:
        raise ValueError(f"the nextage-sim back end is a simulator and takes no {', '.join(given)}")
    period = option_ranges.check("control_period", options.extra.get("control_period", "0.01"), label="nextage-sim: control_period")
    tool = parse_tool(options.extra["tool"]) if "tool" in options.extra else HAND_TOOL
    check = options.extra.get("collision_check", "on")
    if check not in ("on", "off"):
        raise ValueError(f"nextage-sim: collision_check must be on or off, got {check!r}")
    mounts = {n: parse_mount(options.extra[f"{n}_mount"], f"nextage-sim: {n}_mount") for n in vision.REAL_CAMERAS if f"{n}_mount" in options.extra}
    faults = [parse_fault(text) for text in options.faults]
    for spec, text in zip(faults, options.faults):  # an option error now, not a BridgeError out of the start
        if spec.group not in GROUPS:
            raise ValueError(f"nextage-sim: fault {text!r}: no group {spec.group!r} (groups: {', '.join(GROUPS)})")
    return NextageSimBackend(
        clock,
        initial_pose=options.extra.get("initial_pose", "initial"),
        control_period=period,
        seed=options.seed,
        faults=faults,
        tools={"left_arm": tool, "right_arm": tool},
        camera_mounts=mounts,
        check_collisions=check == "on",
    )
