"""The RSI external system: the loop that answers every ``<Rob>`` packet within the cycle.

ITRA's RSI-Manager Thread (seed 003): one UDP socket serves every robot, each known by the
address its packets come from; each packet is timestamped, parsed, answered at once with its
IPOC echoed, and only then published to the application.  Between the parse and the reply the
loop does the one thing that cannot wait: it reads the latest command, steps the robot's online
trajectory generator (or the next point of a streamed tool path) and writes the correction.

Built never to miss a deadline:

* driven by packet arrival -- the robot's clock -- never by sleeping; the receive wait is bounded
  (``poll``) only so the loop can notice silence and its control pipe;
* commands and feedback go through seqlocked shared records (:mod:`.slots`): setters never wait
  for the loop and the loop never waits for them (a record caught mid-write is read next cycle);
* the reply is one formatting of a precompiled byte template; the receive buffer is reused;
* work that may stall -- files, events to the application, garbage collection -- comes after the
  reply or on other threads; in its own process (:mod:`.runner`) the loop freezes and disables the
  garbage collector and shortens the interpreter's switch interval, so the feedback writer cannot
  hold the GIL across a cycle.

Corrections follow the controller's RSI context: *absolute* (``AK`` = set point - position where
RSI_MOVECORR began; ``RKorr`` = pose - base pose) or *relative* (increments per cycle).  Joint
moves drive ``AK``; Cartesian moves drive ``RKorr`` on top of the joint correction.  Changing
space brakes the running generator, waits until the robot's set point has caught up, and folds
the corrections (absolute mode: ``AK`` takes the robot's set point, ``RKorr`` returns to zero, in
one packet, so the set point does not move).
"""
from __future__ import annotations

import gc
import math
import os
import socket
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from core_functions.geometry import quaternion_to_matrix
from core_functions.robots import KUKA_KR
from robot_bridges.kuka_rsi.codec import MAX_PACKET_BYTES, PacketCodec, PacketError, Value
from robot_bridges.kuka_rsi.config import FEEDBACK_KEYS, ConfigError, RsiConfig, RsiRoles, default_config
from robot_bridges.kuka_rsi.feedback import FeedbackLogger
from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, matrix_to_abc, rotation_angle
from robot_bridges.kuka_rsi.otg import CartesianOTG, VectorOTG
from robot_bridges.kuka_rsi.pipe import FramedPipe, PipeClosed
from robot_bridges.kuka_rsi.slots import CommandKind, RobotSlots, Status, bits
from robot_bridges.kuka_rsi.streaming import ToolPath

_DEG = math.pi / 180.0
#: Cycles the set point must have been still before the generator may change space.
QUIET_CYCLES = 2
#: Cycles a stream command waits for its points to arrive through the pipe.
STREAM_ARRIVAL_CYCLES = 250


@dataclass(frozen=True)
class RobotLink:
    """One robot controller served by the loop."""

    name: str
    host: str  # the IP its packets come from; packets from anywhere else are ignored
    port: int | None = None  # and the port, when several controllers share an IP (simulators)
    config: RsiConfig | None = None  # None: the package's default configuration
    roles: RsiRoles = RsiRoles()
    correction_mode: str = "absolute"  # must match the RSI context: "absolute" or "relative"
    cycle_ms: int = 4
    joint_tolerance: float = 1e-4  # rad: a joint move is done when every actual axis is this close
    position_tolerance: float = 1e-4  # m: a Cartesian move is done when the actual TCP is this close
    rotation_tolerance: float = 1e-3  # rad
    settle_cycles: int = 500  # cycles after the generator stopped before "did not reach" is reported
    lower: tuple[float, ...] = tuple(j.lower for j in KUKA_KR.group("arm").joints)
    upper: tuple[float, ...] = tuple(j.upper for j in KUKA_KR.group("arm").joints)
    max_joint_speed: tuple[float, ...] = tuple(j.max_velocity for j in KUKA_KR.group("arm").joints)

    def __post_init__(self) -> None:
        if self.correction_mode not in ("absolute", "relative"):
            raise ValueError(f"robot {self.name}: correction mode is 'absolute' or 'relative', not {self.correction_mode!r}")
        if self.cycle_ms not in (4, 12):
            raise ValueError(f"robot {self.name}: RSI runs at 4 ms or 12 ms, not {self.cycle_ms}")

    def rsi_config(self) -> RsiConfig:
        return self.config if self.config is not None else default_config()


@dataclass(frozen=True)
class LoopSettings:
    host: str = "127.0.0.1"
    port: int = 49152
    poll: float = 0.02  # s: longest receive wait before the loop looks at the time and its pipe
    silence_timeout: float = 0.1  # s without packets after the first: the robot is lost
    connect_timeout: float = 10.0  # s to the first packet of each robot
    heartbeat_cycles: int = 25
    max_packet: int = MAX_PACKET_BYTES
    gc_control: bool = False  # freeze + disable the collector (only where the loop owns the process)
    gc_every: int = 2500  # cycles between young-generation collections in the slack after a reply
    switch_interval: float | None = None  # s; set sys.setswitchinterval (process mode)
    realtime_priority: int | None = None  # try SCHED_FIFO at this priority (needs CAP_SYS_NICE)
    record_busy: bool = False  # keep every receive-to-send time (benchmarks)


def _require_feedback(config: RsiConfig, name: str) -> None:
    missing = [k for k in FEEDBACK_KEYS if not config.has_send(k)]
    if missing:
        raise ConfigError(
            f"robot {name}: {config.source} must send DEF_RIst, DEF_RSol, DEF_AIPos and DEF_ASPos "
            f"(missing {', '.join(missing[:4])})"
        )


class Channel:
    """Everything the loop knows and does for one robot."""

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
        _require_feedback(config, link.name)
        if config.onlysend:
            raise ConfigError(f"robot {link.name}: {config.source} has ONLYSEND TRUE; the robot would ignore every reply")
        self.index = index
        self.link = link
        self.slots = slots
        self._send_event = events
        self._events: list[tuple[object, ...]] = []
        self._logger = logger
        self.rob = PacketCodec.rob(config)
        self.sen = PacketCodec.sen(config)
        self.rx: list[Value] = list(self.rob.defaults)
        self.tx: list[Value] = list(self.sen.defaults)
        self.dt = link.cycle_ms / 1000.0
        roles = link.roles
        ri = self.rob.index
        self._i_rist = [ri[f"RIst.{a}"] for a in "XYZABC"]
        self._i_rsol = [ri[f"RSol.{a}"] for a in "XYZABC"]
        self._i_aipos = [ri[f"AIPos.A{i}"] for i in range(1, 7)]
        self._i_aspos = [ri[f"ASPos.A{i}"] for i in range(1, 7)]
        self._i_delay = ri.get("Delay.D")
        self._feedback_map = [ri[k] for k in FEEDBACK_KEYS]
        self._state_scale = [1e-3, 1e-3, 1e-3, _DEG, _DEG, _DEG] * 2 + [_DEG] * 12
        self._send_bools = [i for i, f in enumerate(self.rob.fields) if f.type == "BOOL"]
        self._recv_bools = [i for i, f in enumerate(self.sen.fields) if f.type == "BOOL"]
        self._i_ak = [self.sen.index[k] for k in roles.axis_correction] if roles.axis(config) else None
        self._i_rk = [self.sen.index[k] for k in roles.cart_correction] if roles.cartesian(config) else None
        self._i_correcting = ri[roles.correction_active] if roles.handshake(config) else None
        self.relative = link.correction_mode == "relative"
        self.lower = np.array(link.lower)
        self.upper = np.array(link.upper)
        self.vmax = np.array(link.max_joint_speed)
        # motion state
        self.joint = VectorOTG([1] * 6, self.dt)
        self.cart = CartesianOTG(self.dt)
        self.mode = "joint"  # which generator drives the corrections: joint, cart, stream
        self.q_ref: np.ndarray | None = None
        self.base_p = np.zeros(3)
        self.base_r = np.eye(3)
        self.ak = np.zeros(6)  # deg, the absolute axis correction
        self.rk = np.zeros(6)  # mm / deg, the absolute Cartesian correction
        self._sent_ak = np.zeros(6)
        self._sent_rk = np.zeros(6)
        self.quiet = 0
        self._moved = False
        self.correcting = False
        self.active_id = 0
        self._active_kind = CommandKind.NONE
        self._active_target: tuple[np.ndarray, ...] = ()
        self._settle = 0
        self._pending: tuple[object, ...] | None = None
        self._pending_age = 0
        self._cmd_version = slots.command.version() & ~1
        self._flags_version = slots.flags.version() & ~1
        self._flags = 0
        self.staged: dict[int, ToolPath] = {}
        self._stream: np.ndarray | None = None
        self._stream_pos = 0
        self._stream_space = "joint"
        self.withhold = 0
        self.withheld = 0
        self.catch_ups = 0  # times the generator restarted from the robot's set point
        self._robot_delay = -1
        # bookkeeping
        self.cycles = 0
        self.ipoc = 0
        self.delay = 0
        self.rejected = 0
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
                self._catch_up()
                self._step()
            self._fill_tx()
        if self.withhold:
            self.withhold -= 1
            self.withheld += 1
            return None
        return self.sen.encode(self.tx, ipoc)

    def _emit(self, event: tuple[object, ...]) -> None:
        """Queue an event; it leaves after the reply and after the shared record of this cycle
        is written, so whoever it wakes reads a state at least as new as the event."""
        self._events.append(event)

    def _track_correcting(self) -> None:
        now = True if self._i_correcting is None else bool(self.rx[self._i_correcting])
        if now and not self.correcting:
            self._begin()
        elif self.correcting and not now:
            self._end("the robot left RSI_MOVECORR (real-time control ended)")
        self.correcting = now

    def _begin(self) -> None:
        """RSI_MOVECORR began: corrections are measured from here."""
        q = self._axes(self._i_aspos)
        self.q_ref = q
        self.joint.reset(q)
        p, r = self._pose(self._i_rsol)
        self.base_p, self.base_r = p, r
        self.cart.reset(p, r)
        self.ak = np.zeros(6)
        self.rk = np.zeros(6)
        self._sent_ak = self.ak
        self._sent_rk = self.rk
        self._moved = True
        self.mode = "joint"
        self.quiet = 0

    def _end(self, why: str, kind: str = "controller") -> None:
        self.joint.reset(self.joint.position)
        self.cart.reset(self.cart.position, self.cart.rotation)
        self._stream = None
        if self.mode == "stream":
            self.mode = self._stream_space
        if self.active_id:
            self._finish(False, why, kind)
        if self._pending is not None:
            self._fail_pending(why, kind)

    def _catch_up(self) -> None:
        """When the robot counted late replies, start again from where it really is.

        A reply that came late was never applied: the robot held its set point (HOLDON) while the
        generator went on, and the next reply would make up the difference in one cycle -- a jump
        beyond the axes' speed.  With absolute corrections the robot's set point (ASPos / RSol)
        says exactly where it stands: the generator restarts there from rest, toward the same
        target; a stream goes back to the point the robot holds.  (Relative corrections cannot be
        caught up: what a late increment did depends on HOLDON.)
        """
        if self._i_delay is None:
            return
        delay = int(self.rx[self._i_delay])  # type: ignore[call-overload]
        missed = delay - self._robot_delay if self._robot_delay >= 0 else 0
        self._robot_delay = delay
        if missed <= 0 or self.relative:
            return
        self.catch_ups += 1
        if self.mode == "joint" and not self.joint.done:
            self.joint.resync(self._axes(self._i_aspos))
        elif self.mode == "cart" and not self.cart.done:
            self.cart.resync(*self._pose(self._i_rsol))
        elif self.mode == "stream" and self._stream is not None:
            self._stream_pos = self._held_point()

    def _held_point(self) -> int:
        """The index after the stream point the robot's set point is on (searching back a second)."""
        assert self._stream is not None
        lo = max(0, self._stream_pos - 250)
        window = self._stream[lo : self._stream_pos]
        if self._stream_space == "joint":
            distance = np.max(np.abs(window - self._axes(self._i_aspos)), axis=1)
        else:
            distance = np.linalg.norm(window[:, :3] - self._pose(self._i_rsol)[0], axis=1)
        return lo + int(np.argmin(distance)) + 1

    def _axes(self, idx: Sequence[int]) -> np.ndarray:
        return np.array([float(self.rx[i]) * _DEG for i in idx])

    def _pose(self, idx: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        x, y, z, a, b, c = (float(self.rx[i]) for i in idx)
        return np.array([x / 1000.0, y / 1000.0, z / 1000.0]), abc_to_matrix(a * _DEG, b * _DEG, c * _DEG)

    # ------------------------------------------------------------------ commands
    def _read_commands(self) -> None:
        version = self.slots.command.version()
        if version != self._cmd_version and not version & 1:
            got = self.slots.command.try_read()
            if got is not None:
                self._cmd_version = got[0]
                self._command(got[1])
        if self._pending is not None:
            self._try_pending()

    def _command(self, values: tuple[object, ...]) -> None:
        kind, cmd_id = int(values[0]), int(values[1])  # type: ignore[call-overload]
        if kind == CommandKind.NONE:
            return
        if not self.correcting:
            if kind == CommandKind.HALT:
                self._report_done(cmd_id)
            else:
                self._report_failure(cmd_id, "the robot does not follow corrections (RSI_MOVECORR not active: allow the move first)")
            return
        if self.active_id:
            self._finish(False, f"superseded by command {cmd_id}", "stopped")
        if self._pending is not None:
            self._fail_pending(f"superseded by command {cmd_id}", "stopped")
        if kind == CommandKind.HALT:
            self._halt()
            self._start(cmd_id, kind, ())
            return
        space = self._space_of(kind, values)
        if space is None:
            return
        ready = self._ready_for(kind, values)
        if ready and (space == self.mode or (self.mode != "stream" and self._generator_idle() and self._can_fold())):
            self._launch(values, space)
        else:
            self._halt()
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

    def _generator_idle(self) -> bool:
        return self.joint.done if self.mode == "joint" else self.cart.done

    def _can_fold(self) -> bool:
        return self.quiet >= QUIET_CYCLES

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
        if self.mode != "stream" and self._generator_idle() and self._can_fold():
            self._pending = None
            self._launch(values, self._space_of(kind, values) or "joint")

    def _fail_pending(self, why: str, kind: str = "controller") -> None:
        assert self._pending is not None
        cmd_id = int(self._pending[1])  # type: ignore[call-overload]
        self._pending = None
        self._report_failure(cmd_id, why, kind)

    def _launch(self, values: tuple[object, ...], space: str) -> None:
        kind, cmd_id = int(values[0]), int(values[1])  # type: ignore[call-overload]
        v = np.array(values[2:9], dtype=float)
        limits = np.array(values[9:13], dtype=float)
        if kind == CommandKind.STREAM:
            self._launch_stream(cmd_id, int(v[0]), limits)
            return
        if not np.all(np.isfinite(v)) or not np.all(np.isfinite(limits)):
            self._report_failure(cmd_id, "command values must be finite", "internal")
            return
        try:
            if space == "joint":
                target = v[:6]
                outside = np.nonzero((target < self.lower - 1e-9) | (target > self.upper + 1e-9))[0]
                if outside.size:
                    i = int(outside[0])
                    self._report_failure(cmd_id, f"A{i + 1} target {math.degrees(target[i]):.3f} deg is outside its limits", "joint_limit")
                    return
                self._fold_to("joint")
                # limits: speed (rad/s) for every axis, acceleration, and a fraction of each axis's own maximum
                speed = np.minimum(limits[0], self.vmax * limits[2]) if limits[2] > 0 else np.minimum(limits[0], self.vmax)
                self.joint.set_target(target, speed, limits[1])
                self._start(cmd_id, kind, (target,))
            else:
                rotation = _quat_matrix(v[3:7])
                self._fold_to("cart")
                self.cart.set_target(v[:3], rotation, (limits[0], limits[1], limits[2], limits[3]))
                self._start(cmd_id, kind, (v[:3].copy(), rotation))
        except ValueError as error:
            self._report_failure(cmd_id, str(error), "internal")

    def _launch_stream(self, cmd_id: int, key: int, limits: np.ndarray) -> None:
        """Play a staged path; ``limits[0]``/``limits[2]`` bound the first Cartesian step (m/s, rad/s)."""
        path = self.staged.pop(key)
        space = "joint" if path.space == "joint" else "cart"
        if space == "joint" and self._i_ak is None or space == "cart" and self._i_rk is None:
            self._report_failure(cmd_id, f"the configuration has no correction for a {path.space} path", "unsupported")
            return
        self._fold_to(space)
        first = path.points[0]
        if space == "joint":
            too_far = bool(np.any(np.abs(first - self.joint.position) / self.dt > self.vmax * (1 + 1e-9)))
        else:
            shift = float(np.linalg.norm(first[:3] - self.cart.position)) / self.dt
            turn = rotation_angle(abc_to_matrix(*first[3:]) @ self.cart.rotation.T) / self.dt
            too_far = shift > limits[0] * (1 + 1e-9) or turn > limits[2] * (1 + 1e-9)
        if too_far:
            self._report_failure(cmd_id, f"{path.where(0)}: the first point is more than one cycle's motion away from the robot", "unreachable")
            return
        self._stream = path.points
        self._stream_pos = 0
        self._stream_space = space
        self.mode = "stream"
        last = path.points[-1]
        target = (last,) if space == "joint" else (last[:3].copy(), abc_to_matrix(*last[3:]))
        self._start(cmd_id, CommandKind.STREAM, target)

    def _fold_to(self, space: str) -> None:
        """Hand the corrections over to the other generator without moving the set point."""
        if space == self.mode:
            return
        assert self.q_ref is not None
        if space == "joint":
            # The robot's set point already holds every correction sent; the axis correction
            # takes all of it and the Cartesian one returns to zero, so the set point stays put.
            q = self._axes(self._i_aspos)
            self.joint.reset(q)
            self.ak = (q - self.q_ref) / _DEG
            self.rk = np.zeros(6)
        else:
            p, r = self._pose(self._i_rsol)
            self.cart.reset(p, r)
            self.base_p, self.base_r = p, r
            self.rk = np.zeros(6)
        if self.relative:
            # Increments only: nothing has moved, so nothing may be sent for the fold itself.
            self._sent_ak = self.ak
            self._sent_rk = self.rk
        self._moved = True
        self.mode = space

    def _halt(self) -> None:
        if self.mode == "stream":
            # A stream cannot brake on its own: its generator takes over from the last point.
            self._stop_stream()
        if self.mode == "joint":
            self.joint.halt()
        else:
            self.cart.halt()

    def _stop_stream(self) -> None:
        assert self._stream is not None
        # Velocity of the last step, so the generator brakes instead of stopping dead.
        k = max(1, self._stream_pos)
        here = self._stream[k - 1]
        before = self._stream[k - 2] if k >= 2 else here
        velocity = (here - before) / self.dt
        if self._stream_space == "joint":
            self.joint.reset(here, velocity)
        else:
            self.cart.reset(here[:3], abc_to_matrix(*here[3:]), np.concatenate((velocity[:3], np.zeros(3))))
        self._stream = None
        self.mode = self._stream_space

    # ------------------------------------------------------------------ stepping
    def _step(self) -> None:
        if self.mode == "stream":
            self._step_stream()
        elif self.mode == "joint":
            if not self.joint.done:
                self.joint.step()
                self.ak = (self.joint.position - self.q_ref) / _DEG  # type: ignore[operator]
                self._moved = True
        elif not self.cart.done:
            self.cart.step()
            self._cart_correction(self.cart.position, self.cart.rotation)
        self._check_done()

    def _cart_correction(self, p: np.ndarray, r: np.ndarray) -> None:
        a, b, c = matrix_to_abc(r @ self.base_r.T)
        d = (p - self.base_p) * 1000.0
        self.rk = np.array([d[0], d[1], d[2], a / _DEG, b / _DEG, c / _DEG])
        self._moved = True

    def _step_stream(self) -> None:
        assert self._stream is not None
        point = self._stream[self._stream_pos]
        self._stream_pos += 1
        if self._stream_space == "joint":
            self.joint.position = point.copy()
            self.ak = (point - self.q_ref) / _DEG  # type: ignore[operator]
            self._moved = True
        else:
            self.cart.position = point[:3].copy()
            self.cart.rotation = abc_to_matrix(*point[3:])
            self._cart_correction(self.cart.position, self.cart.rotation)
        if self._stream_pos >= len(self._stream):
            self._stream = None
            self.mode = self._stream_space
            if self.mode == "joint":
                self.joint.reset(self.joint.position)
            else:
                self.cart.reset(self.cart.position, self.cart.rotation)

    def _fill_tx(self) -> None:
        """Write the corrections into the reply, when they changed; count the quiet cycles.

        ``ak`` and ``rk`` are replaced, never changed in place, and every assignment sets
        ``_moved``; so "sent" can keep a reference instead of a copy.
        """
        tx = self.tx
        if self._moved:
            self._moved = False
            self.quiet = 0
            if self._i_ak is not None:
                out = self.ak - self._sent_ak if self.relative else self.ak
                for i, value in zip(self._i_ak, out.tolist()):
                    tx[i] = value
            if self._i_rk is not None:
                out = self._relative_rk() if self.relative else self.rk
                for i, value in zip(self._i_rk, out.tolist()):
                    tx[i] = value
            self._sent_ak, self._sent_rk = self.ak, self.rk
        else:
            self.quiet += 1
            if self.relative and self.quiet == 1:  # the increments were sent once: none now
                for i in (self._i_ak or []) + (self._i_rk or []):
                    tx[i] = 0.0
        self._read_flags()

    def _relative_rk(self) -> np.ndarray:
        """The increment from the last sent Cartesian correction: translation and rotation."""
        before = abc_to_matrix(*(self._sent_rk[3:] * _DEG))
        now = abc_to_matrix(*(self.rk[3:] * _DEG))
        a, b, c = matrix_to_abc(now @ before.T)
        d = self.rk[:3] - self._sent_rk[:3]
        return np.array([d[0], d[1], d[2], a / _DEG, b / _DEG, c / _DEG])

    def _read_flags(self) -> None:
        version = self.slots.flags.version()
        if version != self._flags_version and not version & 1:
            got = self.slots.flags.try_read()
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
        if not self.active_id:
            return
        if self.mode == "stream" or not self._generator_idle():
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
        p, r = self._pose(self._i_rist)
        shift = float(np.linalg.norm(p - self._active_target[0]))
        turn = rotation_angle(r @ self._active_target[1].T)
        if shift <= self.link.position_tolerance and turn <= self.link.rotation_tolerance:
            return None
        return f"the TCP is {shift * 1000:.3f} mm and {math.degrees(turn):.4f} deg off"

    def _finish(self, ok: bool, message: str, kind: str = "controller") -> None:
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

    def _report_failure(self, cmd_id: int, message: str, kind: str = "controller") -> None:
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
        status = Status.CONNECTED
        if self.correcting:
            status |= Status.CORRECTING
        if self.mode == "stream" or not self._generator_idle():
            status |= Status.MOVING
        values = [float(rx[i]) * s for i, s in zip(self._feedback_map, self._state_scale)]  # type: ignore[arg-type]
        self.slots.state.write(
            t_ns, self.ipoc, self.cycles, delay, status, digouts, self.done_id, self.done_ok, self.active_id, self.rejected, *values
        )
        if self._logger.enabled(self.index):
            self._logger.push(self.index, (t_ns, self.ipoc, delay, *(rx[i] for i in self._i_rist), *(rx[i] for i in self._i_aipos)))  # type: ignore[arg-type]
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


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(q))
    if not n > 0.0:
        raise ValueError("the target orientation quaternion is zero")
    x, y, z, w = (float(v) / n for v in q)
    return quaternion_to_matrix(x, y, z, w)


@dataclass
class LoopStats:
    packets: int = 0
    foreign: int = 0
    rejected: int = 0
    oversized: int = 0
    stale: int = 0  # packets skipped because a newer one from the same robot was already waiting
    max_busy_ns: int = 0  # longest receive-to-send time
    busy_ns: list[int] = field(default_factory=list)  # every receive-to-send time, when recording


class RsiLoop:
    """The loop over one socket for every robot; runs on a thread or as a process's main."""

    def __init__(
        self,
        links: Sequence[RobotLink],
        settings: LoopSettings,
        slots: Sequence[RobotSlots],
        pipe: FramedPipe,
        now_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        """``now_ns`` is the timestamp source (ITRA's performance counter), injected so tests
        can drive it; the default is the system-wide monotonic clock, the same in every
        process, so the application can compare its own timestamps with the loop's."""
        if len(slots) != len(links):
            raise ValueError("one set of shared records per robot")
        self.links = tuple(links)
        self.settings = settings
        self.pipe = pipe
        self.now_ns = now_ns
        self.logger = FeedbackLogger(len(links))
        self.channels = [
            Channel(i, link, slots[i], self._emit, self.logger, settings.heartbeat_cycles) for i, link in enumerate(links)
        ]
        self._by_host_port = {(l.host, l.port): c for l, c in zip(links, self.channels) if l.port is not None}
        self._by_host = {l.host: c for l, c in zip(links, self.channels) if l.port is None}
        self.stats = LoopStats()
        self._shutdown = False
        self._warned: dict[str, int] = {}

    def _emit(self, message: tuple[object, ...]) -> None:
        try:
            self.pipe.send(message)
        except PipeClosed:
            self._shutdown = True  # the application is gone

    def _warn(self, key: str, text: str) -> None:
        """Report the first occurrence of a kind of bad datagram, then every 1000th."""
        n = self._warned.get(key, 0) + 1
        self._warned[key] = n
        if n == 1 or n % 1000 == 0:
            self._emit(("warn", -1, f"{text} ({n} so far)"))

    # ------------------------------------------------------------------------------ run
    def run(self) -> None:
        """Bind, serve until told to stop; every failure is reported through the pipe."""
        sock = None
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind((self.settings.host, self.settings.port))
            host, port = sock.getsockname()[:2]
            self._emit(("ready", host, port, self._tune()))
            self._serve(sock)
        except OSError as error:
            where = f"{self.settings.host}:{self.settings.port}"
            self._emit(("fault", -1, "connection", f"RSI socket {where}: {error.strerror or error}"))
        except Exception as error:  # noqa: BLE001 - a defect must reach the application, not vanish
            self._emit(("fault", -1, "internal", f"RSI loop crashed: {type(error).__name__}: {error}\n{traceback.format_exc()}"))
        finally:
            if sock is not None:
                sock.close()
            self.logger.close()
            self._emit(("stopped",))
            try:
                self.pipe.flush()
            except PipeClosed:
                pass

    def _tune(self) -> str:
        """Apply the process-wide settings; say what took effect."""
        notes = []
        s = self.settings
        if s.switch_interval is not None:
            sys.setswitchinterval(s.switch_interval)
            notes.append(f"switch interval {s.switch_interval * 1e6:.0f} us")
        if s.gc_control:
            gc.collect()
            gc.freeze()
            gc.disable()
            notes.append("gc frozen and disabled")
        if s.realtime_priority is not None:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(s.realtime_priority))
                # The saving thread shares the GIL: preempted by ordinary work while holding it,
                # it would hold the loop back too (priority inversion).  Just below the loop, it cannot be.
                writer = max(1, s.realtime_priority - 1)
                os.sched_setscheduler(self.logger.native_id, os.SCHED_FIFO, os.sched_param(writer))
                notes.append(f"SCHED_FIFO {s.realtime_priority} (saving thread {writer})")
            except (PermissionError, OSError) as error:
                notes.append(f"no real-time priority ({error.strerror or error})")
        return ", ".join(notes) or "defaults"

    def _serve(self, sock: socket.socket) -> None:
        s = self.settings
        sock.settimeout(s.poll)
        # The same socket without Python's timeout emulation, to take what is already waiting.
        drain = socket.socket(fileno=os.dup(sock.fileno()))
        drain.setblocking(False)
        buf = bytearray(s.max_packet + 1)
        view = memoryview(buf)
        started = self.now_ns()
        gc_every = s.gc_every if s.gc_control else 0
        try:
            while not self._shutdown:
                try:
                    n, addr = sock.recvfrom_into(buf)
                except TimeoutError:
                    self._idle(started)
                    continue
                except ConnectionRefusedError:
                    continue  # ICMP for an earlier reply: that robot is gone; silence will tell
                batch = [(bytes(view[:n]), addr)]
                while True:
                    try:
                        n, addr = drain.recvfrom_into(buf)
                    except (BlockingIOError, ConnectionRefusedError):
                        break
                    batch.append((bytes(view[:n]), addr))
                t = self.now_ns()
                for channel, ipoc, source in self._packets(batch):
                    self._answer(sock, channel, ipoc, source, t)
                self._service(started)
                if gc_every and self.stats.packets % gc_every < len(batch):
                    gc.collect(0)  # in the slack after a reply, never before one
        finally:
            drain.close()

    def _packets(self, batch: list[tuple[bytes, tuple[str, int]]]) -> list[tuple[Channel, int, tuple[str, int]]]:
        """The packets of a batch of datagrams, decoded, and of each robot only the newest.

        More than one packet from a robot means the loop was held up and the robot has moved on:
        the older packet is late already, and answering it would step the generator for a cycle
        the robot has counted late -- a jump in the set point when the newest reply lands.
        Foreign, oversized and malformed datagrams are counted and reported, never answered.
        """
        s, stats = self.settings, self.stats
        packets: list[tuple[Channel, int, tuple[str, int]]] = []
        for data, addr in batch:
            channel = self._by_host_port.get(addr[:2]) or self._by_host.get(addr[0])
            if channel is None:
                stats.foreign += 1
                self._warn("foreign", f"ignored a datagram from {addr[0]}:{addr[1]}, which is not a configured robot")
                continue
            if len(data) > s.max_packet:
                stats.oversized += 1
                channel.rejected += 1
                self._warn("oversized", f"rejected a datagram over {s.max_packet} bytes from {channel.link.name}")
                continue
            try:
                ipoc = channel.rob.decode_into(data, channel.rx)  # a later packet overwrites an earlier one
            except PacketError as error:
                stats.rejected += 1
                channel.rejected += 1
                self._warn(f"bad {channel.index}", f"rejected a packet from {channel.link.name}: {error}")
                continue
            packets.append((channel, ipoc, addr))
        if len(packets) > 1:
            newest = {id(channel): i for i, (channel, _, _) in enumerate(packets)}
            kept = [p for i, p in enumerate(packets) if newest[id(p[0])] == i]
            stats.stale += len(packets) - len(kept)
            return kept
        return packets

    def _answer(self, sock: socket.socket, channel: Channel, ipoc: int, addr: tuple[str, int], t: int) -> None:
        stats = self.stats
        try:
            reply = channel.respond(ipoc, t)
        except Exception as error:  # noqa: BLE001 - keep answering, report the defect
            channel.broken = True
            self._emit(("fault", channel.index, "internal", f"{type(error).__name__}: {error}\n{traceback.format_exc()}"))
            reply = channel.sen.encode(channel.tx, ipoc)
        if reply is not None:
            sock.sendto(reply, addr)
            busy = self.now_ns() - t
            if busy > stats.max_busy_ns:
                stats.max_busy_ns = busy
            if self.settings.record_busy:
                stats.busy_ns.append(busy)
        stats.packets += 1
        channel.after_reply(t)

    def _service(self, started: int) -> None:
        """Between packets: control messages, silence watch, the saving thread's complaints."""
        errors = self.logger.errors
        while errors:
            self._emit(("warn", -1, errors.popleft()))
        try:
            for message in self.pipe.receive():
                self._control(message)
            self.pipe.flush()
        except PipeClosed:
            self._shutdown = True
        now = self.now_ns()
        s = self.settings
        for channel in self.channels:
            if channel.connected:
                if not channel.lost and now - channel.last_ns > s.silence_timeout * 1e9:
                    silent = (now - channel.last_ns) / 1e6
                    self._emit(("fault", channel.index, "timeout", f"no packet from {channel.link.name} for {silent:.0f} ms after IPOC {channel.ipoc} (delay count {channel.delay})"))
                    channel.mark_lost(f"no RSI packet for {silent:.0f} ms")  # then the running command ends
            elif not channel.lost and now - started > s.connect_timeout * 1e9:
                channel.lost = True
                self._emit(("fault", channel.index, "timeout", f"no packet from {channel.link.name} ({channel.link.host}) within {s.connect_timeout:g} s"))

    def _idle(self, started: int) -> None:
        self._service(started)
        self.logger.flush()

    def _control(self, message: tuple[object, ...]) -> None:
        kind = message[0]
        if kind == "shutdown":
            self._shutdown = True
        elif kind == "stage":
            _, robot, key, space, raw, rows, source, lines = message
            points = np.frombuffer(raw, dtype=np.float64).reshape(int(rows), 6).copy()  # type: ignore[arg-type, call-overload]
            self.channels[int(robot)].staged = {int(key): ToolPath(space, points, str(source), tuple(lines))}  # type: ignore[arg-type, call-overload]
        elif kind == "feedback":
            _, robot, path = message
            self.logger.set_output(int(robot), None if path is None else str(path))  # type: ignore[call-overload]
            self._emit(("feedback", robot, path))
        elif kind == "wake":
            _, robot, cycle = message
            self.channels[int(robot)].wake_at(int(cycle))  # type: ignore[call-overload]
        elif kind == "withhold":
            _, robot, count = message
            self.channels[int(robot)].withhold = int(count)  # type: ignore[call-overload]
        elif kind == "stats":
            st = self.stats
            self._emit(("stats", st.packets, st.foreign, st.rejected, st.oversized, st.max_busy_ns, list(st.busy_ns), [c.withheld for c in self.channels], list(self.logger.written), st.stale))
        else:
            self._emit(("warn", -1, f"unknown control message {kind!r}"))
