"""The KUKA RSI back end's motion: each primitive as commands of the external-system loop, waited for on the robot.

A joint move and a point-to-point Cartesian move (inverse kinematics once, here) go to the joint generator and
``AK``; a linear move and a relative linear move go to the Cartesian generator and ``RKorr``; a recording samples
straight legs within its tolerance (:mod:`.recording`); a recorded trajectory is replayed on the chords between
its samples at the RSI cycle (:mod:`.replay`) and streamed point by point; a dwell counts robot cycles (IPOC), not
wall time; a hand action sets a tool output of the ``<Sen>`` packet and waits until the robot echoes it.  A
command ends when the loop reports it done or failed; after a pause a move is sent again towards the same target
and a trajectory streams its rest from where the arm stopped; a stop abandons it.  Every plan starts from the set
point the loop commands, never from what the controller reports.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from core_functions.geometry import Pose
from core_functions.motion_profile import TcpLimits
from core_functions.primitives import EndEffectorResult, ExecuteTrajectory, MoveRelative, RecordTrajectory, TrajectoryResult
from core_functions.robots import GroupSpec
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.config import RsiConfig, RsiRoles
from robot_bridges.kuka_rsi.external import RobotLink
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.loop_events import LoopEvents
from robot_bridges.kuka_rsi.recording import RecordingPlanner
from robot_bridges.kuka_rsi.replay import remainder, resample_along, samples_passed
from robot_bridges.kuka_rsi.streaming import ToolPath, ToolPathError
from robot_bridges.kuka_rsi.target_checks import check_line, reach

#: Tool actions and the (tool output index, value) they set; index into RsiRoles.tool_outputs.
TOOL_ACTIONS: dict[str, tuple[int, bool]] = {
    "gripper_open": (0, False),
    "gripper_close": (0, True),
    "air_on": (1, True),
    "air_off": (1, False),
    "tool_on": (2, True),
    "tool_off": (2, False),
}
TOOL_NAMES = ("gripper", "air", "tool")


@dataclass(frozen=True)
class MotionLimits:
    """The speeds at SetSpeed(1.0); every motion scales them by the current speed fraction."""

    linear_speed: float = 1.0  # m/s
    linear_accel: float = 2.0  # m/s^2
    angular_speed: float = 1.5  # rad/s
    angular_accel: float = 3.0  # rad/s^2
    joint_accel: float = 6.0  # rad/s^2 (speeds: each axis's own maximum)


@dataclass
class Run:
    """The primitive being executed, and what pause/resume/stop asked of it."""

    paused: bool = False
    stopped: bool = False
    resumed: asyncio.Event = field(default_factory=asyncio.Event)
    halt: int = 0  # the pause's halt command while it has not ended (0: none)


def fault_kind(kind: str) -> FaultKind:
    """The fault kind the loop named for a failed command (CONTROLLER for one it does not know)."""
    try:
        return FaultKind(kind)
    except ValueError:
        return FaultKind.CONTROLLER


class ArmCommands:
    """The primitives of one arm as commands of the loop (``events.iface``), at the speed fraction ``speed``."""

    def __init__(
        self, events: LoopEvents, link: RobotLink, spec: GroupSpec, arm: KukaArm, limits: MotionLimits, config: RsiConfig, roles: RsiRoles
    ) -> None:
        self.events = events
        self.link = link
        self.spec = spec
        self.arm = arm
        self.limits = limits
        self.config = config
        self.roles = roles
        self.speed = 1.0
        #: The primitive being executed (None between primitives), for pause, resume and stop.
        self.run: Run | None = None
        self._dt = link.cycle_ms / 1000.0

    @property
    def name(self) -> str:
        return self.events.name

    def commanded(self) -> np.ndarray:
        """The joint set point the loop commands: where every plan starts (never the reported ASPos)."""
        return np.array(self.events.state().commanded_joints)

    def set_pose(self) -> Pose:
        """The commanded TCP pose (our kinematics of the commanded joints)."""
        return Pose.from_matrix(self.arm.fk(self.commanded()))

    # ------------------------------------------------------------------------------ moves
    async def move_joints(self, target: np.ndarray) -> None:
        iface, fraction = self.events.iface, self.speed
        assert iface is not None
        accel = self.limits.joint_accel * fraction
        await self.command(lambda: iface.set_axial_pos(0, target, 1e9, accel, fraction))

    def relative_target(self, primitive: MoveRelative) -> Pose:
        current = self.set_pose()
        d = primitive.delta
        if primitive.reference == "tool":
            return current.compose(d)
        rotation = d.matrix()[:3, :3] @ current.matrix()[:3, :3]
        m = np.eye(4)
        m[:3, :3] = rotation
        m[:3, 3] = (current.x + d.x, current.y + d.y, current.z + d.z)
        return Pose.from_matrix(m)

    async def move_pose(self, target: Pose, interpolation: str, what: str) -> None:
        iface = self.events.iface
        assert iface is not None
        reference = self.commanded()
        goal = reach(self.name, self.arm, target, reference, what)
        if interpolation == "ptp":
            await self.move_joints(goal)
            return
        check_line(self.name, self.arm, self.set_pose(), target, reference, what)
        f, lim = self.speed, self.limits
        await self.command(
            lambda: iface.set_cart_pos(0, target, lim.linear_speed * f, lim.linear_accel * f, lim.angular_speed * f, lim.angular_accel * f)
        )

    async def command(self, issue: Callable[[], int]) -> None:
        """Send a command, wait for its end; re-send it after a pause, give up on stop."""
        iface, events = self.events.iface, self.events
        assert iface is not None and self.run is not None
        run = self.run
        while True:
            if run.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.name}: stopped")
            if run.paused:
                await events.until(lambda: run.resumed.is_set() or run.stopped, None, "resume")
                continue
            cmd = issue()
            done = iface.events.done
            await events.until(lambda: cmd in done, None, "end of the move")
            ok, message, kind = done.pop(cmd)
            if ok:
                return
            if run.stopped or run.paused:
                continue  # superseded by the halt of stop() / pause()
            if events.fault is not None:
                raise events.fault  # the command ended because the robot did; say why
            raise BridgeError(fault_kind(kind), f"{self.name}: {message}")

    async def dwell(self, seconds: float) -> None:
        iface, events = self.events.iface, self.events
        assert iface is not None and self.run is not None
        run = self.run
        remaining = math.ceil(seconds / self._dt - 1e-9)
        while remaining > 0:
            if run.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.name}: stopped")
            if run.paused:
                await events.until(lambda: run.resumed.is_set() or run.stopped, None, "resume")
                continue
            end = events.state().cycles + remaining
            iface.wake_at(0, end)
            await events.until(lambda: events.state().cycles >= end or run.paused or run.stopped, None, "the end of the dwell")
            remaining = max(0, end - events.state().cycles)

    # ------------------------------------------------------------------------ trajectories
    async def trajectory(self, primitive: ExecuteTrajectory) -> None:
        """The computer-based approach: resample at the RSI cycle and stream, after a move to the start."""
        names = self.spec.joint_names
        if tuple(primitive.joint_names) != names:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: trajectory {primitive.name!r} is for {list(primitive.joint_names)}, not {list(names)}")
        points = np.array(primitive.points, dtype=float)
        times = np.array(primitive.times, dtype=float) / self.speed
        await self.move_joints(points[0])
        if len(points) > 1 and times[-1] > times[0]:
            await self._replay(primitive.name, times, points)

    async def _replay(self, name: str, times: np.ndarray, points: np.ndarray) -> None:
        """Stream the samples resampled at the RSI cycle.  A pause halts the stream wherever braking ends; the
        resume streams what is left from where the arm stands (:func:`.replay.remainder`), from rest: never the
        stream again from its first point (a jump the loop refuses, and motion made twice)."""
        iface, events = self.events.iface, self.events
        assert iface is not None and self.run is not None
        run = self.run
        while True:
            await self._unpaused(run)
            if len(points) < 2:  # paused at the end: the last sample is all that is left
                await self.move_joints(points[-1])
                return
            try:
                sampled, along = resample_along(times, points, self._dt, np.array(self.link.max_joint_speed), np.array(self.link.max_joint_accel))
                cmd = iface.set_tool_path(0, ToolPath("joint", sampled, f"trajectory {name}"))
            except ToolPathError as error:
                raise BridgeError(FaultKind.JOINT_LIMIT, f"{self.name}: {error}") from None
            except ValueError as error:
                raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: trajectory {name!r}: {error}") from None
            done = iface.events.done
            await events.until(lambda: cmd in done, None, "end of the trajectory")
            ok, message, kind = done.pop(cmd)
            reached = iface.events.progress.pop(cmd, 0.0)
            if ok:
                return
            if not (run.stopped or run.paused):
                if events.fault is not None:
                    raise events.fault
                raise BridgeError(fault_kind(kind), f"{self.name}: {message}")
            await self._unpaused(run)
            times, points = remainder(times, points, self.commanded(), samples_passed(points, along, reached))

    async def _unpaused(self, run: Run) -> None:
        """Return once the primitive may move: not paused, and the arm at rest after a pause's halt (so the
        plan starts where it really stands); STOPPED when it was stopped."""
        iface, events = self.events.iface, self.events
        assert iface is not None
        while True:
            if run.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.name}: stopped")
            if not run.paused:
                break
            await events.until(lambda: run.resumed.is_set() or run.stopped, None, "resume")
        halt, done = run.halt, iface.events.done
        if halt:
            await events.until(lambda: halt in done or run.stopped or run.paused, None, "the arm to stop")
            if halt in done:
                done.pop(halt)
                run.halt = 0
            else:  # stopped or paused again meanwhile
                await self._unpaused(run)

    async def record(self, primitive: RecordTrajectory) -> TrajectoryResult:
        """Plan through waypoints with the robot's own generators at full speed (replaying scales
        the times by the speed set then), or sample the axes while taught."""
        names = self.spec.joint_names
        period = primitive.sample_period
        if primitive.mode == "teach":
            times, points = [], []
            for k in range(max(1, math.ceil(primitive.duration / period - 1e-9)) + 1):
                if k:
                    await self.events.wait_cycles(max(1, round(period / self._dt)))
                times.append(k * period)
                points.append(tuple(self.events.state().actual_joints))
            return TrajectoryResult(names, tuple(points), tuple(times))
        return self.plan(primitive)

    def plan(self, primitive: RecordTrajectory) -> TrajectoryResult:
        """Plan from the commanded set point (never the reported one): straight legs sampled within the
        recording's tolerance, ptp legs as the joint generator moves (:mod:`.recording`)."""
        lim = self.limits
        planner = RecordingPlanner(
            self.arm, self.spec.joint_names, np.array([j.max_velocity for j in self.spec.joints]), lim.joint_accel,
            TcpLimits(linear_velocity=lim.linear_speed, angular_velocity=lim.angular_speed, linear_acceleration=lim.linear_accel, angular_acceleration=lim.angular_accel),
            self._dt,
        )
        return planner.plan(self.name, self.commanded(), primitive)

    # ------------------------------------------------------------------------------- tools
    async def end_effector(self, action: str) -> EndEffectorResult:
        iface, events = self.events.iface, self.events
        assert iface is not None
        tools = self.roles.tools(self.config)
        if action not in TOOL_ACTIONS or TOOL_ACTIONS[action][0] >= len(tools):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: no tool output for {action} in {self.config.source}")
        index, value = TOOL_ACTIONS[action]
        tag = tools[index]
        raised = events.state().cycles
        iface.set_flag(0, tag, value)
        await events.until(lambda: events.fresh(raised, tag, value), events.handshake_cycles, f"the robot to switch {tag} ({action})")
        state = events.state()
        return EndEffectorResult({TOOL_NAMES[i]: iface.digout(0, t, state) for i, t in enumerate(tools)})
