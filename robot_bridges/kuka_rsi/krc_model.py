"""The KR C4 controller running an RSI context, without I/O: stepped one cycle at a time.

The network side (``sim_network``) puts it on a UDP socket; tests and benchmarks drive it directly.  Each cycle
the model makes its ``<Rob>`` packet (:meth:`KrcModel.packet`), is offered the datagrams that arrived
(:meth:`KrcModel.offer`), and closes the cycle (:meth:`KrcModel.advance`): lateness counted against ``Delay`` and
the ETHERNET object's timeout, HOLDON applied, the KRL program's handshakes, axis and Cartesian corrections clamped
and monitored (AXISCORR/AXISCORRMON, POSCORR/POSCORRMON), software limit switches and the axes' maximum speeds,
and a servo following the set point.  What it reports can be made to lie on purpose (:class:`~.sim_faults.Quirks`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from core_functions.robots import KUKA_KR
from robot_bridges.kuka_rsi.codec import PacketCodec, PacketError, Value
from robot_bridges.kuka_rsi.config import RsiConfig, RsiRoles
from robot_bridges.kuka_rsi.kinematics import KukaArm, abc_to_matrix, matrix_to_abc, rotation_angle
from robot_bridges.kuka_rsi.setpoint import compose_cartesian
from robot_bridges.kuka_rsi.sim_faults import Quirks

HOME_DEG = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
#: Where ROS-Industrial's kuka_rsi_simulator starts (its defaults).
ROS_I_START_DEG = (0.0, -90.0, 90.0, 0.0, 90.0, 0.0)

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


#: The controllers the simulated one can behave like, at their default settings.
PEERS = ("kr-c4", "ros-industrial")


def like_peer(peer: str, context: RsiContext, quirks: Quirks) -> tuple[RsiContext, Quirks]:
    """``context`` and ``quirks`` as ``peer`` has them: ``kr-c4`` changes nothing; ``ros-industrial`` is
    ROS-Industrial's ``kuka_rsi_simulator`` at its defaults -- its start pose (0 -90 90 0 90 0), AIPos taking
    each correction at once (no servo lag), ASPos frozen at the start, RIst and RSol at zero,
    ``<Rob TYPE="KUKA">``, an IPOC counting packets from 0."""
    if peer == "kr-c4":
        return context, quirks
    if peer == "ros-industrial":
        return (
            replace(context, servo_time_constant=0.0, start_deg=ROS_I_START_DEG, ipoc_start=0),
            replace(quirks, frozen_setpoint=True, root_attribute="TYPE", ipoc_step=1, zero_cartesian=True),
        )
    raise ValueError(f"the simulated controller behaves like {' or '.join(PEERS)}, not {peer!r}")


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
        # A signal in both directions is an output the robot reads back (kroshu's GPIO.01): echoed, as a
        # KRL program's $OUT read by DIGOUT would be; inputs the cell drives are set in ``inputs``.
        self._echo = [(self.rob.index[k], self.sen.index[k]) for k in self.sen.index if k in self.rob.index and k not in self._tools]
        #: Values of <Rob> the simulated cell drives (a sensor, a PLC), by key: tests set them.
        self.inputs: dict[str, Value] = {}
        self._send_values: list[Value] = list(self.rob.defaults)
        self._cache_q: dict[str, tuple[bytes, tuple[float, ...]]] = {}
        #: When a list, the set point (rad) of every cycle is appended: what the robot was told to do.
        self.trace: list[np.ndarray] | None = None
        self._accept_echo = accept_echo
        self._last_packet = b""

    def carry_correction(self, axes_deg: Sequence[float]) -> None:
        """Start with this axis correction in force and the robot standing where it puts it: a controller that
        kept it from an earlier connection (ROS-I's simulator does; a KR C4 begins RSI_MOVECORR at zero)."""
        self._ak_total = np.array(axes_deg, dtype=float)
        self.q_cmd = self.q_ref + np.radians(self._ak_total)
        self.q_act = self.q_cmd.copy()

    # ------------------------------------------------------------------------------ output
    def packet(self) -> bytes:
        """The ``<Rob>`` packet of the current cycle."""
        values = self._send_values
        actual = self.q_act + self._drift if self.quirks.drift_actual else self.q_act
        reported = self._reported_setpoint()
        if self.quirks.zero_cartesian:
            self._fill("RIst", (0.0,) * 6)
            self._fill("RSol", (0.0,) * 6)
        else:
            self._fill("RIst", self._cartesian("act", actual))
            self._fill("RSol", self._cartesian("cmd", reported))
        self._fill("AIPos", tuple(math.degrees(v) for v in actual))
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
        for sent, received in self._echo:
            values[sent] = self._received[received]
        for key, value in self.inputs.items():
            values[index[key]] = value
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
        return self.q_cmd + self._drift if self.quirks.drift_axis and not self.quirks.drift_actual else self.q_cmd

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
