"""The Nextage Open kinematic simulator as a :class:`RobotBackend`.

Groups ``left_arm``, ``right_arm`` and ``torso_head``; world frame ``WAIST``.  Every primitive of
:mod:`core_functions.primitives` is executed the way the real robot would: planned completely
first (IK, limits, continuity -- so a bad request fails before anything moves), then played on
the injected :class:`~node_transport.clock.Clock`, one control period at a time, so that
``joint_state()`` and ``tcp_pose()`` show the motion in progress and the simulation runs at real
time, 10x, or in virtual time purely by the choice of clock.

A running primitive is a *job* holding one group, or several (FullBodyMove: all three;
MasterSlaveMove: both arms).  ``pause`` freezes the job's own clock (the arm holds where it is),
``resume`` continues the very same planned motion to its original target, ``stop`` abandons it
and its ``execute`` raises ``BridgeError(STOPPED)``.  The speed override plays the jobs' own time at its
rate (:mod:`robot_bridges.path_rate`: on the path, within the joints' limits; 0 holds on the path).  Faults
can be injected per group (:mod:`robot_bridges.nextage_sim.faults`) to exercise error handling.

This module is the back end's face: the port, the simulator's extras and what each primitive does.  The
jobs and the loop that plays them are :mod:`~robot_bridges.nextage_sim.jobs`, the Cartesian plans
:mod:`~robot_bridges.nextage_sim.planning`, and the limit, collision and camera-range checks with the
wording of injected faults :mod:`~robot_bridges.nextage_sim.checks`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from core_functions.geometry import Pose
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
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind, JointLimits, RobotBackend
from robot_bridges.camera.sources import RenderedCamera
from robot_bridges.camera.spec import parse_mount
from robot_bridges.camera.vision import CameraVision
from robot_bridges.collision import CollisionScene, cell_boxes, held_part, scene_for
from robot_bridges.nextage_sim import checks, planning, vision
from robot_bridges.nextage_sim.faults import FaultPlan, FaultSpec, parse_fault
from robot_bridges.nextage_sim.guard import CollisionGuard
from robot_bridges.nextage_sim.hands import HandIO
from robot_bridges.nextage_sim.jobs import DONE, Job, JobBoard, Tick
from robot_bridges.nextage_sim.model import WORLD_FRAME, ArmKinematics, NextageModel
from robot_bridges.nextage_sim.trajectory import CartesianLimits, Motion, at_rate, plan_joint_move, plan_replay, sample
from robot_bridges.path_rate import sampled_shape

if TYPE_CHECKING:
    from node_transport.wire import CellSnapshot

GROUPS: tuple[str, ...] = ("left_arm", "right_arm", "torso_head")


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
        self.model = model or NextageModel()
        self.cartesian_limits = cartesian_limits or CartesianLimits()
        #: Told of every motion as it starts: (groups, joint names, motion with ``at(t)``, duration).
        self.motion_observer: Callable[[frozenset[str], tuple[str, ...], Any, float], None] | None = None
        #: The collision model every motion is swept with as it starts (None: not checked; the dry run sweeps instead).
        #: ``run`` turns it on (the ``collision_check`` option); a bare simulator for kinematics tests has it off.
        self.collisions: CollisionScene | None = scene_for(NEXTAGE_OPEN) if check_collisions else None
        self._guard: CollisionGuard | None = None  # sweeps the running motions when they change (guard.py)
        self._moving: dict[Job, Motion] = {}  # every job playing a motion, and its motion
        self._tcps: dict[str, tuple[tuple[bytes, Pose], Pose]] = {}  # arm -> ((joints, tool), TCP there): tcp_pose's last answer
        self._cell: CellSnapshot | None = None
        self._work: checks.Work = {}  # arm -> where its current motion starts and ends
        self._q = self.model.named_pose(initial_pose)
        self._results: dict[str, tuple[bytes, Pose | None, MotionResult]] = {}  # group -> the joints and tool of its last result
        self._speed = dict.fromkeys(GROUPS, 1.0)
        self._jobs = JobBoard(clock, float(control_period))
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
            MoveJoints: self._move_joints, MoveCartesian: self._move_cartesian, MoveRelative: self._move_relative,
            SetSpeed: self._set_speed, Dwell: self._dwell, EndEffector: self._end_effector, Vision: self._look,
            RecordTrajectory: self._record, ExecuteTrajectory: self._execute_trajectory, FullBodyMove: self._full_body,
            MasterSlaveMove: self._master_slave,
        }

    # ------------------------------------------------------------------------ the port
    @property
    def groups(self) -> tuple[str, ...]:
        return GROUPS

    @property
    def control_period(self) -> float:
        """s between two steps of a motion (and two checks of its joint limits; collisions are proven per motion)."""
        return self._jobs.control_period

    async def close(self) -> None:
        await self._jobs.close()

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self._check_group(group)
        handler = self._handlers.get(type(primitive))
        if handler is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name} cannot execute {type(primitive).__name__}")
        result: PrimitiveResult = await handler(group, primitive)
        return result

    async def pause(self, group: str) -> None:
        self._check_group(group)
        self._jobs.pause(group)
        self._replan()

    async def resume(self, group: str) -> None:
        self._check_group(group)
        self._jobs.resume(group)
        self._replan()

    async def stop(self, group: str) -> None:
        self._check_group(group)
        self._replan()
        await self._jobs.stop(group)

    def set_speed_override(self, rate: float) -> None:
        super().set_speed_override(rate)  # every job's own time runs at the rate, reached within the joints' limits
        self._jobs.set_override(rate)
        self._replan()

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names = NEXTAGE_OPEN.joint_names
        return names, tuple(float(self._q[self.model.index(n)]) for n in names)

    def tcp_pose(self, group: str) -> Pose | None:
        """The arm's TCP now; kept until a joint or the tool changes (the state is published every period,
        a set_speed or dwell answers with it: no forward kinematics for a robot that did not move)."""
        self._check_group(group)
        arm = self.model.arms.get(group)
        if arm is None:
            return None
        key = (self._q.tobytes(), arm.tool)
        kept = self._tcps.get(group)
        if kept is None or kept[0] != key:
            kept = self._tcps[group] = (key, arm.tcp_pose(self._q))
        return kept[1]

    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell
        self._replan()
        if self.collisions is not None:
            self.collisions.set_cell(cell_boxes(cell))
        self._vision.set_cell(cell)
        self.cameras.set_cell(cell)

    def robot_description(self) -> str | None:
        return self.model.urdf_path.read_text(encoding="utf-8")

    def joint_limits(self, group: str) -> JointLimits:
        """The URDF's position and speed limits and the arms' acceleration limit, as every motion is checked."""
        self._check_group(group)
        names = NEXTAGE_OPEN.group(group).joint_names
        idx = self.model.indices(names)
        m = self.model
        return JointLimits(names, *(tuple(float(v) for v in a[idx]) for a in (m.lower, m.upper, m.velocity, m.acceleration)))

    # ----------------------------------------------------------------- simulator extras
    def set_tool(self, group: str, tool: Pose) -> None:
        """Make the arm's TCP ``tool`` (a pose in ``*ARM_JOINT5_Link``) instead of the flange."""
        self._arm(group).tool = tool
        self._tcps.pop(group, None)
        self._replan()
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
        job = self._jobs.of(group)
        if job is None or not job.teaching:
            raise ValueError(f"{group} is not teaching a trajectory; it can only be guided while it is")
        idx = self._group_indices(group)
        if len(positions) != len(idx):
            raise ValueError(f"{group} has {len(idx)} joints, got {len(positions)} positions")
        values = np.array(positions, dtype=float)
        problem = checks.limit_violation(self.model, self._q, idx, values)
        if problem:
            raise ValueError(f"{group} cannot be guided there: {problem}")
        self._q[idx] = values
        self._replan()

    # --------------------------------------------------------------------- primitives
    async def _set_speed(self, group: str, primitive: SetSpeed) -> MotionResult:
        with self._jobs.hold(frozenset({group}), primitive):
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
        with self._jobs.hold(frozenset({group}), primitive) as job:
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
        with self._jobs.hold(frozenset({group}), primitive) as job:
            start = arm.tcp_pose(self._q)
            target = target_of(start)
            fault = self._take_fault(job, group, target)
            limits = self._limits(arm.indices)
            motion = planning.plan_cartesian(
                group, arm, self._q, start, target, interpolation, limits, self.cartesian_limits, self._job_speed(job)
            )
            await self._play(job, motion, fault)
        return self._result(group)

    async def _dwell(self, group: str, primitive: Dwell) -> MotionResult:
        with self._jobs.hold(frozenset({group}), primitive) as job:
            await self._run(job, primitive.seconds, lambda t: None)
        return self._result(group)

    async def _end_effector(self, group: str, primitive: EndEffector) -> EndEffectorResult:
        hand = self._hand(group)
        with self._jobs.hold(frozenset({group}), primitive) as job:
            action = hand.apply(primitive.action)  # the output switches now; the hardware takes a moment
            await self._run(job, action.duration, lambda t: None)
        if self.collisions is not None and primitive.action in ("gripper_close", "gripper_open"):
            tcp = self._arm(group).tcp_pose(self._q)
            closed = primitive.action == "gripper_close" and self._cell is not None
            self.collisions.set_held(group, held_part(self._cell, tcp) if closed and self._cell is not None else None)
            self._replan()
        return EndEffectorResult(io=hand.snapshot())

    async def _look(self, group: str, primitive: Vision) -> VisionResult:
        cameras = vision.taking_part(primitive.camera or NEXTAGE_OPEN.group(group).camera, self.camera_specs)
        with self._jobs.hold(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group)
            # The images are taken now, with the cameras where the kinematics put them now.
            placed = [(cam, cam.optical_pose(Pose.from_matrix(self.model.frame_matrix(self._q, cam.link)))) for cam in cameras]
            observation: VisionResult | BridgeError
            try:
                checks.check_range(primitive, primitive.nominal or self._vision.frame_pose(primitive.target), placed)
                observation = await self.cameras.observe(primitive, placed)
            except BridgeError as error:
                observation = error
            await self._run(job, vision.VISION_TIME, lambda t: None, fault)
        if isinstance(observation, BridgeError):
            raise observation
        return observation

    async def _record(self, group: str, primitive: RecordTrajectory) -> TrajectoryResult:
        if primitive.mode == "teach":
            return await self._teach(group, primitive)
        arm = self._arm(group)
        with self._jobs.hold(frozenset({group}), primitive) as job:
            fault = self._take_fault(job, group, primitive.waypoints[0])
            if fault is not None and fault.kind is FaultKind.UNREACHABLE:
                raise self._fault_error(job, fault, primitive.waypoints[0])
            plan = planning.plan_recording(group, arm, self._q, primitive, self._limits(arm.indices), self.cartesian_limits)
            times, points = sample(plan, primitive.sample_period)
        return TrajectoryResult(arm.joint_names, tuple(tuple(map(float, p)) for p in points), tuple(map(float, times)))

    async def _teach(self, group: str, primitive: RecordTrajectory) -> TrajectoryResult:
        idx = self._group_indices(group)
        period = primitive.sample_period
        count = max(1, math.ceil(primitive.duration / period - 1e-9))
        marks = [min(k * period, primitive.duration) for k in range(count + 1)]
        times: list[float] = []
        points: list[tuple[float, ...]] = []

        def tick(t: float) -> None:
            while len(times) < len(marks) and t >= marks[len(times)] - DONE:
                times.append(marks[len(times)])
                points.append(tuple(float(v) for v in self._q[idx]))

        with self._jobs.hold(frozenset({group}), primitive) as job:
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
        with self._jobs.hold(frozenset({group}), primitive) as job:
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
        joined = await self._jobs.join(group, primitive)
        if not joined:
            idx = self.model.indices(primitive.joint_names)
            goal = np.array(primitive.positions, dtype=float)
            self._require_within_limits(group, idx, goal, "full-body target")
            with self._jobs.hold(frozenset(GROUPS), primitive) as job:
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
        if not await self._jobs.join(group, primitive):
            with self._jobs.hold(frozenset(pair), primitive) as job:
                fault = self._take_fault(job, group, primitive.master_path[0])
                master, slave = self._arm(primitive.master), self._arm(primitive.slave)
                limits = self._limits(np.concatenate([master.indices, slave.indices]))
                motion = planning.plan_master_slave(primitive, master, slave, self._q, limits, self.cartesian_limits, self._job_speed(job))
                await self._play(job, motion, fault)
        return self._result(group)

    # ------------------------------------------------------------------- the runner
    async def _play(self, job: Job, motion: Motion, fault: FaultSpec | None) -> None:
        """Drive the joints along ``motion`` on the clock, checking limits every period."""
        group = sorted(job.groups)[0]
        if self.motion_observer is not None:  # the dry run keeps the exact path for its collision sweep
            self.motion_observer(job.groups, tuple(self.model.joint_names[int(i)] for i in motion.indices), *at_rate(motion, job.rate.rate))

        checks.note_work(self.model, self._q, self._work, job.groups, motion)
        job.shape, job.limits = sampled_shape(motion.at, motion.duration), self.model.acceleration[motion.indices]
        self._moving[job] = motion
        self._replan()

        def tick(t: float) -> None:
            positions = motion.at(t)
            problem = checks.limit_violation(self.model, self._q, motion.indices, positions)
            if problem:
                raise BridgeError(FaultKind.JOINT_LIMIT, f"{group}: {describe(job.primitive)} at t = {t:.3f} s: {problem}")
            self._q[motion.indices] = positions
            guard = self._guard_now()
            if guard is not None:
                checks.check_collisions(guard, self.clock.now(), self._q, self._moving, self._work, job, motion, t)

        try:
            await self._run(job, motion.duration, tick, fault)
        finally:
            del self._moving[job]
            self._replan()

    def _guard_now(self) -> CollisionGuard | None:
        """The guard of the collision model in use (None: collisions are not checked)."""
        if self.collisions is None:
            self._guard = None
        elif self._guard is None or self._guard.scene is not self.collisions:
            self._guard = CollisionGuard(self.collisions)
        return self._guard

    def _replan(self) -> None:
        """What the robot will do changed: the running motions are swept again at their next tick."""
        if self._guard is not None:
            self._guard.invalidate()

    async def _run(self, job: Job, duration: float, tick: Tick, fault: FaultSpec | None = None, marks: Sequence[float] = ()) -> None:
        """Play ``job`` over ``duration`` s of its own time (:meth:`JobBoard.run`), an injected fault worded here."""
        await self._jobs.run(job, duration, tick, fault, self._fault_error, marks)

    def _take_fault(self, job: Job, group: str, target: Pose | None = None) -> FaultSpec | None:
        """The injected fault for this job, raised at once when it strikes before any motion."""
        fault = self._faults.take(job.groups, job.primitive)
        if fault is not None and fault.after <= 0.0:
            raise self._fault_error(job, fault, target)
        return fault

    def _fault_error(self, job: Job, fault: FaultSpec, target: Pose | None = None) -> BridgeError:
        return checks.injected_fault_error(self.model, self._q, job, fault, target)

    # ----------------------------------------------------------------------- helpers
    def _check_group(self, group: str) -> None:
        if group not in GROUPS:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name} has no group {group!r} (groups: {', '.join(GROUPS)})")

    def _arm(self, group: str) -> ArmKinematics:
        self._check_group(group)
        return checks.require_arm(self.model, group)

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

    def _job_speed(self, job: Job) -> float:
        """A job over several groups moves at the slowest of their speeds."""
        return min(self._speed[g] for g in job.groups)

    def _require_within_limits(self, group: str, idx: np.ndarray, values: np.ndarray, what: str) -> None:
        checks.require_within_limits(self.model, self._q, group, idx, values, what)

    def _result(self, group: str) -> MotionResult:
        """Where the group is. A primitive that moved nothing (set_speed, a dwell) gets the group's last
        result again, without forward kinematics: the same joints and tool give the same TCP, bit for bit."""
        arm = self.model.arms.get(group)
        joints, tool = self._q.tobytes(), None if arm is None else arm.tool
        last = self._results.get(group)
        if last is not None and last[0] == joints and last[1] == tool:
            return last[2]
        names = NEXTAGE_OPEN.group(group).joint_names
        result = MotionResult(names, tuple(float(self._q[self.model.index(n)]) for n in names), self.tcp_pose(group))
        self._results[group] = (joints, tool, result)
        return result


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


@dataclass(frozen=True)
class NextageSettings:
    """The simulator's options, parsed and checked: what :func:`create` builds it from."""

    initial_pose: str
    control_period: float
    tool: Pose
    check_collisions: bool
    camera_mounts: dict[str, Pose]
    faults: tuple[FaultSpec, ...]


def parse_options(options: BackendOptions, speed: float = 1.0) -> NextageSettings:
    """The ``nextage-sim`` options checked, before anything is built or run (``speed``: the run's
    clock, ``math.inf`` for simulated time -- a simulator takes any); ValueError naming the option.

    Understands ``faults``, ``seed`` and the extras ``initial_pose``, ``control_period``,
    ``tool`` (the TCP in the flange frame; default :data:`HAND_TOOL`), ``collision_check`` (``on``, the
    default: two bodies touching stop the motion with a ``collision`` fault; ``off``) and ``<camera>_mount`` (a
    camera's hand-eye calibration, six numbers x y z roll pitch yaw in its link); a controller address makes
    no sense for a simulator and is refused rather than ignored.  ``control_period`` lies in its range
    (core_functions.option_ranges: [0.001, 0.5] s): a longer step would let a motion pass a joint limit
    between two checks (collisions are proven per motion, whatever the period: guard.py).
    """
    options.check("nextage-sim", NEXTAGE_OPEN, _EXTRAS)
    given = [n for n, v in (("host", options.host), ("port", options.port), ("rsi_listen", options.rsi_listen)) if v is not None]
    if given:
        raise ValueError(f"the nextage-sim back end is a simulator and takes no {', '.join(given)}")
    period = option_ranges.check("control_period", options.extra.get("control_period", "0.01"), label="nextage-sim: control_period")
    pose = options.extra.get("initial_pose", "initial")
    if pose not in NEXTAGE_OPEN.poses:
        raise ValueError(f"nextage-sim: initial_pose: unknown Nextage pose {pose!r} (known: {', '.join(NEXTAGE_OPEN.poses)})")
    tool = parse_tool(options.extra["tool"]) if "tool" in options.extra else HAND_TOOL
    check = options.extra.get("collision_check", "on")
    if check not in ("on", "off"):
        raise ValueError(f"nextage-sim: collision_check must be on or off, got {check!r}")
    mounts = {n: parse_mount(options.extra[f"{n}_mount"], f"nextage-sim: {n}_mount") for n in vision.REAL_CAMERAS if f"{n}_mount" in options.extra}
    faults = tuple(parse_fault(text) for text in options.faults)
    for spec, text in zip(faults, options.faults):  # an option error now, not a BridgeError out of the start
        if spec.group not in GROUPS:
            raise ValueError(f"nextage-sim: fault {text!r}: no group {spec.group!r} (groups: {', '.join(GROUPS)})")
    return NextageSettings(pose, period, tool, check == "on", mounts, faults)


async def create(clock: Clock, options: BackendOptions) -> NextageSimBackend:
    """Registry factory (``nextage-sim``): the simulator from CLI / launch options (:func:`parse_options`)."""
    settings = parse_options(options)
    return NextageSimBackend(
        clock,
        initial_pose=settings.initial_pose,
        control_period=settings.control_period,
        seed=options.seed,
        faults=list(settings.faults),
        tools={"left_arm": settings.tool, "right_arm": settings.tool},
        camera_mounts=settings.camera_mounts,
        check_collisions=settings.check_collisions,
    )
