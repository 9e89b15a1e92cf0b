"""A KR C4 controller running an RSI context, as seen from the network: the other end of the bridge.

What it reproduces, because the bridge must cope with it (seed 003; ARCHITECTURE "Protocol facts"):

* a ``<Rob>`` packet every cycle (4 ms or 12 ms) on a fixed clock, whether or not replies come;
  IPOC steps by the cycle in ms;
* a reply counts only if it parses, carries the configured SENTYPE and the packet's IPOC, and
  arrives before the next cycle; otherwise the packet is *late*: ``Delay`` counts it, each
  RECEIVE value keeps its last value (HOLDON=1) or falls to zero (HOLDON=0), and after
  ``timeout`` late packets in a row RSI stops with a timeout error;
* axis corrections (``AK``, deg) and Cartesian corrections (``RKorr``, mm/deg in the base
  frame, rotations about the TCP), absolute (relative to the pose where RSI_MOVECORR began) or
  relative (increments per cycle); each clamped like an AXISCORR / POSCORR object and its
  total watched like AXISCORRMON / POSCORRMON, which stop the robot when exceeded;
* software limit switches and the axes' maximum speeds: a set point beyond either stops RSI;
* a servo that follows the set point (``ASPos``) with a first-order lag (``AIPos``);
* the KRL program of ITRA's handshakes: allow start -> task active, allow move ->
  RSI_MOVECORR (corrections followed), request end -> RSI_MOVECORR left, allow finish -> the task
  ends and RSI stops; ``Stop`` ends RSI at once;
* injected faults for tests: send jitter, lost packets, garbage datagrams, replies dropped;
* peers that report what they like (:class:`Quirks`), as the external system meets them: a set
  point frozen at the start pose (ROS-Industrial's ``kuka_rsi_simulator`` never updates ``ASPos``),
  a reported set point drifting away from the real one, ``<Rob TYPE="KUKA">`` (ROS-I's spelling),
  an IPOC counting packets instead of milliseconds;
* a second sender on the controller's host (:class:`~.spoofer.Flood`): forged packets or garbage
  from another port of the controller's IP, at many times the cycle rate.

:class:`KrcModel` is the controller without I/O, stepped cycle by cycle.  Two drivers put it on
a UDP socket: :func:`run_lockstep` (accelerated: the next packet goes out as soon as the reply
is in or known missing; lateness is counted against the simulated cycle, so 100,000 cycles run
in seconds and deterministically) and :func:`run_realtime` (a fixed clock from the injected
:class:`~execution_engine.clock.Clock`).  ``python -m robot_bridges.kuka_rsi.simulator``.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import random
import select
import signal
import socket
import sys
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from core_functions.option_ranges import argument_type
from core_functions.robots import KUKA_KR
from execution_engine.clock import Clock, real_clock, run_with_clock
from robot_bridges.kuka_rsi.codec import PacketCodec, PacketError, Value
from robot_bridges.kuka_rsi.config import RsiConfig, RsiRoles, load_config, default_config
from robot_bridges.kuka_rsi.kinematics import KukaArm, abc_to_matrix, matrix_to_abc, rotation_angle
from robot_bridges.kuka_rsi.realtime import ask_realtime
from robot_bridges.kuka_rsi.setpoint import compose_cartesian
from robot_bridges.kuka_rsi.spoofer import Flood, Flooder, garbage_datagram

HOME_DEG = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RsiContext:
    """What the RSI-Visual diagram and the KRL program configure (not in the Ethernet XML)."""

    cycle_ms: int = 4  # 4 or 12
    timeout: int = 100  # late packets in a row that stop RSI (the ETHERNET object's Timeout)
    correction_mode: str = "absolute"  # or "relative": AK / RKorr as increments per cycle
    axis_limit_deg: tuple[float, ...] = (360.0,) * 6  # AXISCORR: |correction| clamped per axis
    axis_monitor_deg: tuple[float, ...] = (360.0,) * 6  # AXISCORRMON: |total| above -> stop
    pos_limit: tuple[float, float] = (2000.0, 180.0)  # POSCORR: mm per component, deg per angle
    pos_monitor: tuple[float, float] = (2000.0, 360.0)  # POSCORRMON: |translation| mm, |angle| deg
    servo_time_constant: float = 0.006  # s; AIPos follows ASPos with this first-order lag
    start_deg: tuple[float, ...] = HOME_DEG
    ipoc_start: int = 3_741_924_000

    def __post_init__(self) -> None:
        if self.cycle_ms not in (4, 12):
            raise ValueError(f"RSI runs at 4 ms or 12 ms, not {self.cycle_ms} ms")
        if self.timeout < 1:
            raise ValueError(f"timeout must be >= 1 late packet, got {self.timeout}")
        if self.correction_mode not in ("absolute", "relative"):
            raise ValueError(f"correction mode is 'absolute' or 'relative', not {self.correction_mode!r}")
        if len(self.axis_limit_deg) != 6 or len(self.axis_monitor_deg) != 6 or len(self.start_deg) != 6:
            raise ValueError("axis limits, monitors and the start position need 6 values")

    @property
    def dt(self) -> float:
        return self.cycle_ms / 1000.0


@dataclass(frozen=True)
class Faults:
    """Faults to inject, reproducibly from ``seed``."""

    jitter_ms: float = 0.0  # real-time mode: each send is moved by up to +- this
    loss: float = 0.0  # probability that a packet is never sent (the cycle is then late)
    garbage: float = 0.0  # probability that a garbage datagram precedes a packet
    seed: int = 0
    drop: float = 0.0  # probability that a valid reply is discarded on arrival (the cycle is then late)

    def __post_init__(self) -> None:
        if not (0.0 <= self.loss <= 1.0 and 0.0 <= self.garbage <= 1.0 and 0.0 <= self.drop <= 1.0 and self.jitter_ms >= 0.0):
            raise ValueError(f"fault probabilities must lie in [0, 1] and jitter be >= 0: {self}")


@dataclass(frozen=True)
class Quirks:
    """How a controller reports: the peers an external system must not take at their word."""

    frozen_setpoint: bool = False  # ASPos and RSol keep reporting the start pose (ROS-I's kuka_rsi_simulator)
    drift_axis: int = 0  # 1..6: the reported ASPos (and RSol) of this axis drifts from the real set point ...
    drift_deg: float = 0.0  # ... by this much per cycle while RSI_MOVECORR runs
    root_attribute: str = "Type"  # how <Rob> spells its type attribute (ROS-I: "TYPE")
    ipoc_step: int | None = None  # IPOC increment per cycle; None: the cycle in ms, as a KR C4 (ROS-I: 1)

    def __post_init__(self) -> None:
        if not 0 <= self.drift_axis <= 6 or not math.isfinite(self.drift_deg):
            raise ValueError(f"drift axis is 1..6 (0: none) and the drift finite: {self}")
        if not self.root_attribute.isidentifier() or (self.ipoc_step is not None and self.ipoc_step < 1):
            raise ValueError(f"the root attribute must be a name and the IPOC step >= 1: {self}")

    @staticmethod
    def parse_drift(text: str) -> tuple[int, float]:
        """``A3:0.01`` (or ``3:0.01``): axis and degrees per cycle."""
        axis, sep, value = text.partition(":")
        axis = axis.upper().removeprefix("A")
        if not sep or not axis.isdigit():
            raise ValueError(f"drift is AXIS:DEG_PER_CYCLE, e.g. A3:0.01, got {text!r}")
        return int(axis), float(value)


class Program(Enum):
    """Where the simulated KRL program is."""

    IDLE = "idle"  # waiting for allow start
    TASK = "task"  # task active, waiting for allow move
    MOVECORR = "movecorr"  # RSI_MOVECORR: corrections are followed
    ENDED = "ended"  # real-time control ended, waiting for allow finish
    FINISHED = "finished"


class RsiStopped(Exception):
    """RSI has stopped; ``error`` is False for a normal end (Stop flag, task finished)."""

    def __init__(self, reason: str, error: bool) -> None:
        super().__init__(reason)
        self.reason = reason
        self.error = error


@dataclass
class SimStats:
    packets: int = 0
    late: int = 0
    late_since_first_reply: int = 0  # leaves out the packets sent before the external system was there
    late_ipocs: list[int] = field(default_factory=list)  # the first 1000 of those
    accepted: int = 0
    invalid_replies: int = 0
    foreign: int = 0
    lost: int = 0
    garbage_sent: int = 0
    dropped: int = 0  # valid replies discarded on purpose (Faults.drop)
    late_replies_discarded: int = 0
    lateness_ns: list[int] = field(default_factory=list)  # real time: how far past its deadline each discarded reply came
    overruns: int = 0
    latencies_ns: list[int] = field(default_factory=list)
    flood_sent: int = 0  # datagrams the second sender on the controller's host sent (Flood)
    flood_replies: int = 0  # replies that reached it: none, unless the external system took it for the controller


class KrcModel:
    """The controller, one cycle at a time: :meth:`packet`, :meth:`offer` replies, :meth:`advance`."""

    def __init__(
        self,
        config: RsiConfig,
        context: RsiContext = RsiContext(),
        roles: RsiRoles = RsiRoles(),
        arm: KukaArm | None = None,
        *,
        accept_echo: bool = False,
        quirks: Quirks = Quirks(),
    ) -> None:
        """``accept_echo``: a datagram equal to the packet counts as the reply -- to time a bare UDP
        echo server as the baseline of a benchmark; nothing is applied then."""
        if config.onlysend:
            raise ValueError(f"{config.source}: ONLYSEND is TRUE, so no corrections could ever arrive")
        self.config = config
        self.context = context
        self.roles = roles
        self.arm = arm or KukaArm()
        self.rob = PacketCodec.rob(config)
        self.sen = PacketCodec.sen(config)
        self.dt = context.dt
        self.ipoc = context.ipoc_start
        self.stats = SimStats()
        self.delay = 0
        self.late_in_row = 0
        self.stopped: RsiStopped | None = None
        self.q_cmd = np.radians(context.start_deg)
        self.q_act = self.q_cmd.copy()
        self.q_ref = self.q_cmd.copy()
        self.quirks = quirks
        self._q_start = self.q_cmd.copy()
        self._drift = np.zeros(6)
        self._root = b'<Rob Type="' if quirks.root_attribute == "Type" else None
        self._alpha = 1.0 - math.exp(-self.dt / context.servo_time_constant) if context.servo_time_constant > 0 else 1.0
        self._vmax = np.array([j.max_velocity for j in KUKA_KR.group("arm").joints])
        fields = self.sen.fields
        self._received: list[Value] = list(self.sen.defaults)
        self._holdon = [f.holdon for f in fields]
        self._reply_ok = False
        self._ak_idx = [self.sen.index[k] for k in roles.axis_correction] if roles.axis(config) else None
        self._rk_idx = [self.sen.index[k] for k in roles.cart_correction] if roles.cartesian(config) else None
        self._ak_total = np.zeros(6)
        self._rk_total = np.zeros(6)
        self._handshake = roles.handshake(config)
        self.program = Program.IDLE if self._handshake else Program.MOVECORR
        self.outputs: dict[str, bool] = {}
        self._tools = roles.tools(config)
        self._send_values: list[Value] = list(self.rob.defaults)
        self._cache_q: dict[str, tuple[bytes, tuple[float, ...]]] = {}
        #: When a list, the set point (rad) of every cycle is appended: what the robot was told to do.
        self.trace: list[np.ndarray] | None = None
        self._accept_echo = accept_echo
        self._last_packet = b""

    # ------------------------------------------------------------------------------ output
    def packet(self) -> bytes:
        """The ``<Rob>`` packet of the current cycle."""
        values = self._send_values
        self._fill("RIst", self._cartesian("act", self.q_act))
        reported = self._reported_setpoint()
        self._fill("RSol", self._cartesian("cmd", reported))
        self._fill("AIPos", tuple(math.degrees(v) for v in self.q_act))
        self._fill("ASPos", tuple(math.degrees(v) for v in reported))
        index = self.rob.index
        if "Delay.D" in index:
            values[index["Delay.D"]] = self.delay
        if self._handshake:
            r = self.roles
            p = self.program
            values[index[r.task_active]] = p in (Program.TASK, Program.MOVECORR, Program.ENDED)
            values[index[r.correction_active]] = p is Program.MOVECORR
            values[index[r.move_required]] = p is Program.TASK
            values[index[r.realtime_ended]] = p is Program.ENDED
        for tag in self._tools:
            values[index[tag]] = self.outputs.get(tag, False)
        self.stats.packets += 1
        packet = self.rob.encode(values, self.ipoc)
        if self._root is None:
            packet = packet.replace(b'<Rob Type="', f'<Rob {self.quirks.root_attribute}="'.encode("ascii"), 1)
        self._last_packet = packet
        return packet

    def forged_packet(self, delay_jump: int, cycles_ahead: int) -> bytes:
        """This cycle's packet as a forger on the controller's host would send it: its values, but
        ``Delay`` ``delay_jump`` higher and the IPOC ``cycles_ahead`` cycles on."""
        values = list(self._send_values)
        at = self.rob.index.get("Delay.D")
        if at is not None:
            values[at] = self.delay + delay_jump
        return self.rob.encode(values, self.ipoc + cycles_ahead * (self.quirks.ipoc_step or self.context.cycle_ms))

    def _reported_setpoint(self) -> np.ndarray:
        """The set point the packet reports: the real one, unless a quirk says otherwise."""
        if self.quirks.frozen_setpoint:
            return self._q_start
        return self.q_cmd + self._drift if self.quirks.drift_axis else self.q_cmd

    def _fill(self, element: str, six: Sequence[float]) -> None:
        index = self.rob.index
        names = ("X", "Y", "Z", "A", "B", "C") if element in ("RIst", "RSol") else ("A1", "A2", "A3", "A4", "A5", "A6")
        for name, value in zip(names, six):
            at = index.get(f"{element}.{name}")
            if at is not None:
                self._send_values[at] = value

    def _cartesian(self, which: str, q: np.ndarray) -> tuple[float, ...]:
        """RIst / RSol (mm, deg) of ``q``, recomputed only when ``q`` changed."""
        key = q.tobytes()
        cached = self._cache_q.get(which)
        if cached is not None and cached[0] == key:
            return cached[1]
        t = self.arm.fk(q)
        a, b, c = matrix_to_abc(t[:3, :3])
        pose = (t[0, 3] * 1000.0, t[1, 3] * 1000.0, t[2, 3] * 1000.0, math.degrees(a), math.degrees(b), math.degrees(c))
        self._cache_q[which] = (key, pose)
        return pose

    # ------------------------------------------------------------------------------- input
    def offer(self, data: bytes, drop: bool = False) -> bool:
        """A datagram from the external system during this cycle; True if it is *the* reply
        (``drop``: a valid reply is discarded all the same, and the cycle will be late)."""
        if self._reply_ok:
            return False  # the cycle already has its reply; RSI takes the first valid one
        if self._accept_echo and data == self._last_packet:
            self._reply_ok = True
            self.stats.accepted += 1
            return True
        out = list(self._received)
        try:
            ipoc = self.sen.decode_into(data, out)
        except PacketError:
            self.stats.invalid_replies += 1
            return False
        if ipoc != self.ipoc:
            self.stats.invalid_replies += 1
            return False
        if drop:
            self.stats.dropped += 1
            return True
        self._received = out
        self._reply_ok = True
        self.stats.accepted += 1
        return True

    # ------------------------------------------------------------------------------- cycle
    def advance(self) -> None:
        """Close the cycle: count lateness, apply the values, move the robot, step IPOC.

        Raises :class:`RsiStopped` when RSI stops; the model then stays stopped.
        """
        if self.stopped is not None:
            raise self.stopped
        try:
            self._close_cycle()
        except RsiStopped as stop:
            self.stopped = stop
            raise

    def _close_cycle(self) -> None:
        if self._reply_ok:
            self.late_in_row = 0
        else:
            self.delay += 1
            self.late_in_row += 1
            self.stats.late += 1
            if self.stats.accepted:
                self.stats.late_since_first_reply += 1
                if len(self.stats.late_ipocs) < 1000:
                    self.stats.late_ipocs.append(self.ipoc)
            self._received = [v if hold else d for v, hold, d in zip(self._received, self._holdon, self.sen.defaults)]
            if self.late_in_row >= self.context.timeout:
                raise RsiStopped(
                    f"RSI timeout: {self.late_in_row} packets late in a row (Timeout {self.context.timeout}), "
                    f"IPOC {self.ipoc}",
                    error=True,
                )
        self._reply_ok = False
        values = self._received
        index = self.sen.index
        for tag in self._tools:
            self.outputs[tag] = bool(values[index[tag]])
        stop_at = index.get(self.roles.stop)
        if stop_at is not None and values[stop_at]:
            raise RsiStopped(f"RSI stopped by the external system (Stop) at IPOC {self.ipoc}", error=False)
        self._run_program(values)
        if self.program is Program.MOVECORR:
            self._apply_corrections(values)
        self.q_act = self.q_act + self._alpha * (self.q_cmd - self.q_act)
        if self.trace is not None:
            self.trace.append(self.q_cmd.copy())
        if self.quirks.drift_axis and self.program is Program.MOVECORR:
            self._drift[self.quirks.drift_axis - 1] += math.radians(self.quirks.drift_deg)
        self.ipoc += self.quirks.ipoc_step or self.context.cycle_ms
        if self.program is Program.FINISHED:
            raise RsiStopped(f"KRL task finished at IPOC {self.ipoc}; RSI off", error=False)

    def _run_program(self, values: list[Value]) -> None:
        if not self._handshake:
            return
        r, index, p = self.roles, self.sen.index, self.program
        if p is Program.IDLE and values[index[r.allow_start]]:
            self.program = Program.TASK
        elif p is Program.TASK and values[index[r.allow_move]]:
            self.program = Program.MOVECORR
            self._begin_movecorr()
        elif p is Program.TASK and values[index[r.allow_finish]]:
            self.program = Program.FINISHED
        elif p is Program.MOVECORR and values[index[r.request_end]]:
            self.program = Program.ENDED
        elif p is Program.ENDED and values[index[r.allow_finish]]:
            self.program = Program.FINISHED

    def _begin_movecorr(self) -> None:
        """Absolute corrections are relative to where RSI_MOVECORR starts."""
        self.q_ref = self.q_cmd.copy()
        self._ak_total[:] = 0.0
        self._rk_total[:] = 0.0

    def _apply_corrections(self, values: list[Value]) -> None:
        ctx = self.context
        relative = ctx.correction_mode == "relative"
        if self._ak_idx is not None:
            limit = np.array(ctx.axis_limit_deg)
            ak = np.clip(np.array([float(values[i]) for i in self._ak_idx]), -limit, limit)  # AXISCORR
            self._ak_total = self._ak_total + ak if relative else ak
            over = np.nonzero(np.abs(self._ak_total) > np.array(ctx.axis_monitor_deg))[0]
            if over.size:  # AXISCORRMON
                i = int(over[0])
                raise RsiStopped(
                    f"AXISCORRMON: total correction of A{i + 1} is {self._ak_total[i]:.3f} deg, more than the "
                    f"{ctx.axis_monitor_deg[i]:.3f} deg allowed",
                    error=True,
                )
        if self._rk_idx is not None:
            mm, deg = ctx.pos_limit
            limit = np.array([mm, mm, mm, deg, deg, deg])
            rk = np.clip(np.array([float(values[i]) for i in self._rk_idx]), -limit, limit)  # POSCORR
            self._rk_total = compose_cartesian(self._rk_total, rk) if relative else rk
            if relative and float(np.max(np.abs(self._rk_total))) < 1e-9:
                self._rk_total = np.zeros(6)  # increments that cancel leave no correction, not rounding noise
            shift = float(np.linalg.norm(self._rk_total[:3]))
            turn = math.degrees(rotation_angle(abc_to_matrix(*np.radians(self._rk_total[3:]))))
            if shift > ctx.pos_monitor[0] or turn > ctx.pos_monitor[1]:  # POSCORRMON
                raise RsiStopped(
                    f"POSCORRMON: total Cartesian correction {shift:.2f} mm / {turn:.2f} deg exceeds "
                    f"{ctx.pos_monitor[0]:.2f} mm / {ctx.pos_monitor[1]:.2f} deg",
                    error=True,
                )
        q_new = self.q_ref + np.radians(self._ak_total)
        if np.any(self._rk_total):
            base = self.arm.fk(q_new)
            target = base.copy()
            target[:3, 3] += self._rk_total[:3] / 1000.0
            target[:3, :3] = abc_to_matrix(*np.radians(self._rk_total[3:])) @ base[:3, :3]
            solved = self.arm.ik(target, self.q_cmd)
            if solved is None:
                raise RsiStopped(
                    f"Cartesian correction RKorr {np.round(self._rk_total, 3).tolist()} leads out of the workspace",
                    error=True,
                )
            q_new = solved
        self._check_motion(q_new)
        self.q_cmd = q_new

    def _check_motion(self, q_new: np.ndarray) -> None:
        arm = self.arm
        for i in range(6):
            if not arm.lower[i] - 1e-9 <= q_new[i] <= arm.upper[i] + 1e-9:
                raise RsiStopped(
                    f"software limit switch A{i + 1}: set point {math.degrees(q_new[i]):.3f} deg outside "
                    f"[{math.degrees(arm.lower[i]):.1f}, {math.degrees(arm.upper[i]):.1f}] deg",
                    error=True,
                )
        speed = np.abs(q_new - self.q_cmd) / self.dt
        over = np.nonzero(speed > self._vmax * 1.0001)[0]
        if over.size:
            i = int(over[0])
            raise RsiStopped(
                f"commanded speed of A{i + 1} is {math.degrees(speed[i]):.1f} deg/s, more than the "
                f"{math.degrees(self._vmax[i]):.1f} deg/s the axis can do",
                error=True,
            )


# ---------------------------------------------------------------------------------- drivers
@dataclass(frozen=True)
class Endpoint:
    host: str
    port: int

    @staticmethod
    def parse(text: str, default_port: int | None = None) -> Endpoint:
        host, sep, port = text.rpartition(":")
        if not sep:
            if default_port is None:
                raise ValueError(f"expected HOST:PORT, got {text!r}")
            return Endpoint(text, default_port)
        if not port.isdigit() or not 0 <= int(port) < 65536:
            raise ValueError(f"bad port in {text!r}")
        return Endpoint(host or "127.0.0.1", int(port))

    def __str__(self) -> str:
        return f"{self.host}:{self.port}"


def latency_summary(latencies_ns: Sequence[int]) -> dict[str, float]:
    """p50, p99, p99.9 and max of round trips, in microseconds."""
    if not latencies_ns:
        return {}
    values = np.sort(np.asarray(latencies_ns, dtype=np.float64)) / 1000.0
    pick = lambda q: float(values[min(len(values) - 1, int(q * len(values)))])  # noqa: E731
    return {"n": float(len(values)), "p50": pick(0.5), "p99": pick(0.99), "p99.9": pick(0.999), "max": float(values[-1])}


_SO_TIMESTAMPNS = 35  # Linux <asm-generic/socket.h>; not exported by the socket module
_TIMESPEC = struct.Struct("qq")


def _wall_ns() -> int:
    """CLOCK_REALTIME, the clock the kernel stamps received datagrams with (see :class:`_Link`).

    Only the on-time verdict of the real-time driver reads it, to compare with those stamps;
    the schedule itself runs on the injected :class:`Clock`.
    """
    return time.clock_gettime_ns(time.CLOCK_REALTIME)


class _Link:
    """The controller's socket: sends the model's packets (with injected loss and garbage) and
    reads datagrams with their arrival time.

    The arrival time is the kernel's receive stamp when the platform gives one, so a reply that
    came in time is on time even if the simulator itself was scheduled late to read it -- a real
    controller's RSI runs hard real time.  ``now_ns`` stamps sends (and arrivals without kernel
    stamps); round trips of accepted replies go to ``model.stats.latencies_ns``.
    """

    def __init__(self, sock: socket.socket, peer: tuple[str, int], model: KrcModel, faults: Faults, now_ns: Callable[[], int] | None, *, kernel_stamps: bool = False) -> None:
        self.sock, self.peer, self.model, self.faults = sock, peer, model, faults
        self.rng = random.Random(faults.seed)
        self.now_ns = now_ns
        self.sent_ns = 0
        self.kernel_stamps = False
        if kernel_stamps:
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.kernel_stamps = True
            except OSError:
                pass

    def send(self) -> bool:
        """Send this cycle's packet; False when it was 'lost'."""
        packet = self.model.packet()
        if self.faults.garbage and self.rng.random() < self.faults.garbage:
            self.model.stats.garbage_sent += 1
            self.sock.sendto(garbage_datagram(self.rng), self.peer)
        if self.faults.loss and self.rng.random() < self.faults.loss:
            self.model.stats.lost += 1
            return False
        if self.now_ns is not None:
            self.sent_ns = self.now_ns()
        self.sock.sendto(packet, self.peer)
        return True

    def read(self, timeout: float, buf: bytearray) -> tuple[bytes, int] | None:
        """Wait up to ``timeout`` wall seconds for a datagram from the peer: ``(data, arrival_ns)``,
        ``(b"", 0)`` for anything else that arrived, None when nothing did."""
        ready, _, _ = select.select([self.sock], [], [], max(0.0, timeout))
        if not ready:
            return None
        try:
            if self.kernel_stamps:
                n, ancillary, _, addr = self.sock.recvmsg_into([buf], socket.CMSG_SPACE(_TIMESPEC.size))
                arrived = next(
                    (
                        sec * 1_000_000_000 + nsec
                        for level, kind, data in ancillary
                        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size
                        for sec, nsec in [_TIMESPEC.unpack_from(data)]
                    ),
                    0,
                )
            else:
                n, addr = self.sock.recvfrom_into(buf)
                arrived = 0
        except ConnectionRefusedError:
            return (b"", 0)  # ICMP: nobody listens at the external system's address (yet)
        if not arrived and self.now_ns is not None:
            arrived = self.now_ns()
        if addr[0] != self.peer[0] or addr[1] != self.peer[1]:
            self.model.stats.foreign += 1
            return (b"", 0)
        return bytes(buf[:n]), arrived

    def offer(self, data: bytes, arrived: int) -> bool:
        drop = bool(self.faults.drop) and self.rng.random() < self.faults.drop
        accepted = self.model.offer(data, drop)
        if accepted and self.now_ns is not None:
            self.model.stats.latencies_ns.append(arrived - self.sent_ns)
        return accepted


def run_lockstep(
    sock: socket.socket,
    peer: tuple[str, int],
    model: KrcModel,
    *,
    cycles: int | None = None,
    faults: Faults = Faults(),
    reply_grace: float = 0.25,
    stop: threading.Event | None = None,
    now_ns: Callable[[], int] | None = None,
    flooder: Flooder | None = None,
) -> RsiStopped | None:
    """Accelerated mode: each packet goes out as soon as the previous cycle's fate is decided.

    A cycle is on time when its reply arrives before the next packet is sent; a reply that does
    not come within ``reply_grace`` wall seconds is late (a lost packet is late at once).  So the
    outcome depends on what the external system answered, not on how fast the machine is.
    ``now_ns`` (for benchmarks) records each reply's round trip in ``model.stats.latencies_ns``.
    A ``flooder`` sends its cycle's datagrams half just before the packet, half just after it, so
    they compete with the packet and with the reply.  Returns why RSI stopped, or None when
    ``cycles`` ran out or ``stop`` was set.
    """
    link = _Link(sock, peer, model, faults, now_ns)
    buf = bytearray(65536)
    done = 0
    while (cycles is None or done < cycles) and not (stop is not None and stop.is_set()):
        burst = flooder.due() if flooder is not None else 0
        if flooder is not None:
            flooder.send(burst // 2)
        sent = link.send()
        if flooder is not None:
            flooder.send(burst - burst // 2)
        if sent:
            while True:
                got = link.read(reply_grace, buf)
                if got is None or (got[0] and link.offer(*got)):
                    break  # no reply within the grace, or the reply
        try:
            model.advance()
        except RsiStopped as stopped:
            return stopped
        done += 1
    return None


def run_realtime(
    sock: socket.socket,
    peer: tuple[str, int],
    model: KrcModel,
    clock: Clock,
    *,
    cycles: int | None = None,
    faults: Faults = Faults(),
    stop: threading.Event | None = None,
    flooder: Flooder | None = None,
) -> RsiStopped | None:
    """Real-time mode: a packet every cycle of ``clock`` run time, replies or not.

    Packets leave on a fixed grid; a reply is on time if it arrived (by the kernel's receive
    stamp) before the next tick, and the cycle is closed then, just before the next packet is
    computed and sent.  If the simulator itself wakes more than an eighth of a cycle late, it
    counts an overrun and restarts its grid there, so its own hiccups never shorten the
    external system's cycle.  The
    waits are ``select`` timeouts computed from ``clock.now()``: microsecond resolution, where
    asyncio timers round to the millisecond.  A ``flooder`` sends its datagrams evenly spread
    over every cycle from the same thread, between the waits.
    """
    link = _Link(sock, peer, model, faults, _wall_ns, kernel_stamps=True)
    buf = bytearray(65536)
    cycle = model.dt
    tick = clock.now()
    deadline_ns: int | None = None  # for the reply to the packet in flight; None: none can be on time
    in_flight = False
    done = 0
    if flooder is not None:
        flooder.pace(tick, cycle)
    while not (stop is not None and stop.is_set()):
        jitter = link.rng.uniform(0.0, faults.jitter_ms) / 1000.0 if faults.jitter_ms else 0.0
        _collect(link, clock, tick + jitter, buf, deadline_ns, flooder)
        woke = clock.now()
        if woke - tick - jitter > cycle / 8:
            # The simulator itself woke late (a controller never does): start the grid again
            # from here, so the external system still gets a whole cycle for this packet.
            model.stats.overruns += 1
            tick = woke - jitter
        if in_flight:
            try:
                model.advance()
            except RsiStopped as stopped:
                return stopped
            done += 1
            if cycles is not None and done >= cycles:
                return None
        tick += cycle
        now = clock.now()
        sent = link.send()
        # On time means: in by the next tick of the grid, by the kernel's receive stamp.
        deadline_ns = link.sent_ns + int(clock.to_wall(tick - now) * 1e9) if sent else None
        in_flight = True
    return None


def _collect(link: _Link, clock: Clock, until: float, buf: bytearray, deadline_ns: int | None, flooder: Flooder | None = None) -> None:
    """Read datagrams until run time ``until`` (and whatever has arrived by then); offer the ones
    that arrived by ``deadline_ns``, discard the rest as late.  A flooder's datagrams leave at
    their instants in between."""
    while True:
        wake = until
        if flooder is not None:
            flooder.fire(clock.now())
            wake = min(until, flooder.next_at)
        got = link.read(clock.to_wall(wake - clock.now()), buf)
        if got is None:
            if wake < until:
                continue  # woke for the flood, not for the end of the wait
            return
        data, arrived = got
        if not data:
            continue
        if deadline_ns is not None and arrived <= deadline_ns:
            link.offer(data, arrived)
        else:
            link.model.stats.late_replies_discarded += 1
            if deadline_ns is not None:
                link.model.stats.lateness_ns.append(arrived - deadline_ns)


# ------------------------------------------------------------------------------------ thread
class SimulatorThread:
    """The simulator on its own thread and socket, for tests and for an in-process bridge.

    ``clock=None`` runs in accelerated (lockstep) mode; with a clock it runs in real time.  A
    ``flood`` adds a second sender on the controller's IP (another port): :attr:`flooder`.
    """

    def __init__(
        self,
        config: RsiConfig,
        peer: tuple[str, int],
        *,
        context: RsiContext = RsiContext(),
        roles: RsiRoles = RsiRoles(),
        bind: tuple[str, int] = ("127.0.0.1", 0),
        clock: Clock | None = None,
        faults: Faults = Faults(),
        cycles: int | None = None,
        reply_grace: float = 0.25,
        now_ns: Callable[[], int] | None = None,
        quirks: Quirks = Quirks(),
        flood: Flood = Flood(),
    ) -> None:
        self.model = KrcModel(config, context, roles, quirks=quirks)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(bind)
        self.address: tuple[str, int] = self.sock.getsockname()
        self.peer = peer
        self.flooder = Flooder(flood, self.address[0], peer, self.model, faults.seed) if flood.rate > 0 else None
        self._clock = clock
        self._faults = faults
        self._cycles = cycles
        self._grace = reply_grace
        self._now_ns = now_ns
        self._stop = threading.Event()
        self.result: RsiStopped | None = None
        self.crash: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="rsi-simulator", daemon=True)

    def start(self) -> SimulatorThread:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            if self._clock is None:
                self.result = run_lockstep(
                    self.sock, self.peer, self.model, cycles=self._cycles, faults=self._faults, reply_grace=self._grace,
                    stop=self._stop, now_ns=self._now_ns, flooder=self.flooder,
                )
            else:
                self.result = run_realtime(
                    self.sock, self.peer, self.model, self._clock, cycles=self._cycles, faults=self._faults, stop=self._stop,
                    flooder=self.flooder,
                )
        except BaseException as error:  # noqa: BLE001 - kept for the test or bridge that owns the thread
            self.crash = error
        finally:
            self.sock.close()
            if self.flooder is not None:
                self.flooder.close()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def join(self, timeout: float | None = None) -> bool:
        self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    @property
    def stop_reason(self) -> str | None:
        if self.crash is not None:
            return f"simulator crashed: {type(self.crash).__name__}: {self.crash}"
        return self.result.reason if self.result else None


# --------------------------------------------------------------------------------------- CLI
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m robot_bridges.kuka_rsi.simulator", description=__doc__.split("\n")[0])
    p.add_argument("--config", help="RSI Ethernet configuration XML (default: the package's)")
    p.add_argument("--to", default="", help="external system HOST:PORT (default: IP_NUMBER:PORT of the config)")
    p.add_argument("--bind", default="127.0.0.1:0", help="address the controller sends from (default 127.0.0.1:0)")
    p.add_argument("--cycle", type=int, default=4, choices=(4, 12), help="RSI cycle in ms")
    p.add_argument("--accelerated", action="store_true", help="lockstep: next packet as soon as the reply is in")
    p.add_argument("--speed", type=argument_type("speed"), default=1.0, help="real-time mode: run faster than real time by this factor, in [0.01, 1000]")
    p.add_argument("--cycles", type=int, default=None, help="stop after this many cycles")
    p.add_argument("--timeout", type=int, default=100, help="late packets in a row that stop RSI")
    p.add_argument("--mode", choices=("absolute", "relative"), default="absolute", help="correction mode")
    p.add_argument("--axis-monitor", type=float, default=360.0, help="AXISCORRMON limit (deg, every axis)")
    p.add_argument("--jitter-ms", type=float, default=0.0)
    p.add_argument("--loss", type=float, default=0.0)
    p.add_argument("--garbage", type=float, default=0.0)
    p.add_argument("--drop", type=float, default=0.0, help="probability that a valid reply is discarded (the cycle is late)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--frozen-setpoint", action="store_true", help="report ASPos/RSol of the start pose forever (ROS-I's simulator)")
    p.add_argument("--drift", default="", metavar="AXIS:DEG", help="the reported ASPos of AXIS drifts by DEG per cycle, e.g. A3:0.01")
    p.add_argument("--root-attribute", default="Type", help="how <Rob> spells its type attribute (ROS-I's simulator: TYPE)")
    p.add_argument("--ipoc-step", type=int, default=None, help="IPOC increment per cycle (default: the cycle in ms; ROS-I's simulator: 1)")
    p.add_argument("--flood", default="", metavar="RATE[:CONTENT]", help="a second sender on the controller's IP, another port: RATE datagrams per cycle of packet (forged, Delay +50), garbage or mixed")
    p.add_argument("--flood-port", type=int, default=0, help="the flooder's port on the controller's IP (default: any free one)")
    p.add_argument("--reply-grace", type=float, default=0.25, help="accelerated mode: wall seconds to wait for a reply")
    p.add_argument("--rt-priority", type=int, default=0, help="try SCHED_FIFO at this priority (a controller is hard real time)")
    p.add_argument("--accept-echo", action="store_true", help="benchmark baseline: a datagram equal to the packet is the reply")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the simulator; the last line on stdout is a JSON summary. Exit 0 normal end, 2 RSI error, 1 bad usage."""
    args = _parser().parse_args(argv)
    try:
        config = load_config(args.config) if args.config else default_config()
        to = Endpoint.parse(args.to) if args.to else Endpoint(config.ip, config.port)
        bind = Endpoint.parse(args.bind)
        context = RsiContext(
            cycle_ms=args.cycle, timeout=args.timeout, correction_mode=args.mode, axis_monitor_deg=(args.axis_monitor,) * 6
        )
        faults = Faults(args.jitter_ms, args.loss, args.garbage, args.seed, args.drop)
        axis, deg = Quirks.parse_drift(args.drift) if args.drift else (0, 0.0)
        quirks = Quirks(args.frozen_setpoint, axis, deg, args.root_attribute, args.ipoc_step)
        flood = Flood.parse(args.flood) if args.flood else Flood()
        flood = Flood(flood.rate, flood.content, flood.delay_jump, args.flood_port)
        model = KrcModel(config, context, accept_echo=args.accept_echo, quirks=quirks)
    except (ValueError, OSError) as error:
        print(f"kuka_rsi simulator: {error}", file=sys.stderr)
        return 1
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((bind.host, bind.port))
    except OSError as error:
        print(f"kuka_rsi simulator: cannot bind {bind}: {error.strerror}", file=sys.stderr)
        return 1
    host, port = sock.getsockname()
    peer = (to.host, to.port)
    try:
        flooder = Flooder(flood, host, peer, model, args.seed) if flood.rate > 0 else None
    except OSError as error:
        sock.close()
        print(f"kuka_rsi simulator: cannot bind the flooder to {host}:{flood.port}: {error.strerror}", file=sys.stderr)
        return 1
    priority = ask_realtime(args.rt_priority)
    flooding = "" if flooder is None else f", flooding from {flooder.address[0]}:{flooder.address[1]} ({flood.rate:g} {flood.content} per cycle)"
    print(f"KRC simulator {host}:{port} -> {to}, {args.cycle} ms, {'accelerated' if args.accelerated else f'x{args.speed:g}'}, {priority}{flooding}", flush=True)
    stop = threading.Event()
    # SIGTERM / SIGINT end the run between two cycles, so the summary below is still printed.
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    async def realtime(clock: Clock) -> RsiStopped | None:
        return await asyncio.to_thread(run_realtime, sock, peer, model, clock, cycles=args.cycles, faults=faults, stop=stop, flooder=flooder)

    try:
        if args.accelerated:
            result = run_lockstep(sock, peer, model, cycles=args.cycles, faults=faults, reply_grace=args.reply_grace, stop=stop, flooder=flooder)
        else:
            result = run_with_clock(realtime, real_clock() if args.speed == 1.0 else Clock(args.speed))
    finally:
        sock.close()
        if flooder is not None:
            flooder.close()
    s = model.stats
    summary = {
        "stopped": result.reason if result else None,
        "error": bool(result and result.error),
        "packets": s.packets,
        "late": s.late,
        "late_since_first_reply": s.late_since_first_reply,
        "accepted": s.accepted,
        "invalid_replies": s.invalid_replies,
        "dropped": s.dropped,
        "overruns": s.overruns,
        "last_ipoc": model.ipoc,
        "round_trip_us": latency_summary(s.latencies_ns),
        "late_ipocs": s.late_ipocs[:20],
        "late_replies": s.late_replies_discarded,
        "lateness_us": latency_summary(s.lateness_ns),
        "flood_sent": s.flood_sent,
        "flood_replies": s.flood_replies,
    }
    print(json.dumps(summary), flush=True)
    return 2 if result and result.error else 0


if __name__ == "__main__":
    sys.exit(main())
