"""The KUKA RSI back end: group ``arm`` of a KR C4 robot driven through RSI corrections.

Primitives become commands of the external-system loop (:mod:`.interface`): a joint move and a
point-to-point Cartesian move (inverse kinematics once, here) go to the joint generator and
``AK``; a linear move and a relative linear move go to the Cartesian generator and ``RKorr``; a
recording samples straight legs within its tolerance (:mod:`.recording`); a recorded trajectory is
replayed on the chords between its samples at the RSI cycle (:mod:`.replay`) and streamed point by
point; a dwell counts robot cycles (IPOC), not wall time; a hand action sets a tool output of the
``<Sen>`` packet and waits until the robot echoes it.

Every wait is bounded by the robot itself: a move ends when the loop reports it done or failed
(it gives up after ``settle_cycles``), a handshake or a tool output gets a budget of cycles, and
if packets stop coming the loop reports the silence.  An RSI stop, a timeout or a stopped
simulator becomes :class:`BridgeError` (``CONTROLLER`` or ``TIMEOUT``) for the running and every
later primitive: RSI must be restarted on the controller before the robot moves again.

``pause`` brakes the robot at the generator's limits; ``resume`` aims again at the same target;
``stop`` brakes and abandons the primitive.
"""
from __future__ import annotations

import asyncio
import json
import logging
import math
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from core_functions import option_ranges
from core_functions.geometry import Pose
from core_functions.motion_profile import TcpLimits
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
    describe,
)
from core_functions.robots import KUKA_KR, RobotModel
from execution_engine.clock import Clock, real_clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind, RobotBackend
from robot_bridges.kuka_rsi.config import ConfigError, load_config
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink
from robot_bridges.kuka_rsi.interface import RobotState, RsiInterface, RunnerMode
from robot_bridges.kuka_rsi.kinematics import KR6_R900, URDF_PATH, KukaArm
from robot_bridges.kuka_rsi.recording import RecordingPlanner
from robot_bridges.kuka_rsi.peer import resolve_ipv4
from robot_bridges.kuka_rsi.realtime import SIMULATED_SILENCE, SIMULATOR_PRIORITY, realtime_advice
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import Endpoint, SimulatorThread
from robot_bridges.kuka_rsi.spoofer import Flood
from robot_bridges.kuka_rsi.replay import resample
from robot_bridges.kuka_rsi.streaming import ToolPath, ToolPathError

log = logging.getLogger(__name__)

GROUP = "arm"
#: Tool actions and the (tool output index, value) they set; index into RsiRoles.tool_outputs.
TOOL_ACTIONS: dict[str, tuple[int, bool]] = {
    "gripper_open": (0, False),
    "gripper_close": (0, True),
    "air_on": (1, True),
    "air_off": (1, False),
    "tool_on": (2, True),
    "tool_off": (2, False),
}
_TOOL_NAMES = ("gripper", "air", "tool")


@dataclass(frozen=True)
class MotionLimits:
    """The speeds at SetSpeed(1.0); every motion scales them by the current speed fraction."""

    linear_speed: float = 1.0  # m/s
    linear_accel: float = 2.0  # m/s^2
    angular_speed: float = 1.5  # rad/s
    angular_accel: float = 3.0  # rad/s^2
    joint_accel: float = 6.0  # rad/s^2 (speeds: each axis's own maximum)


@dataclass(frozen=True)
class SimulatorSpec:
    """A simulated controller the back end starts itself (``--robot kuka-rsi`` without a real one)."""

    runner: str = "process"  # "process": python -m ...simulator (real time); "thread": in-process
    accelerated: bool = False  # lockstep (thread runner only)
    context: RsiContext = RsiContext()
    faults: Faults = Faults()
    quirks: Quirks = Quirks()  # a misbehaving peer, for tests and demonstrations
    flood: Flood = Flood()  # a second sender on the controller's host (another port), for tests and demonstrations
    rt_priority: int = SIMULATOR_PRIORITY  # SCHED_FIFO of a simulator process, above the loop's (a controller is hard real time); 0: none


class RsiStartError(BridgeError, ConnectionError):
    """The back end could not start: no robot to drive.  A ConnectionError as well, so a command
    line reports it in one line like any other controller it cannot reach."""


@dataclass
class _Run:
    """The primitive being executed, and what pause/resume/stop asked of it."""

    paused: bool = False
    stopped: bool = False
    resumed: asyncio.Event = field(default_factory=asyncio.Event)


class KukaRsiBackend(RobotBackend):
    """One KR C4 robot over RSI; group ``arm``, axes A1..A6, poses in the robot base frame."""

    world_frame = "base"

    def __init__(
        self,
        *,
        listen: tuple[str, int] = ("127.0.0.1", 49152),
        robot_host: str = "127.0.0.1",
        robot_port: int | None = None,
        link: RobotLink | None = None,
        simulator: SimulatorSpec | None = SimulatorSpec(),
        runner: RunnerMode = "process",
        settings: LoopSettings | None = None,
        limits: MotionLimits = MotionLimits(),
        robot: RobotModel = KUKA_KR,
        feedback_file: str | None = None,
        handshake_cycles: int = 500,
    ) -> None:
        self.robot = robot
        self.spec = robot.group(GROUP)
        self.link = link or RobotLink("kuka", robot_host, robot_port)
        self.config = self.link.rsi_config()
        self.roles = self.link.roles
        base = settings or LoopSettings()
        self.settings = LoopSettings(**{**base.__dict__, "host": listen[0], "port": listen[1]})
        self.simulator_spec = simulator
        self.runner = runner
        self.limits = limits
        self.arm = KukaArm(joints=self.spec.joints)
        self.feedback_file = feedback_file
        self.handshake_cycles = handshake_cycles
        self.name = f"kuka_rsi {listen[0]}:{listen[1]}" + (" (simulated)" if simulator else f" <- {robot_host}")
        self.speed = 1.0
        self.iface: RsiInterface | None = None
        self._sim_thread: SimulatorThread | None = None
        self._sim_process: subprocess.Popen[str] | None = None
        self._sim_summary: dict[str, object] | None = None
        self._sim_clock_loop: asyncio.AbstractEventLoop | None = None
        self._changed = asyncio.Event()
        self._fault: BridgeError | None = None
        self._run: _Run | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._readers: list[int] = []
        self._dt = self.link.cycle_ms / 1000.0
        self._starting = False
        self.summary: str | None = None  # the loop's end-of-run account, after close()

    @property
    def groups(self) -> tuple[str, ...]:
        return (GROUP,)

    # ---------------------------------------------------------------------------- lifecycle
    async def start(self) -> None:
        """Bind the loop, start the simulator if any, wait for the first valid packet and the
        handshakes.  On failure everything started is closed again and :class:`RsiStartError` says why."""
        self._starting = True
        try:
            await self._start()
        except BridgeError as error:
            self._fault = self._fault or error  # so close() tears down without the closing handshakes
            await self.close()
            raise RsiStartError(error.kind, error.detail) from None
        finally:
            self._starting = False

    async def _start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Event()
        self.iface = RsiInterface([self.link], self.settings, mode=self.runner)
        self.iface.start()
        self._watch(self.iface.fileno(), self._on_events)
        await self._until(lambda: self.iface is not None and self.iface.events.address is not None, None, "the RSI loop to bind")
        address = self.iface.events.address
        assert address is not None
        log.info("%s: RSI loop on %s:%d (%s)", self.name, address[0], address[1], self.iface.events.tuning)
        advice = realtime_advice(self.iface.events.tuning)
        if advice is not None:
            log.warning("%s: %s", self.name, advice)
        if self.feedback_file:
            self.iface.set_feedback_output(0, self.feedback_file)
        if self.simulator_spec is not None:
            self._start_simulator(address)
        await self._until(lambda: self.iface is not None and self.iface.events.connected[0], None, "the first RSI packet")
        if self.roles.handshake(self.config):
            await self._handshake(self.roles.allow_start, self.roles.task_active, "allow start")
            await self._handshake(self.roles.allow_move, self.roles.correction_active, "allow move")
        await self._until(lambda: self._state().correcting, self.handshake_cycles, "RSI_MOVECORR")

    def _start_simulator(self, address: tuple[str, int]) -> None:
        spec = self.simulator_spec
        assert spec is not None
        if spec.runner == "thread":
            clock = None
            if not spec.accelerated:
                # The simulated controller keeps wall time whatever clock the application runs on.
                self._sim_clock_loop = asyncio.new_event_loop()
                clock = real_clock().bind(self._sim_clock_loop)
            self._sim_thread = SimulatorThread(
                self.config, address, context=spec.context, roles=self.roles, faults=spec.faults, clock=clock,
                bind=(self.link.host, self.link.port or 0), quirks=spec.quirks, flood=spec.flood,
            ).start()
            return
        self._sim_process = subprocess.Popen(self.simulator_command(address), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        assert self._sim_process.stdout is not None
        self._watch(self._sim_process.stdout.fileno(), self._on_sim_output)

    def simulator_command(self, address: tuple[str, int]) -> list[str]:
        """The command line of the simulated controller's own process, sending to the loop at ``address``."""
        spec = self.simulator_spec
        assert spec is not None
        ctx = spec.context
        args = [
            sys.executable, "-m", "robot_bridges.kuka_rsi.simulator", "--to", f"{address[0]}:{address[1]}",
            "--bind", f"{self.link.host}:{self.link.port or 0}", "--cycle", str(ctx.cycle_ms), "--timeout", str(ctx.timeout),
            "--mode", ctx.correction_mode, "--seed", str(spec.faults.seed), "--axis-monitor", str(ctx.axis_monitor_deg[0]),
            "--rt-priority", str(spec.rt_priority),
        ]
        args += _quirk_arguments(spec.faults, spec.quirks, spec.flood)
        if self.link.config is not None:
            args += ["--config", self.link.config.source]
        return args

    async def close(self) -> None:
        iface = self.iface
        try:
            if iface is not None and self._fault is None and self.roles.handshake(self.config):
                await self._handshake(self.roles.request_end, self.roles.realtime_ended, "request real-time end")
                tag = self.roles.allow_finish
                iface.set_flag(0, tag, True)
                await self._until(lambda: iface.flag_sent(0, tag), None, f"a reply carrying {tag}")  # then the KRL task ends RSI
        except BridgeError as error:
            log.warning("%s: could not end the KRL task cleanly: %s", self.name, error)
        finally:
            for fd in self._readers:
                assert self._loop is not None
                self._loop.remove_reader(fd)
            self._readers = []
            if self._sim_thread is not None:
                self._sim_thread.stop()
                self._sim_thread = None
            if self._sim_clock_loop is not None:
                self._sim_clock_loop.close()
                self._sim_clock_loop = None
            if self._sim_process is not None:
                if self._sim_process.poll() is None:
                    self._sim_process.terminate()  # our own child, by its handle
                try:
                    self._sim_process.communicate(timeout=5)
                except subprocess.TimeoutExpired:
                    self._sim_process.kill()
                    self._sim_process.communicate()
                self._sim_process = None
            if iface is not None:
                iface.close()
                self.summary = iface.events.summary
                if self.summary is not None:  # the loop's account of the run: every other sender named by address
                    log.log(logging.WARNING if iface.events.suspicious else logging.INFO, "%s: %s", self.name, self.summary)
            self.iface = None

    # ------------------------------------------------------------------------------ events
    def _watch(self, fd: int, callback: Callable[[], None]) -> None:
        assert self._loop is not None
        self._loop.add_reader(fd, callback)
        self._readers.append(fd)

    def _on_events(self) -> None:
        assert self.iface is not None
        try:
            messages = self.iface.poll_events()
        except ConnectionError:
            self._set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: the RSI loop has gone"))
            assert self._loop is not None
            self._loop.remove_reader(self.iface.fileno())
            self._readers.remove(self.iface.fileno())
            messages = []
        for message in messages:
            if message[0] == "fault":
                self._on_fault(str(message[2]), str(message[3]))
            elif message[0] == "warn":
                log.warning("%s: %s", self.name, message[2])
            elif message[0] == "late":
                log.warning("%s: the controller counts %d late replies (IPOC %d)", self.name, message[2], message[3])
            elif message[0] == "peer":
                log.info("%s: the controller speaks from %s (%s); datagrams from any other port are ignored", self.name, message[2], message[3])
            elif message[0] == "stopped" and self._fault is None:
                self._set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: the RSI loop stopped"))
        self._changed.set()

    def _on_sim_output(self) -> None:
        assert self._sim_process is not None and self._sim_process.stdout is not None
        line = self._sim_process.stdout.readline()
        if not line:
            assert self._loop is not None
            fd = self._sim_process.stdout.fileno()
            self._loop.remove_reader(fd)
            self._readers.remove(fd)
            return
        if line.startswith("{"):
            try:
                self._sim_summary = json.loads(line)
            except json.JSONDecodeError:
                pass
        elif line.strip():
            log.info("%s: %s", self.name, line.strip()[:500])  # the banner: address, cycle, real-time priority
        self._changed.set()

    def _simulator_stop_reason(self) -> str | None:
        if self._sim_thread is not None:
            return self._sim_thread.stop_reason
        if self._sim_summary is not None:
            return str(self._sim_summary.get("stopped") or "the simulator ended")
        if self._sim_process is not None and self._sim_process.poll() is not None:
            return f"the simulator exited with code {self._sim_process.returncode}"
        return None

    def _on_fault(self, kind: str, message: str) -> None:
        if kind == "timeout":
            reason = self._simulator_stop_reason()
            if reason is not None:
                self._set_fault(BridgeError(FaultKind.CONTROLLER, f"{self.name}: RSI stopped: {reason} ({message})"))
                return
            delay = self._state().delay
            hint = f"; the controller had counted {delay} late replies, so RSI may have stopped on its timeout" if delay else ""
            self._set_fault(BridgeError(FaultKind.TIMEOUT, f"{self.name}: {message}{hint}"))
        elif kind == "connection":
            self._set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: {message}"))
        elif kind == "controller":
            self._set_fault(BridgeError(FaultKind.CONTROLLER, f"{self.name}: {message}"))
        else:
            self._set_fault(BridgeError(FaultKind.INTERNAL, f"{self.name}: {message}"))

    def _set_fault(self, error: BridgeError) -> None:
        if self._fault is None:
            self._fault = error
            if not self._starting:  # a failed start says it once, in its exception
                log.error("%s", error)
        self._changed.set()

    def _state(self) -> RobotState:
        assert self.iface is not None
        return self.iface.state(0)

    async def _until(self, predicate: Callable[[], bool], cycles: int | None, what: str) -> None:
        """Wait until ``predicate()``; a fault, or ``cycles`` robot cycles, end the wait with an error.

        Without ``cycles`` the wait is bounded by the loop: it reports a fault when it cannot bind,
        when the first packet does not come in time, when packets stop, or when it dies.
        """
        start = self._state().cycles if cycles is not None and self.iface is not None else 0
        while True:
            self._changed.clear()
            if self._fault is not None:
                raise self._fault
            if predicate():
                return
            if cycles is not None and self._state().cycles - start > cycles:
                raise BridgeError(FaultKind.TIMEOUT, f"{self.name}: no {what} within {cycles} RSI cycles")
            await self._changed.wait()

    async def _handshake(self, flag: str, ack: str, what: str) -> None:
        """ITRA's logical setters: raise a flag, wait for the KRL program's output, lower the flag."""
        assert self.iface is not None
        iface = self.iface
        raised = self._state().cycles
        iface.set_flag(0, flag, True)
        try:
            await self._until(lambda: self._fresh(raised, ack, True), self.handshake_cycles, f"acknowledgement of {what} ({ack})")
        finally:
            iface.set_flag(0, flag, False)

    def _fresh(self, raised: int, tag: str, value: bool) -> bool:
        """Output ``tag`` reads ``value`` in a packet that answers a flag raised at cycle ``raised``
        (it leaves with the next reply; the robot's answer comes in the packet after)."""
        assert self.iface is not None
        state = self._state()
        return state.cycles >= raised + 2 and self.iface.digout(0, tag, state) == value

    # ----------------------------------------------------------------------------- execute
    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self._check_group(group)
        if self._run is not None:
            raise BridgeError(FaultKind.BUSY, f"{self.name}: {group} is already executing a primitive")
        if self._fault is not None:
            raise self._fault
        if self.iface is None:
            raise BridgeError(FaultKind.CONNECTION, f"{self.name}: not started")
        self._run = _Run()
        try:
            return await self._execute(primitive)
        finally:
            self._run = None

    async def _execute(self, primitive: Primitive) -> PrimitiveResult:
        if isinstance(primitive, MoveJoints):
            await self._move_joints(self._joint_target(primitive))
        elif isinstance(primitive, MoveCartesian):
            await self._move_pose(primitive.target, primitive.interpolation, primitive.frame or str(primitive.target))
        elif isinstance(primitive, MoveRelative):
            await self._move_pose(self._relative_target(primitive), primitive.interpolation, f"relative {primitive.delta}")
        elif isinstance(primitive, SetSpeed):
            self.speed = primitive.fraction
        elif isinstance(primitive, Dwell):
            await self._dwell(primitive.seconds)
        elif isinstance(primitive, EndEffector):
            return await self._end_effector(primitive.action)
        elif isinstance(primitive, ExecuteTrajectory):
            await self._trajectory(primitive)
        elif isinstance(primitive, RecordTrajectory):
            return await self._record(primitive)
        else:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: a KUKA arm over RSI cannot do {describe(primitive)}")
        return self._motion_result()

    def _check_group(self, group: str) -> None:
        if group != GROUP:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: no group {group!r} (only {GROUP!r})")

    def _motion_result(self) -> MotionResult:
        state = self._state()
        return MotionResult(self.spec.joint_names, tuple(state.actual_joints), state.tcp())

    # ------------------------------------------------------------------------------ motion
    def _joint_target(self, primitive: MoveJoints) -> np.ndarray:
        names = self.spec.joint_names
        values = np.array(primitive.positions, dtype=float)
        if primitive.joint_names:
            unknown = [n for n in primitive.joint_names if n not in names]
            if unknown or len(set(primitive.joint_names)) != len(primitive.joint_names):
                raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: joints {list(primitive.joint_names)} are not the axes {list(names)}")
            # Axes not named stay where they are: no change (relative) or the current set point.
            order = {n: i for i, n in enumerate(primitive.joint_names)}
            current = self._commanded()
            values = np.array(
                [values[order[n]] if n in order else (0.0 if primitive.relative else current[i]) for i, n in enumerate(names)]
            )
        elif len(values) != 6:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: a joint move needs 6 values (A1..A6), got {len(values)}")
        target = values + self._commanded() if primitive.relative else values
        for spec, value in zip(self.spec.joints, target):
            if not spec.contains(float(value)):
                raise BridgeError(
                    FaultKind.JOINT_LIMIT,
                    f"{self.name}: {spec.name} target {math.degrees(value):.3f} deg is outside "
                    f"[{math.degrees(spec.lower):.1f}, {math.degrees(spec.upper):.1f}] deg",
                )
        return target

    async def _move_joints(self, target: np.ndarray) -> None:
        assert self.iface is not None
        iface, fraction = self.iface, self.speed
        accel = self.limits.joint_accel * fraction
        await self._command(lambda: iface.set_axial_pos(0, target, 1e9, accel, fraction))

    def _relative_target(self, primitive: MoveRelative) -> Pose:
        current = self._set_pose()
        d = primitive.delta
        if primitive.reference == "tool":
            return current.compose(d)
        rotation = d.matrix()[:3, :3] @ current.matrix()[:3, :3]
        m = np.eye(4)
        m[:3, :3] = rotation
        m[:3, 3] = (current.x + d.x, current.y + d.y, current.z + d.z)
        return Pose.from_matrix(m)

    def _commanded(self) -> np.ndarray:
        """The joint set point the loop commands: where every plan starts (never the reported ASPos)."""
        return np.array(self._state().commanded_joints)

    def _set_pose(self) -> Pose:
        """The commanded TCP pose (our kinematics of the commanded joints)."""
        return Pose.from_matrix(self.arm.fk(self._commanded()))

    async def _move_pose(self, target: Pose, interpolation: str, what: str) -> None:
        assert self.iface is not None
        reference = self._commanded()
        goal = self.arm.ik(target.matrix(), reference)
        if goal is None:
            raise BridgeError(FaultKind.UNREACHABLE, f"{self.name}: {what} is out of reach of the arm (no IK solution within the joint limits)")
        if interpolation == "ptp":
            await self._move_joints(goal)
            return
        self._check_line(target, reference, what)
        iface, f, lim = self.iface, self.speed, self.limits
        await self._command(
            lambda: iface.set_cart_pos(0, target, lim.linear_speed * f, lim.linear_accel * f, lim.angular_speed * f, lim.angular_accel * f)
        )

    def _check_line(self, target: Pose, reference: np.ndarray, what: str, samples: int = 50) -> None:
        """Refuse a straight line that leaves the workspace or flips the arm (the robot would stop)."""
        start = self._set_pose()
        p0, p1 = np.array(start.position), np.array(target.position)
        q0, q1 = np.array(start.quaternion), np.array(target.quaternion)
        if float(np.dot(q0, q1)) < 0:
            q1 = -q1
        q = reference
        for k in range(1, samples + 1):
            s = k / samples
            quat = q0 + s * (q1 - q0)
            quat /= np.linalg.norm(quat)
            pose = Pose(*(p0 + s * (p1 - p0)), *quat)
            solved = self.arm.ik(pose.matrix(), q)
            if solved is None or float(np.max(np.abs(solved - q))) > math.radians(30):
                raise BridgeError(
                    FaultKind.UNREACHABLE,
                    f"{self.name}: the straight line to {what} leaves the workspace or passes a singularity at {100 * s:.0f}%",
                )
            q = solved

    async def _command(self, issue: Callable[[], int]) -> None:
        """Send a command, wait for its end; re-send it after a pause, give up on stop."""
        assert self.iface is not None and self._run is not None
        run = self._run
        while True:
            if run.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.name}: stopped")
            if run.paused:
                await self._until(lambda: run.resumed.is_set() or run.stopped, None, "resume")
                continue
            cmd = issue()
            done = self.iface.events.done
            await self._until(lambda: cmd in done, None, "end of the move")
            ok, message, kind = done.pop(cmd)
            if ok:
                return
            if run.stopped or run.paused:
                continue  # superseded by the halt of stop() / pause()
            if self._fault is not None:
                raise self._fault  # the command ended because the robot did; say why
            raise BridgeError(_fault_kind(kind), f"{self.name}: {message}")

    async def _dwell(self, seconds: float) -> None:
        assert self.iface is not None and self._run is not None
        run, iface = self._run, self.iface
        remaining = math.ceil(seconds / self._dt - 1e-9)
        while remaining > 0:
            if run.stopped:
                raise BridgeError(FaultKind.STOPPED, f"{self.name}: stopped")
            if run.paused:
                await self._until(lambda: run.resumed.is_set() or run.stopped, None, "resume")
                continue
            end = self._state().cycles + remaining
            iface.wake_at(0, end)
            await self._until(lambda: self._state().cycles >= end or run.paused or run.stopped, None, "the end of the dwell")
            remaining = max(0, end - self._state().cycles)

    async def _trajectory(self, primitive: ExecuteTrajectory) -> None:
        """The computer-based approach: resample at the RSI cycle and stream, after a move to the start."""
        names = self.spec.joint_names
        if tuple(primitive.joint_names) != names:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: trajectory {primitive.name!r} is for {list(primitive.joint_names)}, not {list(names)}")
        points = np.array(primitive.points, dtype=float)
        times = np.array(primitive.times, dtype=float) / self.speed
        await self._move_joints(points[0])
        if len(points) > 1 and times[-1] > times[0]:
            try:
                sampled = resample(times, points, self._dt, np.array(self.link.max_joint_speed), np.array(self.link.max_joint_accel))
            except ValueError as error:
                raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: trajectory {primitive.name!r}: {error}") from None
            path = ToolPath("joint", sampled, f"trajectory {primitive.name}")
            assert self.iface is not None
            iface = self.iface
            try:
                await self._command(lambda: iface.set_tool_path(0, path))
            except ToolPathError as error:
                raise BridgeError(FaultKind.JOINT_LIMIT, f"{self.name}: {error}") from None

    async def _record(self, primitive: RecordTrajectory) -> TrajectoryResult:
        """Plan through waypoints with the robot's own generators at full speed (replaying scales
        the times by the speed set then), or sample the axes while taught."""
        names = self.spec.joint_names
        period = primitive.sample_period
        if primitive.mode == "teach":
            times, points = [], []
            for k in range(max(1, math.ceil(primitive.duration / period - 1e-9)) + 1):
                if k:
                    await self.wait_cycles(max(1, round(period / self._dt)))
                times.append(k * period)
                points.append(tuple(self._state().actual_joints))
            return TrajectoryResult(names, tuple(points), tuple(times))
        return self._plan(primitive)

    def _plan(self, primitive: RecordTrajectory) -> TrajectoryResult:
        """Plan from the commanded set point (never the reported one): straight legs sampled within the
        recording's tolerance, ptp legs as the joint generator moves (:mod:`.recording`)."""
        lim = self.limits
        planner = RecordingPlanner(
            self.arm, self.spec.joint_names, np.array([j.max_velocity for j in self.spec.joints]), lim.joint_accel,
            TcpLimits(linear_velocity=lim.linear_speed, angular_velocity=lim.angular_speed, linear_acceleration=lim.linear_accel, angular_acceleration=lim.angular_accel),
            self._dt,
        )
        return planner.plan(self.name, self._commanded(), primitive)

    async def _end_effector(self, action: str) -> EndEffectorResult:
        assert self.iface is not None
        tools = self.roles.tools(self.config)
        if action not in TOOL_ACTIONS or TOOL_ACTIONS[action][0] >= len(tools):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: no tool output for {action} in {self.config.source}")
        index, value = TOOL_ACTIONS[action]
        tag = tools[index]
        iface = self.iface
        raised = self._state().cycles
        iface.set_flag(0, tag, value)
        await self._until(lambda: self._fresh(raised, tag, value), self.handshake_cycles, f"the robot to switch {tag} ({action})")
        state = self._state()
        return EndEffectorResult({_TOOL_NAMES[i]: iface.digout(0, t, state) for i, t in enumerate(tools)})

    async def wait_cycles(self, cycles: int) -> None:
        """Let ``cycles`` RSI cycles of robot time pass (raises the fault if the robot stops)."""
        assert self.iface is not None
        end = self._state().cycles + cycles
        self.iface.wake_at(0, end)
        await self._until(lambda: self._state().cycles >= end, None, f"{cycles} RSI cycles")

    # ------------------------------------------------------------------ pause, resume, stop
    async def pause(self, group: str) -> None:
        self._check_group(group)
        run = self._run
        if run is None or run.paused or self.iface is None:
            return
        run.paused = True
        run.resumed.clear()
        self.iface.halt(0)

    async def resume(self, group: str) -> None:
        self._check_group(group)
        run = self._run
        if run is None or not run.paused:
            return
        run.paused = False
        run.resumed.set()
        self._changed.set()

    async def stop(self, group: str) -> None:
        self._check_group(group)
        run = self._run
        if run is None or self.iface is None:
            return
        run.stopped = True
        self.iface.halt(0)
        self._changed.set()

    # --------------------------------------------------------------------------- state
    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        if self.iface is None:
            return self.spec.joint_names, tuple(math.radians(v) for v in RsiContext().start_deg)
        return self.spec.joint_names, tuple(self._state().actual_joints)

    def tcp_pose(self, group: str) -> Pose | None:
        self._check_group(group)
        if self.iface is None:
            return None
        return self._state().tcp()

    def robot_description(self) -> str | None:
        """The KR 6 R900's URDF; None for an arm given other link lengths (the URDF would lie)."""
        return URDF_PATH.read_text(encoding="utf-8") if self.arm.g == KR6_R900 else None


def _fault_kind(kind: str) -> FaultKind:
    try:
        return FaultKind(kind)
    except ValueError:
        return FaultKind.CONTROLLER



_EXTRAS = (
    "runner", "simulator", "config", "mode", "cycle", "timeout", "axis_monitor", "silence", "connect_timeout", "feedback",
    "linear_speed", "linear_accel", "tolerance", "tolerance_mm", "sim_frozen_setpoint", "sim_drop", "sim_drift", "sim_root_attribute",
    "sim_flood",
)


async def create(clock: Clock, options: BackendOptions) -> KukaRsiBackend:
    """Registry factory (``kuka-rsi``): the simulated KR C4, or a real one with ``rsi_listen``.

    Without ``rsi_listen`` a simulator is started (its own process, real time) and the loop
    listens on 127.0.0.1 (on ``port``, or a free one).  With ``rsi_listen=HOST:PORT`` -- the address
    in the controller's RSI configuration -- no simulator starts and ``host`` must name the
    controller, the only address whose packets are answered, and of it only the port ``port`` (or,
    without one, the port its first valid packet comes from).  Names in both are resolved once,
    here; one that does not resolve is a ``ValueError`` naming the option.  Extras: ``runner`` (``process`` | ``thread``: where the real-time
    loop runs), ``simulator`` (``process`` | ``thread``: real time; ``accelerated``: in-process
    lockstep, the robot as fast as the loop answers -- for tests), ``config`` (RSI Ethernet XML),
    ``mode`` (``absolute`` | ``relative``, as the RSI context corrects), ``cycle`` (4 | 12 ms),
    ``timeout`` (late packets in a row that stop the simulated RSI), ``axis_monitor`` (deg, the
    simulated AXISCORRMON limit), ``silence`` (s without packets that mean the robot is lost),
    ``connect_timeout`` (s to the first valid packet), ``feedback`` (file to save every packet
    to), ``linear_speed`` (m/s) and ``linear_accel`` (m/s^2) at 100 % speed, ``tolerance`` (deg,
    every axis) and ``tolerance_mm`` (TCP): how far the reported set point may lie from the
    commanded one.  A simulated controller can misbehave on purpose: ``sim_frozen_setpoint``
    (1: ASPos stays at the start pose), ``sim_drop`` (probability a reply is discarded),
    ``sim_drift`` (``A3:0.01``: the reported ASPos drifts, deg per cycle), ``sim_root_attribute``
    (``TYPE``: how ``<Rob>`` spells its type attribute), ``sim_flood`` (``10:packet``: a second
    sender on the controller's IP, another port, sends ten forged packets -- or ``garbage``, or
    ``mixed`` -- per cycle).

    RSI runs on the robot's clock, so the application must too: a simulated or scaled clock
    would let the engine's timeouts run ahead of the robot.
    """
    options.check("kuka-rsi", KUKA_KR, _EXTRAS)
    if clock.simulated or clock.speed != 1.0:
        raise ValueError("the kuka-rsi back end runs on the robot's real-time clock: run with --speed 1 (the default)")
    if options.faults:
        raise ValueError("the kuka-rsi back end takes no --fault (inject RSI faults with robot_bridges.kuka_rsi.sim_faults.Faults)")
    extra = options.extra
    runner = extra.get("runner", "process")
    sim_runner = extra.get("simulator", "process")
    mode = extra.get("mode", "absolute")
    choices = (("runner", runner, ("process", "thread")), ("simulator", sim_runner, ("process", "thread", "accelerated")), ("mode", mode, ("absolute", "relative")))
    for name, value, allowed in choices:
        if value not in allowed:
            raise ValueError(f"kuka-rsi: {name} must be {' or '.join(allowed)}, got {value!r}")
    cycle_text = extra.get("cycle", "4").strip()
    if cycle_text not in ("4", "12"):
        raise ValueError(f"kuka-rsi: cycle must be 4 or 12 (ms), got {cycle_text!r}")
    cycle = int(cycle_text)

    def number(name: str, default: str, setting: str | None = None) -> float:  # in its range (core_functions.option_ranges)
        return option_ranges.check(setting or name, extra.get(name, default), label=f"kuka-rsi: {name}")

    timeout = int(number("timeout", "100", "rsi_timeout"))
    monitor = number("axis_monitor", "360")
    silence = number("silence", "0.1")
    connect = number("connect_timeout", "10")
    limits = MotionLimits(linear_speed=number("linear_speed", "1.0"), linear_accel=number("linear_accel", "2.0"))
    tolerance = number("tolerance", "0.1")
    tolerance_mm = number("tolerance_mm", "1.0")
    try:
        config = load_config(extra["config"]) if "config" in extra else None
    except ConfigError as error:
        raise ValueError(str(error)) from None
    settings = LoopSettings(silence_timeout=silence, connect_timeout=connect)
    trust = {"setpoint_tolerance_deg": (tolerance,) * 6, "tcp_tolerance_mm": tolerance_mm}
    if options.port is not None and not 0 <= options.port < 65536:
        raise ValueError(f"kuka-rsi: port must be 0..65535, got {options.port}")
    if options.rsi_listen is not None:
        try:
            listen = Endpoint.parse(options.rsi_listen)
        except ValueError as error:
            raise ValueError(f"kuka-rsi: rsi_listen (--rsi-listen): {error}") from None
        if options.host is None:
            raise ValueError("kuka-rsi: with rsi_listen, give the controller's address as host: only its packets are answered")
        if any(key.startswith("sim_") for key in extra):
            raise ValueError("kuka-rsi: the sim_ options shape the simulated controller; a real one (rsi_listen) takes none")
        # Names are resolved once, here; from now on the loop compares IPs.
        listen_ip = resolve_ipv4(listen.host, f"kuka-rsi: rsi_listen (--rsi-listen) {options.rsi_listen!r}")
        host_ip = resolve_ipv4(options.host, f"kuka-rsi: host (--host) {options.host!r}")
        link = RobotLink("kuka", host_ip, options.port or None, config=config, correction_mode=mode, cycle_ms=cycle, **trust)  # type: ignore[arg-type]
        backend = KukaRsiBackend(listen=(listen_ip, listen.port), link=link, simulator=None, runner=runner, settings=settings,  # type: ignore[arg-type]
                                 limits=limits, robot=options.robot, feedback_file=extra.get("feedback"))
    else:
        if options.host is not None:
            raise ValueError("kuka-rsi: a real controller needs rsi_listen=HOST:PORT (its RSI configuration's IP_NUMBER:PORT) as well as host")
        context = RsiContext(cycle_ms=cycle, timeout=timeout, correction_mode=mode, axis_monitor_deg=(monitor,) * 6)
        link = RobotLink("kuka", "127.0.0.1", None, config=config, correction_mode=mode, cycle_ms=cycle, **trust)  # type: ignore[arg-type]
        accelerated = sim_runner == "accelerated"
        if "silence" not in extra:
            # The simulated controller is a process (or thread) of this computer, not hard real time:
            # held back by a busy computer it goes quiet without being lost (SIMULATED_SILENCE).  In-process,
            # the lockstep controller shares the application's GIL: a long computation there can hold it
            # back for a while longer.  Neither is silence the loop may take for a stop.
            settings = LoopSettings(silence_timeout=2.0 if accelerated else SIMULATED_SILENCE, connect_timeout=connect)
        faults, quirks, flood = _misbehaviour(extra, options.seed)
        spec = SimulatorSpec(
            runner="thread" if accelerated else sim_runner, accelerated=accelerated, context=context, faults=faults, quirks=quirks, flood=flood,
        )
        backend = KukaRsiBackend(listen=("127.0.0.1", options.port or 0), link=link, simulator=spec, runner=runner,  # type: ignore[arg-type]
                                 settings=settings, limits=limits, robot=options.robot, feedback_file=extra.get("feedback"))
    return backend  # the bridge node starts it


def _misbehaviour(extra: dict[str, str], seed: int) -> tuple[Faults, Quirks, Flood]:
    """The simulated controller's deliberate faults and quirks, and a flooder beside it, from the ``sim_`` options."""
    try:
        drop = option_ranges.check("sim_drop", extra.get("sim_drop", "0"))
        axis, deg = Quirks.parse_drift(extra["sim_drift"]) if "sim_drift" in extra else (0, 0.0)
        frozen = extra.get("sim_frozen_setpoint", "0")
        if frozen not in ("0", "1"):
            raise ValueError(f"sim_frozen_setpoint is 0 or 1, got {frozen!r}")
        flood = Flood.parse(extra["sim_flood"]) if "sim_flood" in extra else Flood()
        return Faults(seed=seed, drop=drop), Quirks(frozen == "1", axis, deg, extra.get("sim_root_attribute", "Type")), flood
    except ValueError as error:
        raise ValueError(f"kuka-rsi: {error}") from None


def _quirk_arguments(faults: Faults, quirks: Quirks, flood: Flood = Flood()) -> list[str]:
    """The simulator's command-line options for a misbehaving peer."""
    args = ["--drop", str(faults.drop)] if faults.drop else []
    if flood.rate:
        args += ["--flood", f"{flood.rate!r}:{flood.content}", "--flood-port", str(flood.port)]
    if quirks.frozen_setpoint:
        args.append("--frozen-setpoint")
    if quirks.drift_axis:
        args += ["--drift", f"A{quirks.drift_axis}:{quirks.drift_deg!r}"]
    if quirks.root_attribute != "Type":
        args += ["--root-attribute", quirks.root_attribute]
    if quirks.ipoc_step is not None:
        args += ["--ipoc-step", str(quirks.ipoc_step)]
    return args
