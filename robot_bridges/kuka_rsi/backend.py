"""The KUKA RSI back end: group ``arm`` of a KR C4 robot driven through RSI corrections.

Primitives become commands of the external-system loop (:mod:`.interface`): a joint move and a
point-to-point Cartesian move go to the joint generator and ``AK``; a linear move and a relative
linear move go to the Cartesian generator and ``RKorr``; a recording is planned or sampled; a
recorded trajectory is streamed point by point; a dwell counts robot cycles (IPOC), not wall time; a
hand action sets a tool output of the ``<Sen>`` packet and waits until the robot echoes it.

Every wait is bounded by the robot itself: a move ends when the loop reports it done or failed
(it gives up after ``settle_cycles``), a handshake or a tool output gets a budget of cycles, and
if packets stop coming the loop reports the silence.  An RSI stop, a timeout or a stopped
simulator becomes :class:`BridgeError` (``CONTROLLER`` or ``TIMEOUT``) for the running and every
later primitive: RSI must be restarted on the controller before the robot moves again.

``pause`` brakes the robot at the generator's limits; ``resume`` aims again at the same target, or
streams the rest of a trajectory from where the arm stopped; ``stop`` brakes and abandons the primitive.

This module is the back end's face: its start and end, the port, and the registry's ``create``.  The
motion is :mod:`.arm_commands`, the checks of a target before anything is sent :mod:`.target_checks`,
the loop's feedback (events, faults, bounded waits) :mod:`.loop_events`, and the simulated controller
it starts without a real one :mod:`.sim_controller`.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from core_functions import option_ranges
from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    ExecuteTrajectory,
    MoveCartesian,
    MotionResult,
    MoveJoints,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    SetOutput,
    SetSpeed,
    WaitInput,
    describe,
)
from core_functions.robots import KUKA_KR, RobotModel
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind, JointLimits, RobotBackend
from robot_bridges.kuka_rsi.arm_commands import ArmCommands, MotionLimits, Run
from robot_bridges.kuka_rsi.config import ConfigError, RsiConfig, load_config
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink
from robot_bridges.kuka_rsi.interface import RsiInterface, RunnerMode
from robot_bridges.kuka_rsi.kinematics import KR6_R900, URDF_PATH, KukaArm
from robot_bridges.kuka_rsi.krc_model import PEERS, RsiContext, like_peer
from robot_bridges.kuka_rsi.link import feedback_gaps, require_feedback
from robot_bridges.kuka_rsi.loop_events import LoopEvents, say_once
from robot_bridges.kuka_rsi.peer import resolve_ipv4
from robot_bridges.kuka_rsi.realtime import SIMULATED_SILENCE, realtime_advice
from robot_bridges.kuka_rsi.signals import Signals
from robot_bridges.kuka_rsi.sim_controller import SimulatedController, SimulatorSpec
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import Endpoint, SimulatorThread
from robot_bridges.kuka_rsi.spoofer import Flood
from robot_bridges.kuka_rsi.target_checks import joint_target

log = logging.getLogger(__name__)

GROUP = "arm"


class RsiStartError(BridgeError, ConnectionError):
    """The back end could not start: no robot to drive.  A ConnectionError as well, so a command
    line reports it in one line like any other controller it cannot reach."""


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
        self.events = LoopEvents(self.name, handshake_cycles, self._simulator_stop_reason)
        #: The simulated controller this back end starts (None: a real one is driven).
        self.simulator = None if simulator is None else SimulatedController(simulator, self.config, self.roles, self.link, self.events, self.name)
        self.commands = ArmCommands(self.events, self.link, self.spec, self.arm, limits, self.config, self.roles)
        self.signals = Signals(self.events, self.config, self.roles, self.link.cycle_ms / 1000.0)
        self.summary: str | None = None  # the loop's end-of-run account, after close()

    @property
    def groups(self) -> tuple[str, ...]:
        return (GROUP,)

    @property
    def iface(self) -> RsiInterface | None:
        """The RSI loop, while started."""
        return self.events.iface

    @property
    def sim_thread(self) -> SimulatorThread | None:
        """The simulated controller's thread, when it runs in this process and has started."""
        return None if self.simulator is None else self.simulator.thread

    def set_speed_override(self, rate: float) -> None:
        """The loop plays every move and stream at ``rate`` of its speed on its path from its next cycle, the change
        within the axes' accelerations (otg.py: the speed cap; streaming.py: the path's rate)."""
        super().set_speed_override(rate)
        if self.iface is not None:
            self.iface.set_speed_override(0, rate)

    def _simulator_stop_reason(self) -> str | None:
        return None if self.simulator is None else self.simulator.stop_reason()

    # ---------------------------------------------------------------------------- lifecycle
    async def start(self) -> None:
        """Bind the loop, start the simulator if any, wait for the first valid packet and the
        handshakes.  On failure everything started is closed again and :class:`RsiStartError` says why."""
        self.events.starting = True
        try:
            await self._start()
        except BridgeError as error:
            self.events.fault = self.events.fault or error  # so close() tears down without the closing handshakes
            await self.close()
            raise RsiStartError(error.kind, error.detail) from None
        finally:
            self.events.starting = False

    async def _start(self) -> None:
        events = self.events
        events.attach(RsiInterface([self.link], self.settings, mode=self.runner))
        iface = events.iface
        assert iface is not None
        iface.start()
        if self.speed_override != 1.0:  # set before the loop started: it holds from the first cycle
            iface.set_speed_override(0, self.speed_override)
        events.watch(iface.fileno(), events.on_events)
        await events.until(lambda: self.iface is not None and self.iface.events.address is not None, None, "the RSI loop to bind")
        address = iface.events.address
        assert address is not None
        log.info("%s: RSI loop on %s:%d (%s)", self.name, address[0], address[1], iface.events.tuning)
        gaps = feedback_gaps(self.config, self.roles)
        if gaps:  # said once, here: what the configuration does not send switches off what needs it
            say_once(logging.WARNING, f"{self.config.source} sends {'; '.join(gaps)}")  # the same words in the dry runs and the run
        advice = realtime_advice(iface.events.tuning)
        if advice is not None:
            log.warning("%s: %s", self.name, advice)
        if self.feedback_file:
            iface.set_feedback_output(0, self.feedback_file)
        if self.simulator is not None:
            self.simulator.start(address)
        await events.until(lambda: self.iface is not None and self.iface.events.connected[0], None, "the first RSI packet")
        if self.roles.handshake(self.config):
            await events.handshake(self.roles.allow_start, self.roles.task_active, "allow start")
            await events.handshake(self.roles.allow_move, self.roles.correction_active, "allow move")
        await events.until(lambda: events.state().correcting, self.handshake_cycles, "RSI_MOVECORR")

    async def close(self) -> None:
        events = self.events
        iface = events.iface
        try:
            if iface is not None and events.fault is None and self.roles.handshake(self.config):
                await events.handshake(self.roles.request_end, self.roles.realtime_ended, "request real-time end")
                tag = self.roles.allow_finish
                iface.set_flag(0, tag, True)
                await events.until(lambda: iface.flag_sent(0, tag), None, f"a reply carrying {tag}")  # then the KRL task ends RSI
            elif iface is not None and events.fault is None and iface.has_flag(0, self.roles.stop):
                # No handshake (kroshu's configurations): Stop ends RSI normally, where silence would end it
                # in the controller's timeout error; its KRL program then goes on after RSI_MOVECORR.
                tag = self.roles.stop
                iface.set_flag(0, tag, True)
                await events.until(lambda: iface.flag_sent(0, tag), None, f"a reply carrying {tag}")
        except BridgeError as error:
            log.warning("%s: could not end the KRL task cleanly: %s", self.name, error)
        finally:
            events.unwatch_all()
            if self.simulator is not None:
                self.simulator.close()
            if iface is not None:
                iface.close()
                self.summary = iface.events.summary
                if self.summary is not None:  # the loop's account of the run: every other sender named by address
                    log.log(logging.WARNING if iface.events.suspicious else logging.INFO, "%s: %s", self.name, self.summary)
            events.iface = None

    async def wait_cycles(self, cycles: int) -> None:
        """Let ``cycles`` RSI cycles of robot time pass (raises the fault if the robot stops)."""
        await self.events.wait_cycles(cycles)

    # ----------------------------------------------------------------------------- execute
    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self._check_group(group)
        commands = self.commands
        if commands.run is not None:
            raise BridgeError(FaultKind.BUSY, f"{self.name}: {group} is already executing a primitive")
        if self.events.fault is not None:
            raise self.events.fault
        if self.iface is None:
            raise BridgeError(FaultKind.CONNECTION, f"{self.name}: not started")
        commands.run = Run()
        try:
            return await self._execute(primitive)
        finally:
            commands.run = None

    async def _execute(self, primitive: Primitive) -> PrimitiveResult:
        commands = self.commands
        if isinstance(primitive, MoveJoints):
            await commands.move_joints(joint_target(self.name, self.spec, primitive, commands.commanded()))
        elif isinstance(primitive, MoveCartesian):
            await commands.move_pose(primitive.target, primitive.interpolation, primitive.frame or str(primitive.target))
        elif isinstance(primitive, MoveRelative):
            await commands.move_pose(commands.relative_target(primitive), primitive.interpolation, f"relative {primitive.delta}")
        elif isinstance(primitive, SetSpeed):
            commands.speed = primitive.fraction
        elif isinstance(primitive, Dwell):
            await commands.dwell(primitive.seconds)
        elif isinstance(primitive, EndEffector):
            return await commands.end_effector(primitive.action)
        elif isinstance(primitive, ExecuteTrajectory):
            await commands.trajectory(primitive)
        elif isinstance(primitive, RecordTrajectory):
            return await commands.record(primitive)
        elif isinstance(primitive, SetOutput):
            return await self.signals.set_output(primitive)
        elif isinstance(primitive, WaitInput):
            assert commands.run is not None
            return await self.signals.wait_input(primitive, commands.run)
        else:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: a KUKA arm over RSI cannot do {describe(primitive)}")
        return self._motion_result()

    def _check_group(self, group: str) -> None:
        if group != GROUP:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name}: no group {group!r} (only {GROUP!r})")

    def _motion_result(self) -> MotionResult:
        state = self.events.state()
        return MotionResult(self.spec.joint_names, tuple(state.actual_joints), self._tcp(state.actual_joints))

    def _tcp(self, joints: tuple[float, ...]) -> Pose:
        """The TCP of the actual axes by the kinematics every plan uses: what a configuration without
        RIst lacks, and what a peer reporting RIst at zero (ROS-I's simulator) would get wrong."""
        return Pose.from_matrix(self.arm.fk(np.array(joints)))

    # ------------------------------------------------------------------ pause, resume, stop
    async def pause(self, group: str) -> None:
        self._check_group(group)
        run = self.commands.run
        if run is None or run.paused or self.iface is None:
            return
        run.paused = True
        run.resumed.clear()
        run.halt = self.iface.halt(0)

    async def resume(self, group: str) -> None:
        self._check_group(group)
        run = self.commands.run
        if run is None or not run.paused:
            return
        run.paused = False
        run.resumed.set()
        self.events.changed.set()

    async def stop(self, group: str) -> None:
        self._check_group(group)
        run = self.commands.run
        if run is None or self.iface is None:
            return
        run.stopped = True
        self.iface.halt(0)
        self.events.changed.set()

    # --------------------------------------------------------------------------- state
    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        if self.iface is None:
            return self.spec.joint_names, tuple(math.radians(v) for v in RsiContext().start_deg)
        return self.spec.joint_names, tuple(self.events.state().actual_joints)

    def tcp_pose(self, group: str) -> Pose | None:
        self._check_group(group)
        if self.iface is None:
            return None
        return self._tcp(self.events.state().actual_joints)

    def joint_limits(self, group: str) -> JointLimits:
        """The axis ranges, speeds and accelerations of the robot link, which the loop's generators keep to."""
        self._check_group(group)
        link = self.link
        return JointLimits(self.spec.joint_names, link.lower, link.upper, link.max_joint_speed, link.max_joint_accel)

    def robot_description(self) -> str | None:
        """The KR 6 R900's URDF; None for an arm given other link lengths (the URDF would lie)."""
        return URDF_PATH.read_text(encoding="utf-8") if self.arm.g == KR6_R900 else None


_EXTRAS = (
    "runner", "simulator", "config", "mode", "cycle", "timeout", "axis_monitor", "silence", "connect_timeout", "feedback",
    "linear_speed", "linear_accel", "tolerance", "tolerance_mm", "sim_frozen_setpoint", "sim_drop", "sim_drift", "sim_root_attribute",
    "sim_flood", "sim_peer", "follow_time",
)



@dataclass(frozen=True)
class KukaSettings:
    """The RSI options, parsed and checked (nothing resolved, bound or started yet)."""

    runner: str
    simulator: str
    mode: str
    cycle: int
    timeout: int
    axis_monitor: float
    silence: float | None  # None: the back end's default for the kind of controller
    connect_timeout: float
    limits: MotionLimits
    tolerance: float
    tolerance_mm: float
    config: RsiConfig | None
    listen: Endpoint | None  # rsi_listen: a real controller
    faults: Faults
    quirks: Quirks
    flood: Flood
    peer: str = "kr-c4"  # sim_peer: the controller the simulated one behaves like
    follow_time: float = 0.1  # s: how long the actual axes may trail the commanded set point (a frozen or absent report)


def parse_options(options: BackendOptions, speed: float = 1.0) -> KukaSettings:
    """The ``kuka-rsi`` options checked against each other and the run's clock (``speed``;
    ``math.inf`` for simulated time) before anything starts; ValueError naming the option.
    Names (``host``, ``rsi_listen``) are resolved by :func:`create`, once."""
    options.check("kuka-rsi", KUKA_KR, _EXTRAS)
    if speed != 1.0:
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

    def number(name: str, default: str) -> float:  # in its range (core_functions.option_ranges), KUKA RSI's where it has its own
        return option_ranges.check(name, extra.get(name, default), label=f"kuka-rsi: {name}", scope="kuka-rsi")

    cycle = int(number("cycle", "4"))  # 4 or 12 ms: the table lists the two
    timeout = int(number("timeout", "100"))
    monitor = number("axis_monitor", "360")
    silence = number("silence", "0.1") if "silence" in extra else None
    connect = number("connect_timeout", "10")
    limits = MotionLimits(linear_speed=number("linear_speed", "1.0"), linear_accel=number("linear_accel", "2.0"))
    tolerance = number("tolerance", "0.1")
    tolerance_mm = number("tolerance_mm", "1.0")
    follow_time = number("follow_time", "0.1")
    try:
        config = load_config(extra["config"]) if "config" in extra else None
        if config is not None:  # what it truly needs, refused here in one line, checked or not
            require_feedback(config, "kuka")
    except ConfigError as error:
        raise ValueError(str(error)) from None
    if options.port is not None:
        option_ranges.check_int("port", options.port, label="kuka-rsi: port")
    listen = None
    if options.rsi_listen is not None:
        try:
            listen = Endpoint.parse(options.rsi_listen)
        except ValueError as error:
            raise ValueError(f"kuka-rsi: rsi_listen (--rsi-listen): {error}") from None
        if options.host is None:
            raise ValueError("kuka-rsi: with rsi_listen, give the controller's address as host: only its packets are answered")
        if any(key.startswith("sim_") for key in extra):
            raise ValueError("kuka-rsi: the sim_ options shape the simulated controller; a real one (rsi_listen) takes none")
    elif options.host is not None:
        raise ValueError("kuka-rsi: a real controller needs rsi_listen=HOST:PORT (its RSI configuration's IP_NUMBER:PORT) as well as host")
    faults, quirks, flood = _misbehaviour(extra, options.seed)
    peer = extra.get("sim_peer", "kr-c4")
    if peer not in PEERS:
        raise ValueError(f"kuka-rsi: sim_peer must be {' or '.join(PEERS)}, got {peer!r}")
    return KukaSettings(runner, sim_runner, mode, cycle, timeout, monitor, silence, connect, limits, tolerance, tolerance_mm,
                        config, listen, faults, quirks, flood, peer, follow_time)


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
    s = parse_options(options, math.inf if clock.simulated else clock.speed)
    trust = {"setpoint_tolerance_deg": (s.tolerance,) * 6, "tcp_tolerance_mm": s.tolerance_mm, "follow_time": s.follow_time}
    common = {"limits": s.limits, "robot": options.robot, "feedback_file": options.extra.get("feedback")}
    if s.listen is not None:
        assert options.host is not None and options.rsi_listen is not None  # parse_options
        # Names are resolved once, here; from now on the loop compares IPs.
        listen_ip = resolve_ipv4(s.listen.host, f"kuka-rsi: rsi_listen (--rsi-listen) {options.rsi_listen!r}")
        host_ip = resolve_ipv4(options.host, f"kuka-rsi: host (--host) {options.host!r}")
        link = RobotLink("kuka", host_ip, options.port or None, config=s.config, correction_mode=s.mode, cycle_ms=s.cycle, **trust)  # type: ignore[arg-type]
        settings = LoopSettings(silence_timeout=0.1 if s.silence is None else s.silence, connect_timeout=s.connect_timeout)
        return KukaRsiBackend(listen=(listen_ip, s.listen.port), link=link, simulator=None, runner=s.runner, settings=settings, **common)  # type: ignore[arg-type]
    context = RsiContext(cycle_ms=s.cycle, timeout=s.timeout, correction_mode=s.mode, axis_monitor_deg=(s.axis_monitor,) * 6)
    context, quirks = like_peer(s.peer, context, s.quirks)  # sim_peer: ROS-Industrial's simulator, say
    link = RobotLink("kuka", "127.0.0.1", None, config=s.config, correction_mode=s.mode, cycle_ms=s.cycle, **trust)  # type: ignore[arg-type]
    accelerated = s.simulator == "accelerated"
    # The simulated controller is a process (or thread) of this computer, not hard real time:
    # held back by a busy computer it goes quiet without being lost (SIMULATED_SILENCE).  In-process,
    # the lockstep controller shares the application's GIL: a long computation there can hold it
    # back for a while longer.  Neither is silence the loop may take for a stop.
    silence = s.silence if s.silence is not None else 2.0 if accelerated else SIMULATED_SILENCE
    settings = LoopSettings(silence_timeout=silence, connect_timeout=s.connect_timeout)
    spec = SimulatorSpec(
        runner="thread" if accelerated else s.simulator, accelerated=accelerated, context=context, faults=s.faults, quirks=quirks, flood=s.flood, peer=s.peer,
    )
    return KukaRsiBackend(listen=("127.0.0.1", options.port or 0), link=link, simulator=spec, runner=s.runner,  # type: ignore[arg-type]
                          settings=settings, **common)  # the bridge node starts it


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
