"""The Adept V+ back end: the primitives of group ``arm`` as AdeptServer skills over TCP.

Units and frames: primitives are SI (m, rad) with quaternion poses in the robot's world frame,
which for V+ is the robot base (``BASE`` null); AdeptServer speaks mm and degrees, and
orientations as V+ yaw/pitch/roll, Z-Y-Z' Euler angles (:mod:`robot_bridges.vplus.kinematics`).
Conversion happens here and nowhere else.

How primitives map to skills -- every motion is one joined write, ``[set_speed:s,] <move>, break``:

=================================  ==================================================================
MoveJoints (absolute / relative)   ``move_joints`` / ``move_rel_joints`` (deg)
MoveCartesian                      ``move_to`` (mm, deg)
MoveRelative, reference tool       ``move_rel_tool`` with the delta as a V+ location
MoveRelative, reference world      translation only: ``move_rel_world:dx,dy,dz,0,0,0``; with a
                                   rotation: ``move_to`` the target computed from the last ack,
                                   because AdeptServer adds Euler angles component by component
SetSpeed                           remembered; sent as ``set_speed`` before *every* motion, since
                                   V+ ``SPEED`` without ``ALWAYS`` lasts one motion only
Dwell                              waits on the clock (nothing is sent)
EndEffector                        air_on/air_off -> ``enable_air``/``disable_air``;
                                   gripper_open/close -> ``gripper_open``/``gripper_close``
Vision                             the :class:`MeasurementPort` (the controller has no camera)
RecordTrajectory (plan)            planned here on the Viper's kinematics; nothing is sent
ExecuteTrajectory                  ``move_joints`` from sample to sample, each with its own speed
anything else                      ``BridgeError(UNSUPPORTED)`` (a taught recording included)
=================================  ==================================================================

AdeptServer's motions are all ``MOVE``/``JMOVE``: joint-interpolated.  A ``linear`` primitive
therefore reaches its target exactly but not along a straight line; ``linear="reject"`` refuses
such primitives (UNSUPPORTED) instead.  A straight line within a tolerance is what a ``linear``
*recording* gives: its samples are placed so that the ``JMOVE`` chords between them keep to the
line (:mod:`robot_bridges.vplus.trajectory`).  Targets are checked against the Viper's kinematics and
joint limits before anything is sent, so an impossible move fails at once as UNREACHABLE or
JOINT_LIMIT rather than as a timeout (the server never reports errors).

Where the robot is comes from the acks: ``tcp_pose`` is the pose of the last ack and the joint
state is derived from it (inverse kinematics seeded by the commanded joints; exact after a
joint move).  After any failure the next primitive first sends a lone ``break``, which waits for
a motion still under way and reports the pose, so the estimate is right again before we move.
Every other ack is checked against what was commanded (:mod:`robot_bridges.vplus.trust`): a
motion must end at its goal and start, like a hand action, where the last one ended, within
``tolerance_mm`` / ``tolerance_deg``; a controller that reports otherwise is a ``controller``
fault and is not trusted again.

Pause, resume and stop: AdeptServer cannot hold or abort a motion in progress (its only motion
control is ``break``).  ``pause`` therefore takes effect at the end of the current motion: the
primitive completes, and its result is held back until ``resume``.  ``stop`` abandons the
primitive at once on our side (``BridgeError(STOPPED)``); the controller finishes the motion it
started, and the next primitive queues behind it (V+ starts no motion before the previous one
has ended).  An emergency stop is the controller's E-stop, not this protocol.  A ``Dwell`` is
paused and stopped exactly.
"""
from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
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
from core_functions.robots import ADEPT_VIPER_S850, RobotModel
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind, JointLimits, RobotBackend
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import (
    CommandTimeout,
    ConnectError,
    ConnectionLost,
    ProtocolError,
    VPlusClient,
    VPlusError,
)
from robot_bridges.vplus.codec import Ack, Command
from robot_bridges.vplus.kinematics import (
    IKError,
    URDF_PATH,
    VIPER_S850,
    ViperKinematics,
    location_to_matrix,
    location_to_pose,
    pose_to_location,
)
from robot_bridges.vplus.camera_port import rendered_focus_camera
from robot_bridges.vplus.job import Job
from robot_bridges.vplus.measurement import MeasurementError, MeasurementPort, SimulatedFocusCamera
from robot_bridges.vplus.monitor import MonitorSpeed
from robot_bridges.vplus.options import parse_options
from robot_bridges.vplus.simulator import DEFAULT_PORT, VPlusSimulator
from robot_bridges.vplus.trajectory import JOINT_RAMP, TrajectoryPlanner, plan_replay
from robot_bridges.vplus.trust import PoseTolerance, agree, disagreement

log = logging.getLogger(__name__)

GROUP = "arm"
LinearPolicy = Literal["joint", "reject"]
_RAMP = 0.2  # s, generous acceleration allowance per motion for the timeout estimate
_END_EFFECTOR: dict[str, Command] = {
    "air_on": codec.ENABLE_AIR,
    "air_off": codec.DISABLE_AIR,
    "gripper_open": codec.GRIPPER_OPEN,
    "gripper_close": codec.GRIPPER_CLOSE,
}


class VPlusBackend(RobotBackend):
    """An Adept Viper s850 behind AdeptServer (a real controller or the simulator)."""

    world_frame = "world"

    def __init__(
        self,
        clock: Clock,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        robot: RobotModel = ADEPT_VIPER_S850,
        kinematics: ViperKinematics | None = None,
        measurement: MeasurementPort | None = None,
        ack_timeout: float = 5.0,
        retries: int = 3,
        linear: LinearPolicy = "joint",
        simulator: VPlusSimulator | None = None,
        tolerance: PoseTolerance | None = None,
    ) -> None:
        group = robot.group(GROUP)
        if len(group.joints) != 6:
            raise ValueError(f"{robot.name}: group {GROUP!r} must have 6 joints for AdeptServer, has {len(group.joints)}")
        if linear not in ("joint", "reject"):
            raise ValueError(f"linear must be 'joint' or 'reject', got {linear!r}")
        self.clock = clock
        self.robot = robot
        self.kin = kinematics or ViperKinematics(joints=group.joints)
        self.planner = TrajectoryPlanner(self.kin)
        self.joint_names = group.joint_names
        self.measurement = measurement
        self.ack_timeout = ack_timeout
        self.linear = linear
        self.tolerance = tolerance or PoseTolerance()
        self.client = VPlusClient(host, port, clock, timeout=ack_timeout, retries=retries)
        # ``name`` also names the bridge node, so it stays a plain token; messages say ``label``.
        self.name = "vplus"
        self.label = f"vplus {host}:{port}"
        self.monitor = MonitorSpeed(clock, self.client, self.label)  # the speed override: V+ monitor speed (monitor.py)
        self._simulator = simulator  # owned: started by create(), closed with us
        self._joints = self.kin.home.copy()
        self._tcp: Pose | None = None
        self._speed = 100.0  # percent
        self._io = {"air": False, "gripper_closed": False}
        self._job: Job | None = None
        self._stale = True  # the pose estimate needs a resync before the next motion
        self._busy_until = 0.0  # run time at which the controller should be idle again
        self._warned_linear = False
        self._distrust: str | None = None  # why this controller's reports are no longer believed

    @property
    def groups(self) -> tuple[str, ...]:
        return (GROUP,)

    #: AdeptServer runs a motion it was sent to its end (break is its only motion control), and the
    #: arm's joints are known from the acknowledgements.
    holds_within_motion = False

    # ---------------------------------------------------------------------------- lifecycle
    async def start(self) -> None:
        await self._ensure_link()

    async def close(self) -> None:
        job = self._job
        if job is not None:
            job.stopped = True
            job.signal()
            await asyncio.gather(asyncio.shield(job.finished), return_exceptions=True)
        await self.monitor.close()
        await self.client.close()
        if self._simulator is not None:
            await self._simulator.close()

    def set_speed_override(self, rate: float) -> None:
        super().set_speed_override(rate)
        self.monitor.set(rate)  # the controller's monitor speed: the running motion too, on its path

    # ------------------------------------------------------------------------------ state
    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        return self.joint_names, tuple(float(q) for q in self._joints)

    def tcp_pose(self, group: str) -> Pose | None:
        self._check_group(group)
        return self._tcp

    def joint_limits(self, group: str) -> JointLimits:
        """The Viper's joint ranges and speeds; its accelerations as the speed reached within the ramp
        (:data:`~robot_bridges.vplus.trajectory.JOINT_RAMP`) every motion estimate of this back end allows."""
        self._check_group(group)
        kin = self.kin
        velocity = tuple(float(v) for v in kin.max_velocity)
        return JointLimits(
            tuple(self.joint_names), tuple(float(v) for v in kin.lower), tuple(float(v) for v in kin.upper),
            velocity, tuple(v / JOINT_RAMP for v in velocity),
        )

    def robot_description(self) -> str | None:
        """The Viper s850's URDF; None for an arm given other link lengths (the URDF would lie)."""
        return URDF_PATH.read_text(encoding="utf-8") if self.kin.geometry == VIPER_S850 else None

    @property
    def speed_percent(self) -> float:
        return self._speed

    # ------------------------------------------------------------------------- execution
    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self._check_group(group)
        if self._job is not None:
            raise BridgeError(FaultKind.BUSY, f"{self.label}: {GROUP} is already executing a primitive")
        job = Job(asyncio.get_running_loop())
        self._job = job
        work = asyncio.ensure_future(self._dispatch(primitive, job))
        try:
            while not work.done() and not job.stopped:
                waiter = asyncio.ensure_future(job.next_change())
                await asyncio.wait({work, waiter}, return_when=asyncio.FIRST_COMPLETED)
                waiter.cancel()
            if job.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.label}: {describe(primitive)} stopped")
            result = work.result()
            while job.paused and not job.stopped:  # pause lands at the end of the motion: hold the result
                await job.next_change()
            if job.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.label}: {describe(primitive)} stopped")
            return result
        finally:
            if not work.done():
                work.cancel()
            await asyncio.gather(work, return_exceptions=True)
            self._job = None
            job.finished.set_result(None)

    async def measure(self, group: str) -> MotionResult:
        """Where the arm is by the controller's word: after a loss or a failure a lone ``break`` asks it first."""
        self._check_group(group)
        if self._job is not None:
            raise BridgeError(FaultKind.BUSY, f"{self.label}: {GROUP} is executing a primitive: no measurement now")
        await self._ensure_link()
        return self._motion_result()

    async def pause(self, group: str) -> None:
        self._check_group(group)
        if self._job is not None:
            self._job.paused = True
            self._job.signal()

    async def resume(self, group: str) -> None:
        self._check_group(group)
        if self._job is not None and self._job.paused:
            self._job.paused = False
            self._job.signal()

    async def stop(self, group: str) -> None:
        self._check_group(group)
        job = self._job
        if job is None:
            return
        job.stopped = True
        job.signal()
        await asyncio.shield(job.finished)

    async def _dispatch(self, primitive: Primitive, job: Job) -> PrimitiveResult:
        if isinstance(primitive, MoveJoints):
            return await self._move_joints(primitive)
        if isinstance(primitive, MoveCartesian):
            self._check_linear(primitive.interpolation, primitive)
            target = primitive.target
            return await self._move_to_pose(target, codec.move_to(pose_to_location(target)), describe(primitive))
        if isinstance(primitive, MoveRelative):
            self._check_linear(primitive.interpolation, primitive)
            return await self._move_relative(primitive)
        if isinstance(primitive, SetSpeed):
            self._speed = max(0.001, round(primitive.fraction * 100.0, 3))
            return self._motion_result()
        if isinstance(primitive, Dwell):
            await self._dwell(primitive.seconds, job)
            return self._motion_result()
        if isinstance(primitive, EndEffector):
            return await self._end_effector(primitive)
        if isinstance(primitive, Vision):
            return await self._vision(primitive)
        if isinstance(primitive, RecordTrajectory):
            return await self._record(primitive)
        if isinstance(primitive, ExecuteTrajectory):
            await self._ensure_link()
            replay = plan_replay(self.kin, self.label, primitive, self._speed)
            return await self._send_motion(replay.commands, replay.goal, replay.estimate, describe(primitive))
        raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: AdeptServer has no skill for {describe(primitive)}")

    # ---------------------------------------------------------------------------- motions
    async def _move_joints(self, primitive: MoveJoints) -> MotionResult:
        values = self._in_group_order(primitive)
        if primitive.relative:
            await self._ensure_link()
            goal = self._joints + np.asarray(values)
            commands = codec.move_rel_joints(np.degrees(values))
        else:
            goal = np.asarray(values, dtype=float)
            commands = codec.move_joints(np.degrees(values))
        violations = self.kin.limit_violations(goal)
        if violations:
            raise BridgeError(FaultKind.JOINT_LIMIT, f"{self.label}: {describe(primitive)}: " + "; ".join(violations))
        return await self._motion(commands, goal, describe(primitive))

    async def _move_relative(self, primitive: MoveRelative) -> MotionResult:
        await self._ensure_link()
        now = self._current_pose()
        delta = primitive.delta
        what = describe(primitive) + f" ({primitive.reference})"
        target = primitive.goal(now)
        if primitive.reference == "tool":
            return await self._move_to_pose(target, codec.move_rel_tool(pose_to_location(delta)), what)
        if delta.angle_to(Pose()) < 1e-12:  # a pure translation: the skill made for it
            mm = (delta.x * 1000.0, delta.y * 1000.0, delta.z * 1000.0, 0.0, 0.0, 0.0)
            return await self._move_to_pose(target, codec.move_rel_world(mm), what)
        return await self._move_to_pose(target, codec.move_to(pose_to_location(target)), what)

    async def _move_to_pose(self, target: Pose, commands: Sequence[Command], what: str) -> MotionResult:
        await self._ensure_link()
        try:
            goal = self.kin.inverse(target.matrix(), self._joints)
        except IKError as error:
            kind = FaultKind.JOINT_LIMIT if error.reason == "joint_limit" else FaultKind.UNREACHABLE
            raise BridgeError(kind, f"{self.label}: {what}: target {target}: {error}") from None
        return await self._motion(commands, goal, what)

    async def _motion(self, commands: Sequence[Command], goal: np.ndarray, what: str) -> MotionResult:
        """Send one motion (with the speed and a break) and wait until the arm has arrived."""
        await self._ensure_link()
        messages: list[Command] = [] if self._speed == 100.0 else [codec.set_speed(self._speed)]
        messages.extend(commands)
        if messages[-1] != codec.BREAK:
            messages.append(codec.BREAK)
        return await self._send_motion(messages, goal, self._duration(goal), what)

    async def _send_motion(self, messages: Sequence[Command], goal: np.ndarray, estimate: float, what: str) -> MotionResult:
        """Write ``messages`` (ending in a break) at once and wait for the arm to reach ``goal`` (the wait stretched
        by the motion time a speed override below 100 % takes)."""
        await self.monitor.delivered()
        if self.monitor.problem is not None:  # never faster than the operator asked
            raise BridgeError(FaultKind.CONTROLLER, f"{what} not sent: {self.monitor.problem}")
        timeout = self.ack_timeout + 2.0 * estimate + self._busy_for()
        start = self._trusted_pose()
        self._busy_until = self.clock.now() + estimate + self._busy_for()
        talk = asyncio.ensure_future(self._talk(messages, timeout, what, joined=True))
        stretch = asyncio.ensure_future(self.monitor.stretching(talk))
        try:
            acks = await talk
        finally:
            stretch.cancel()
        self._busy_until = 0.0
        self._check(acks[0], start, f"{what}, start")
        self._check(acks[-1], self.kin.forward(goal), what)
        self._update(acks[-1], goal)
        return self._motion_result()

    def _duration(self, goal: np.ndarray) -> float:
        """An upper estimate of how long the controller takes to reach ``goal`` (joint move)."""
        delta = np.abs(np.asarray(goal) - self._joints)
        speed = self._speed / 100.0
        return float(np.max(delta / (self.kin.max_velocity * speed))) + _RAMP

    def _busy_for(self) -> float:
        return max(0.0, self._busy_until - self.clock.now())

    def _check_linear(self, interpolation: str, primitive: Primitive) -> None:
        if interpolation != "linear":
            return
        if self.linear == "reject":
            raise BridgeError(
                FaultKind.UNSUPPORTED, f"{self.label}: {describe(primitive)}: AdeptServer moves are joint-interpolated (MOVE), not linear"
            )
        if not self._warned_linear:
            self._warned_linear = True
            log.warning("%s: linear moves run joint-interpolated (AdeptServer MOVE): exact target, curved path", self.label)

    async def _record(self, primitive: RecordTrajectory) -> TrajectoryResult:
        """Plan on the Viper's kinematics from where the arm is; nothing moves (:mod:`.trajectory`)."""
        if primitive.mode == "teach":
            raise BridgeError(
                FaultKind.UNSUPPORTED, f"{self.label}: {describe(primitive)}: AdeptServer cannot report the arm while it is guided by hand"
            )
        await self._ensure_link()
        return self.planner.record(self.label, self._joints, primitive)

    # ---------------------------------------------------------------------- other skills
    async def _dwell(self, seconds: float, job: Job) -> None:
        remaining = seconds
        while remaining > 0 and not job.stopped:
            if job.paused:
                await job.next_change()
                continue
            started = self.clock.now()
            try:
                await self.clock.wait_for(job.next_change(), remaining)
            except asyncio.TimeoutError:
                return
            remaining -= self.clock.now() - started

    async def _end_effector(self, primitive: EndEffector) -> EndEffectorResult:
        command = _END_EFFECTOR.get(primitive.action)
        if command is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: AdeptServer has no skill for {describe(primitive)}")
        await self._ensure_link()
        still = self._trusted_pose()
        acks = await self._talk([command], self.ack_timeout + self._busy_for(), describe(primitive))
        self._check(acks[-1], still, describe(primitive))
        self._note_pose(acks[-1])
        if primitive.action.startswith("gripper"):
            self._io.update(air=True, gripper_closed=primitive.action == "gripper_close")
        else:
            self._io["air"] = primitive.action == "air_on"
        return EndEffectorResult(io=dict(self._io))

    async def _vision(self, primitive: Vision) -> VisionResult:
        if self.measurement is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: {describe(primitive)}: no measurement port connected")
        await self._ensure_link()
        try:
            return await self.measurement.measure(primitive, self._current_pose())
        except MeasurementError as error:
            raise BridgeError(FaultKind.VISION, f"{self.label}: {describe(primitive)}: {error}") from None

    # ------------------------------------------------------------------------- the link
    async def _ensure_link(self) -> None:
        """Connected and with a fresh pose: reconnect after a loss, resync after any failure."""
        if self._distrust is not None:
            raise BridgeError(FaultKind.CONTROLLER, f"{self._distrust}; nothing more is sent to it")
        if not self.client.connected:
            try:
                await self.client.connect()
            except ConnectError as error:
                raise BridgeError(FaultKind.CONNECTION, f"{self.label}: {error}") from None
            self._stale = True
        if self._stale:
            acks = await self._talk([codec.BREAK], self.ack_timeout + 2.0 * self._busy_for(), "resync (break)")
            self._busy_until = 0.0
            self._update(acks[-1], self._joints)

    async def _talk(self, commands: Sequence[Command], timeout: float, what: str, *, joined: bool = False) -> list[Ack]:
        try:
            if joined:
                acks = await self.client.execute_joined(*commands, timeout=timeout)
            else:
                acks = await self.client.execute(*commands, timeout=timeout)
        except VPlusError as error:
            self._stale = True
            raise BridgeError(_fault_kind(error), f"{self.label}: {what}: {error}") from None
        except asyncio.CancelledError:
            self._stale = True  # abandoned (stop): the controller may still be moving
            raise
        self._stale = False
        return acks

    def _trusted_pose(self) -> np.ndarray | None:
        """Where the arm must be when the next ack comes, if it is not moving: the last pose taken."""
        if self._stale or self._tcp is None or self._busy_for() > 0:
            return None
        return self._tcp.matrix()

    def _check(self, ack: Ack, commanded: np.ndarray | None, what: str) -> None:
        """A reported pose that is not where the arm was sent is a fault, and the controller is believed no more."""
        if commanded is None:
            return
        problem = disagreement(self.label, what, commanded, ack.pose, self.tolerance)
        if problem is not None:
            self._distrust, self._stale = problem, True
            raise BridgeError(FaultKind.CONTROLLER, problem)

    def _update(self, ack: Ack, predicted: np.ndarray) -> None:
        """Take the pose from ``ack`` and the joints that explain it, nearest ``predicted``."""
        self._note_pose(ack)
        reported = location_to_matrix(ack.pose)
        expected = self.kin.forward(predicted)
        if agree(expected, reported):
            self._joints = np.asarray(predicted, dtype=float)
            return
        try:
            self._joints = self.kin.inverse(reported, predicted)
        except IKError as error:
            log.warning("%s: pose %s from the controller has no joint solution (%s); joint state is an estimate", self.label, ack.pose, error)
            self._joints = np.asarray(predicted, dtype=float)

    def _note_pose(self, ack: Ack) -> None:
        self._tcp = location_to_pose(ack.pose)

    def _current_pose(self) -> Pose:
        if self._tcp is None:  # before the first ack: where the joint estimate puts it
            return Pose.from_matrix(self.kin.forward(self._joints))
        return self._tcp

    def _motion_result(self) -> MotionResult:
        return MotionResult(self.joint_names, tuple(float(q) for q in self._joints), self._tcp)

    def _in_group_order(self, primitive: MoveJoints) -> tuple[float, ...]:
        if len(primitive.positions) != 6:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: {GROUP} has 6 joints, got {len(primitive.positions)} positions")
        if not primitive.joint_names or tuple(primitive.joint_names) == self.joint_names:
            return tuple(primitive.positions)
        if sorted(primitive.joint_names) != sorted(self.joint_names):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: joints {list(primitive.joint_names)} are not those of {GROUP} {list(self.joint_names)}")
        by_name = dict(zip(primitive.joint_names, primitive.positions))
        return tuple(by_name[n] for n in self.joint_names)

    def _check_group(self, group: str) -> None:
        if group != GROUP:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.label}: no group {group!r} (this robot has only {GROUP!r})")


def _fault_kind(error: VPlusError) -> FaultKind:
    if isinstance(error, CommandTimeout):
        return FaultKind.TIMEOUT
    if isinstance(error, (ConnectionLost, ConnectError)):
        return FaultKind.CONNECTION
    if isinstance(error, ProtocolError):
        return FaultKind.PROTOCOL
    return FaultKind.INTERNAL


# ------------------------------------------------------------------------------ registry
async def create(clock: Clock, options: BackendOptions) -> VPlusBackend:
    """Registry factory (``vplus``): a controller at ``host:port``, or, without a host, the simulator.

    Without a host an AdeptServer simulator is started in-process on 127.0.0.1 (``port``, or a
    free one) and a simulated focus camera answers vision requests.  Extras (checked by
    :func:`robot_bridges.vplus.options.parse_options`): ``timeout`` (s, ack allowance per command on
    top of the motion time), ``retries`` (connection attempts after the first), ``linear`` (``joint``
    or ``reject``), ``camera`` (``simulated``, ``rendered`` or ``none``: what answers vision requests
    -- the sharpness model of the focus camera, the sharpness of its rendered images
    (:mod:`robot_bridges.vplus.camera_port`), nothing; default ``simulated`` without a host, ``none``
    with one -- a real cell plugs its vision pipeline in as a :class:`MeasurementPort`, e.g. a
    :class:`~robot_bridges.vplus.camera_port.CameraMeasurement` on a ROS camera), ``tolerance_mm``
    and ``tolerance_deg`` (how far a reported pose may lie from the commanded one: [0.01, 50] mm,
    default 1; [0.01, 10] deg, default 0.5), ``controller_speed`` (a simulated controller's speed,
    which the run's must match), and for the simulator only ``sim_frozen_pose`` (1: every ack
    reports the pose it started at, home, wherever the arm is -- a controller that lies).
    """
    settings = parse_options(options, math.inf if clock.simulated else clock.speed)
    measurement: MeasurementPort | None = None
    if settings.camera == "simulated":
        measurement = SimulatedFocusCamera(seed=options.seed)
    elif settings.camera == "rendered":
        measurement = rendered_focus_camera(options.seed)
    link = {"robot": options.robot, "measurement": measurement, "ack_timeout": settings.timeout, "retries": settings.retries,
            "linear": settings.linear, "tolerance": settings.tolerance}
    if options.host is not None:
        return VPlusBackend(clock, options.host, DEFAULT_PORT if options.port is None else options.port, **link)  # type: ignore[arg-type]
    simulator = await VPlusSimulator(clock, "127.0.0.1", options.port or 0).start()
    if settings.frozen_pose:
        simulator.faults.report_location = simulator.arm.location()
    return VPlusBackend(clock, "127.0.0.1", simulator.port, simulator=simulator, **link)  # type: ignore[arg-type]
