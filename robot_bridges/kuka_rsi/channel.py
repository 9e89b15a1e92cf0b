"""Everything the loop knows and does for one robot: one packet in, one reply out.

Per packet, before the reply: follow the KRL program's handshakes, read the latest command, play
the controller's cycles since our last reply (:mod:`.setpoint`: was it applied, did the robot hold),
check what the controller reports against what we commanded, step the motion (:mod:`.motion`,
which holds every step to the limits), and write the correction.  After the reply: publish the
cycle to the shared record, feed the saving thread, send events.

A controller whose report disagrees with the commanded set point is a fault: the correction stops
changing at once (absolute: the same value again; relative: zero increments), the running command
fails with :data:`CONTROLLER` naming the axis, and so does every later one -- RSI must be restarted
and the robot looked at.  Refused datagrams are counted per reason, so a peer that never gets a
packet through is told apart from a silent one.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from core_functions.geometry import quaternion_to_matrix
from robot_bridges.kuka_rsi.codec import PacketCodec, Value
from robot_bridges.kuka_rsi.convention import ReportCheck
from robot_bridges.kuka_rsi.feedback import FeedbackLogger
from robot_bridges.kuka_rsi.io_values import IoValues
from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, rotation_angle
from robot_bridges.kuka_rsi.link import RobotLink, require_feedback
from robot_bridges.kuka_rsi.motion import Motion
from robot_bridges.kuka_rsi.peer import PeerGate
from robot_bridges.kuka_rsi.setpoint import CycleAccount
from robot_bridges.kuka_rsi.slots import CommandKind, RobotSlots, SeqSlot, Status, bits
from robot_bridges.kuka_rsi.streaming import ToolPath

_DEG = math.pi / 180.0
#: Cycles the set point must have been still before the generator may change space.
QUIET_CYCLES = 2
#: Cycles a stream command waits for its points to arrive through the pipe.
STREAM_ARRIVAL_CYCLES = 250
#: The fault kind of a controller that does not hold what it was sent (a FaultKind value).
CONTROLLER = "controller"


class Channel:
    """One robot: its packets, its commands, its motion and what the loop reports of it."""

    def __init__(
        self,
        index: int,
        link: RobotLink,
        slots: RobotSlots,
        events: Callable[[tuple[object, ...]], None],
        logger: FeedbackLogger,
        heartbeat_cycles: int = 25,
    ) -> None:
        config = self.config = link.rsi_config()
        require_feedback(config, link.name)  # refused before the loop starts, too (parse_options)
        self.index = index
        self.link = link
        self.slots = slots
        self._send_event = events
        self._events: list[tuple[object, ...]] = []
        self._logger = logger
        self.rob = PacketCodec.rob(config)
        self.sen = PacketCodec.sen(config)
        self.rx: list[Value] = list(self.rob.defaults)
        self.spare: list[Value] = list(self.rob.defaults)  # a datagram is decoded here; rx takes it once it is accepted
        self.tx: list[Value] = list(self.sen.defaults)
        self.gate = PeerGate(link.port, link.ipoc_step)
        self.pinned_now = False  # the packet just taken pinned the port the robot speaks from
        self.spoofed = 0  # datagrams from this robot's IP but another port
        roles = link.roles
        ri = self.rob.index
        # What the configuration does not send is None; require_feedback made sure of AIPos.
        self._i_rist = _six(ri, "RIst", "X Y Z A B C")
        self._i_rsol = _six(ri, "RSol", "X Y Z A B C")
        self._i_aipos: list[int] = _six(ri, "AIPos", "A1 A2 A3 A4 A5 A6") or []
        self._i_aspos = _six(ri, "ASPos", "A1 A2 A3 A4 A5 A6")
        self._i_delay = ri.get("Delay.D")
        # The shared record carries RIst, RSol, AIPos, ASPos: a report not sent shows its stand-in
        # (the set point the actual value, and the other way round), or zeros (-1).
        rist, rsol = self._i_rist or self._i_rsol, self._i_rsol or self._i_rist
        self._feedback_map = [*(rist or [-1] * 6), *(rsol or [-1] * 6), *self._i_aipos, *(self._i_aspos or self._i_aipos)]
        self._state_scale = [1e-3, 1e-3, 1e-3, _DEG, _DEG, _DEG] * 2 + [_DEG] * 12
        self._send_bools = [i for i, f in enumerate(self.rob.fields) if f.type == "BOOL"]
        self._recv_bools = [i for i, f in enumerate(self.sen.fields) if f.type == "BOOL"]
        self._i_ak = [self.sen.index[k] for k in roles.axis_correction] if roles.axis(config) else None
        # Cartesian corrections need the TCP reported, set point or actual, to be checked against.
        cart = roles.cartesian(config) and (self._i_rsol is not None or self._i_rist is not None)
        self._i_rk = [self.sen.index[k] for k in roles.cart_correction] if cart else None
        self._i_correcting = ri[roles.correction_active] if roles.handshake(config) else None
        holdon = {f.key: f.holdon for f in self.sen.fields}
        external = tuple(f.key for f in self.sen.fields if f.element == "EK")  # an external axis: a correction too
        self.io = IoValues(self.rob.fields, self.sen.fields, (*roles.axis_correction, *roles.cart_correction, *external))
        dt_ms = link.cycle_ms
        check = ReportCheck(
            np.radians(np.array(link.setpoint_tolerance_deg)), (link.tcp_tolerance_mm / 1000.0, math.radians(link.tcp_tolerance_deg)),
            self._i_aspos is not None, round(max(link.follow_time * 1000.0, dt_ms)), self._note,
        )
        self.motion = Motion(
            link,
            tuple(holdon.get(k, False) for k in roles.axis_correction),
            tuple(holdon.get(k, False) for k in roles.cart_correction),
            self._reported_pose,
            self._warn,
            check,
        )
        self.account = CycleAccount(link.ipoc_step, link.cycle_ms)
        self.correcting = False
        self._fresh = False
        self._written: tuple[object, object] = (None, None)  # the correction arrays last put in tx
        self.fault: str | None = None  # the controller cross-check failed: corrections frozen for good
        self.active_id = 0
        self._active_kind = CommandKind.NONE
        self._active_target: tuple[np.ndarray, ...] = ()
        self._settle = 0
        self._pending: tuple[object, ...] | None = None
        self._pending_age = 0
        self._cmd_version = slots.command.version() & ~1
        self._override_version = slots.override.version() & ~1  # the speed override: never written is 100 %
        self._flags_version = slots.flags.version() & ~1
        self._flags = 0
        self.staged: dict[int, ToolPath] = {}
        self.withhold = 0
        self.withheld = 0
        self.catch_ups = 0  # packets that showed cycles the robot held without our reply
        self._warned: dict[str, int] = {}
        # bookkeeping
        self.cycles = 0
        self.ipoc = 0
        self.delay = 0
        self.rejected = 0
        self.refused: dict[str, int] = {}  # refused datagrams by reason
        self.refused_example: dict[str, str] = {}  # the first message of each reason
        self.refused_from = ""  # the address of the latest refused datagram
        self.last_ns = 0
        self.connected = False
        self.lost = False
        self.broken = False
        self.done_id = 0
        self.done_ok = 0
        self._digouts = -1
        self._wakes: list[int] = []
        self._heartbeat = max(1, heartbeat_cycles)

    # --------------------------------------------------------------------- per packet
    def on_packet(self, data: bytes, t_ns: int) -> bytes | None:
        """Parse one packet and build its reply (None: reply withheld on purpose)."""
        return self.respond(self.rob.decode_into(data, self.rx), t_ns)

    def respond(self, ipoc: int, t_ns: int) -> bytes | None:
        """The reply to the packet just decoded into ``rx``: one step of the robot's motion."""
        self.ipoc = ipoc
        self.last_ns = t_ns
        self.cycles += 1
        if not self.broken:
            self._track_correcting()
            self._read_commands()
            if self.correcting:
                self._account()
                if self.fault is None:
                    self._check_controller()
                if self.fault is None:
                    stopped = self.motion.step()
                    if stopped is not None and self.active_id:
                        self._finish(False, stopped, "internal")
                    self._check_done()
                self._write_corrections()
            self._read_flags()
        if self.withhold:
            self.withhold -= 1
            self.withheld += 1
            self.motion.withheld()
            return None
        return self.sen.encode(self.tx, ipoc)

    def take(self, ipoc: int, port: int) -> str | None:
        """Make the packet just decoded into :attr:`spare` this robot's latest, unless its IPOC and
        Delay cannot follow the last one's (then why not; nothing changes)."""
        delay = None if self._i_delay is None else int(self.spare[self._i_delay])  # type: ignore[call-overload]
        problem = self.gate.check(ipoc, delay)
        if problem is not None:
            return problem
        self.rx, self.spare = self.spare, self.rx
        self.pinned_now = self.gate.accept(ipoc, delay, port)
        return None

    def refuse(self, reason: str, message: str, source: str) -> None:
        """Count a datagram from this robot's address that was not a packet."""
        self.rejected += 1
        self.refused[reason] = self.refused.get(reason, 0) + 1
        self.refused_example.setdefault(reason, message)
        self.refused_from = source

    def refusals(self) -> str:
        """What was refused, for a message: how many, from where, why."""
        total = sum(self.refused.values())
        reasons = "; ".join(f"{n} x {reason}: {self.refused_example[reason]}" for reason, n in sorted(self.refused.items(), key=lambda kv: -kv[1]))
        return f"{total} packets arrived from {self.refused_from}, all refused: {reasons}"

    def _emit(self, event: tuple[object, ...]) -> None:
        """Queue an event; it leaves after the reply and after the shared record of this cycle
        is written, so whoever it wakes reads a state at least as new as the event."""
        self._events.append(event)

    def _warn(self, key: str, text: str) -> None:
        """A warning to the application: the first of its kind, then every 1000th."""
        n = self._warned.get(key, 0) + 1
        self._warned[key] = n
        if n == 1 or n % 1000 == 0:
            self._emit(("warn", self.index, f"{self.link.name}: {text} ({n} so far)"))

    def set_output(self, key: str, value: object) -> None:
        """An application signal for the next reply; reported once a reply carries it (or why not)."""
        problem = self.io.set(self.tx, key, value)
        self._emit(("output", self.index, key, self.tx[self.sen.index[key]] if problem is None else None, problem or ""))

    def _note(self, level: int, text: str) -> None:
        """Something the application should know once (a ``logging`` level): the convention found."""
        self._emit(("note", self.index, level, f"{self.link.name}: {text}"))

    def _reported_pose(self, actual: bool) -> np.ndarray | None:
        """The controller's TCP in this packet (RIst with ``actual``, else RSol), None when not sent."""
        idx = self._i_rist if actual else self._i_rsol
        return None if idx is None else self._pose_matrix(idx)

    def _track_correcting(self) -> None:
        now = True if self._i_correcting is None else bool(self.rx[self._i_correcting])
        if now and not self.correcting:
            self._begin()
        elif self.correcting and not now:
            self._end("the robot left RSI_MOVECORR (real-time control ended)")
        self.correcting = now

    def _begin(self) -> None:
        """RSI_MOVECORR began: corrections are measured from the set point the controller reports
        now -- the one report taken as an input; from here on every report is checked."""
        setpoint = self._axes(self._i_aspos or self._i_aipos)  # at rest: where the axes stand
        note = self.motion.begin_from(setpoint, self._axes(self._i_aipos), self._i_ak is not None)
        if note is not None:
            self._note(30, note)
        self.motion.check.begin(None if self._i_aspos is None else setpoint, self._reported_pose(False))
        self.account.reset(self.ipoc, self._delay())
        self._fresh = True

    def _end(self, why: str, kind: str = CONTROLLER) -> None:
        self.motion.stop()
        if self.active_id:
            self._finish(False, why, kind)
        if self._pending is not None:
            self._fail_pending(why, kind)

    def _delay(self) -> int | None:
        return None if self._i_delay is None else int(self.rx[self._i_delay])  # type: ignore[call-overload]

    def _account(self) -> None:
        """Play the controller's cycles since our last reply into the commanded set point."""
        if self._fresh:
            self._fresh = False
            return
        applied, held = self.account.account(self.ipoc, self._delay())
        if self.motion.settle(applied, held):
            self.catch_ups += 1

    def _check_controller(self) -> None:
        """The controller must hold what we commanded; if not, stop trusting it for good."""
        setpoint = None if self._i_aspos is None else self._axes(self._i_aspos)
        problem = self.motion.cross_check(setpoint, self._axes(self._i_aipos))
        if problem is None:
            return
        self.fault = f"{self.link.name}: {problem}"
        self.motion.hold()
        self._emit(("fault", self.index, CONTROLLER, self.fault))
        if self.active_id:
            self._finish(False, self.fault, CONTROLLER)
        if self._pending is not None:
            self._fail_pending(self.fault, CONTROLLER)

    def _axes(self, idx: Sequence[int]) -> np.ndarray:
        return np.array([float(self.rx[i]) * _DEG for i in idx])

    def _pose(self, idx: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        x, y, z, a, b, c = (float(self.rx[i]) for i in idx)
        return np.array([x / 1000.0, y / 1000.0, z / 1000.0]), abc_to_matrix(a * _DEG, b * _DEG, c * _DEG)

    def _pose_matrix(self, idx: Sequence[int]) -> np.ndarray:
        p, r = self._pose(idx)
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = r, p
        return m

    def _write_corrections(self) -> None:
        """Put this cycle's correction values into the reply (skipped when they are the very same)."""
        ak, rk = self.motion.replies()
        tx = self.tx
        if self._i_ak is not None and ak is not self._written[0]:
            for i, value in zip(self._i_ak, ak.tolist()):
                tx[i] = value
        if self._i_rk is not None and rk is not self._written[1]:
            for i, value in zip(self._i_rk, rk.tolist()):
                tx[i] = value
        self._written = (ak, rk)

    # ------------------------------------------------------------------ commands
    def _read_commands(self) -> None:
        got = _newer(self.slots.command, self._cmd_version)
        if got is not None:
            self._cmd_version = got[0]
            self._command(got[1])
        override = _newer(self.slots.override, self._override_version)
        if override is not None:
            self._override_version = override[0]
            self.motion.set_override(float(override[1][0]))  # type: ignore[arg-type]
        if self._pending is not None:
            self._try_pending()

    def _command(self, values: tuple[object, ...]) -> None:
        kind, cmd_id = int(values[0]), int(values[1])  # type: ignore[call-overload]
        if kind == CommandKind.NONE:
            return
        if self.fault is not None:
            self._report_failure(cmd_id, self.fault, CONTROLLER)
            return
        if not self.correcting:
            if kind == CommandKind.HALT:
                self._report_done(cmd_id)
            else:
                self._report_failure(cmd_id, "the robot does not follow corrections (RSI_MOVECORR not active: allow the move first)")
            return
        if self.active_id:
            if self._active_kind == CommandKind.STREAM:  # how far it got: a resume goes on from there, never from its start
                self._emit(("progress", self.index, self.active_id, self.motion.stream_progress()))
            self._finish(False, f"superseded by command {cmd_id}", "stopped")
        if self._pending is not None:
            self._fail_pending(f"superseded by command {cmd_id}", "stopped")
        if kind == CommandKind.HALT:
            self.motion.halt()
            self._start(cmd_id, kind, ())
            return
        space = self._space_of(kind, values)
        if space is None:
            return
        motion = self.motion
        if self._ready_for(kind, values) and (space == motion.mode or (motion.mode != "stream" and motion.idle() and self._can_fold())):
            self._launch(values, space)
        else:
            motion.halt()
            self._pending = values
            self._pending_age = 0

    def _space_of(self, kind: int, values: tuple[object, ...]) -> str | None:
        cmd_id = int(values[1])  # type: ignore[call-overload]
        if kind == CommandKind.JOINT:
            if self._i_ak is None:
                self._report_failure(cmd_id, f"{self.config.source} has no AK correction; joint moves are impossible", "unsupported")
                return None
            return "joint"
        if kind == CommandKind.CART:
            if self._i_rk is None:
                self._report_failure(cmd_id, f"{self.config.source} has no RKorr correction; Cartesian moves are impossible", "unsupported")
                return None
            return "cart"
        if kind == CommandKind.STREAM:
            return "stream"
        self._report_failure(cmd_id, f"unknown command kind {kind}", "internal")
        return None

    def _can_fold(self) -> bool:
        return self.motion.quiet >= QUIET_CYCLES

    def _ready_for(self, kind: int, values: tuple[object, ...]) -> bool:
        """A stream can start only once its points have arrived through the pipe."""
        return kind != CommandKind.STREAM or int(values[2]) in self.staged  # type: ignore[call-overload]

    def _try_pending(self) -> None:
        assert self._pending is not None
        self._pending_age += 1
        values = self._pending
        kind, cmd_id = int(values[0]), int(values[1])  # type: ignore[call-overload]
        if not self._ready_for(kind, values):
            if self._pending_age > STREAM_ARRIVAL_CYCLES:
                self._pending = None
                self._report_failure(cmd_id, "the tool path never arrived", "internal")
            return
        if self.motion.mode != "stream" and self.motion.idle() and self._can_fold():
            self._pending = None
            self._launch(values, self._space_of(kind, values) or "joint")

    def _fail_pending(self, why: str, kind: str = CONTROLLER) -> None:
        assert self._pending is not None
        cmd_id = int(self._pending[1])  # type: ignore[call-overload]
        self._pending = None
        self._report_failure(cmd_id, why, kind)

    def _launch(self, values: tuple[object, ...], space: str) -> None:
        kind, cmd_id = int(values[0]), int(values[1])  # type: ignore[call-overload]
        v = np.array(values[2:9], dtype=float)
        limits = np.array(values[9:13], dtype=float)
        motion = self.motion
        if kind == CommandKind.STREAM:
            path = self.staged.pop(int(v[0]))
            if (path.space == "joint" and self._i_ak is None) or (path.space != "joint" and self._i_rk is None):
                self._report_failure(cmd_id, f"the configuration has no correction for a {path.space} path", "unsupported")
                return
            refused = motion.launch_stream(path, limits)
            if refused is not None:
                self._report_failure(cmd_id, refused, "unreachable")
                return
            last = path.points[-1]
            self._start(cmd_id, kind, (last,) if path.space == "joint" else (last[:3].copy(), abc_to_matrix(*last[3:])))
            return
        if not np.all(np.isfinite(v)) or not np.all(np.isfinite(limits)):
            self._report_failure(cmd_id, "command values must be finite", "internal")
            return
        try:
            if space == "joint":
                target = v[:6]
                lower, upper = np.array(self.link.lower), np.array(self.link.upper)
                outside = np.nonzero((target < lower - 1e-9) | (target > upper + 1e-9))[0]
                if outside.size:
                    i = int(outside[0])
                    self._report_failure(cmd_id, f"A{i + 1} target {math.degrees(target[i]):.3f} deg is outside its limits", "joint_limit")
                    return
                # limits: speed (rad/s) for every axis, acceleration, and a fraction of each axis's own maximum
                speed = np.minimum(limits[0], motion.vmax * limits[2]) if limits[2] > 0 else np.full(6, limits[0])
                motion.launch_joint(target, speed, float(limits[1]))
                self._start(cmd_id, kind, (target,))
            else:
                rotation = _quat_matrix(v[3:7])
                motion.launch_cart(v[:3], rotation, (limits[0], limits[1], limits[2], limits[3]))
                self._start(cmd_id, kind, (v[:3].copy(), rotation))
        except ValueError as error:
            self._report_failure(cmd_id, str(error), "internal")

    def _read_flags(self) -> None:
        got = _newer(self.slots.flags, self._flags_version)
        if got is not None:
            self._flags_version = got[0]
            self._flags = int(got[1][0])  # type: ignore[call-overload]
            for bit, i in enumerate(self._recv_bools):
                self.tx[i] = bool(self._flags >> bit & 1)
            self._emit(("flags", self.index, self._flags))  # leaves after the reply that carries them

    # ------------------------------------------------------------------ completion
    def _start(self, cmd_id: int, kind: int, target: tuple[np.ndarray, ...]) -> None:
        self.active_id = cmd_id
        self._active_kind = kind
        self._active_target = target
        self._settle = 0

    def _check_done(self) -> None:
        if not self.active_id or not self.motion.idle():
            return
        if self._active_kind == CommandKind.HALT:
            self._finish(True, "")
            return
        self._settle += 1
        error = self._tracking_error()
        if error is None:
            self._finish(True, "")
        elif self._settle > self.link.settle_cycles:
            self._finish(False, f"the robot did not reach the target within {self.link.settle_cycles} cycles: {error}")

    def _tracking_error(self) -> str | None:
        """None when the actual position is on the target, else how far off it is."""
        if len(self._active_target) == 1:
            actual = self._axes(self._i_aipos)
            off = np.abs(actual - self._active_target[0])
            if float(np.max(off)) <= self.link.joint_tolerance:
                return None
            i = int(np.argmax(off))
            return f"A{i + 1} is {math.degrees(float(off[i])):.4f} deg off"
        if self._i_rist is not None:
            p, r = self._pose(self._i_rist)
        else:  # no RIst sent: the TCP of the actual axes, by our kinematics
            pose = self.motion.arm.fk(self._axes(self._i_aipos))
            p, r = pose[:3, 3], pose[:3, :3]
        shift = float(np.linalg.norm(p - self._active_target[0]))
        turn = rotation_angle(r @ self._active_target[1].T)
        if shift <= self.link.position_tolerance and turn <= self.link.rotation_tolerance:
            return None
        return f"the TCP is {shift * 1000:.3f} mm and {math.degrees(turn):.4f} deg off"

    def _finish(self, ok: bool, message: str, kind: str = CONTROLLER) -> None:
        """End the active command; ``kind`` (a FaultKind value) says why it failed."""
        self.done_id = self.active_id
        self.done_ok = 1 if ok else -1
        self._emit(("done", self.index, self.active_id, ok, message, "" if ok else kind))
        self.active_id = 0
        self._active_kind = CommandKind.NONE

    def _report_done(self, cmd_id: int) -> None:
        self.done_id = cmd_id
        self.done_ok = 1
        self._emit(("done", self.index, cmd_id, True, "", ""))

    def _report_failure(self, cmd_id: int, message: str, kind: str = CONTROLLER) -> None:
        self.done_id = cmd_id
        self.done_ok = -1
        self._emit(("done", self.index, cmd_id, False, message, kind))

    # ------------------------------------------------------------------ after the reply
    def after_reply(self, t_ns: int) -> None:
        """Publish the cycle: shared record, feedback file, events.  Off the latency path."""
        rx = self.rx
        if not self.connected:
            self.connected = True
            self._emit(("connected", self.index, self.ipoc))
        if self.lost:
            self.lost = False
            self._emit(("resumed", self.index, self.ipoc))
        delay = int(rx[self._i_delay]) if self._i_delay is not None else 0  # type: ignore[call-overload]
        if delay != self.delay:
            self.delay = delay
            self._emit(("late", self.index, delay, self.ipoc))
        digouts = bits([bool(rx[i]) for i in self._send_bools])
        if digouts != self._digouts:
            self._digouts = digouts
            self._emit(("io", self.index, digouts, self.cycles))
        inputs = self.io.changed(rx)
        if inputs is not None:
            self._emit(("inputs", self.index, inputs, self.cycles))
        status = Status.CONNECTED
        motion = self.motion
        if self.correcting:
            status |= Status.CORRECTING
            motion.update_commanded()
            commanded = motion.commanded.tolist()
        else:
            commanded = self._axes(self._i_aspos or self._i_aipos).tolist()  # nothing commanded yet: what the robot holds
        if not motion.idle():
            status |= Status.MOVING
        values = [float(rx[i]) * s if i >= 0 else 0.0 for i, s in zip(self._feedback_map, self._state_scale)]  # type: ignore[arg-type]
        self.slots.state.write(
            t_ns, self.ipoc, self.cycles, delay, status, digouts, self.done_id, self.done_ok, self.active_id, self.rejected,
            motion.clamped, *values, *commanded,
        )
        if self._logger.enabled(self.index):
            tcp = (rx[i] for i in self._i_rist) if self._i_rist is not None else (0.0,) * 6
            self._logger.push(self.index, (t_ns, self.ipoc, delay, *tcp, *(rx[i] for i in self._i_aipos)))  # type: ignore[arg-type]
        if self._wakes and self.cycles >= self._wakes[0]:
            while self._wakes and self.cycles >= self._wakes[0]:
                self._wakes.pop(0)
            self._emit(("tick", self.index, self.cycles, self.ipoc))
        elif self.cycles % self._heartbeat == 0:
            self._emit(("tick", self.index, self.cycles, self.ipoc))
        self.flush_events()

    def flush_events(self) -> None:
        for event in self._events:
            self._send_event(event)
        self._events.clear()

    def wake_at(self, cycle: int) -> None:
        self._wakes.append(cycle)
        self._wakes.sort()

    def mark_lost(self, why: str) -> None:
        if not self.lost:
            self.lost = True
            self._end(why, "timeout")
            state = self.slots.state.try_read()
            if state is not None:
                values = list(state[1])
                values[4] = int(values[4]) | Status.LOST  # type: ignore[call-overload]
                self.slots.state.write(*values)
            self.flush_events()


def _six(index: dict[str, int], element: str, names: str) -> list[int] | None:
    """The packet indices of ``element``'s six values, or None when the configuration does not send them all."""
    keys = [f"{element}.{name}" for name in names.split()]
    return [index[k] for k in keys] if all(k in index for k in keys) else None


def _newer(slot: SeqSlot, seen: int) -> tuple[int, tuple[object, ...]] | None:
    """A shared record written since version ``seen``, or None (unchanged, or caught mid-write:
    the loop never spins; it takes the record next cycle)."""
    version = slot.version()
    if version == seen or version & 1:
        return None
    return slot.try_read()


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(q))
    if not n > 0.0:
        raise ValueError("the target orientation quaternion is zero")
    x, y, z, w = (float(v) / n for v in q)
    return quaternion_to_matrix(x, y, z, w)
