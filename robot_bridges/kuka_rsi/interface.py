"""ITRA's public functions: setters, getters and the RSI manager, for one or more robots.

:class:`RsiInterface` starts the real-time loop (:mod:`.external`) on a thread or in a process
of its own and talks to it through shared records (:mod:`.slots`) and a message pipe
(:mod:`.pipe`).  The hot functions -- ``set_cart_pos``, ``set_axial_pos``, ``get_curr_pos`` --
touch only the shared records: a few microseconds, no system call, never waiting for the loop.

Which runner:

* ``"process"`` (the default for real robots): the loop has its own interpreter, so neither the
  application's garbage collector nor its threads holding the GIL can delay a reply; there it
  freezes and disables its own collector and shortens the switch interval.
* ``"thread"``: the loop shares the application's interpreter; start-up is instant and ``now_ns``
  can be injected -- what tests and the accelerated simulator use.

docs/kuka_rsi.md gives the measurements behind the choice.
"""
from __future__ import annotations

import itertools
import mmap
import select
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal, NamedTuple

import numpy as np

from core_functions.geometry import Pose
from robot_bridges.kuka_rsi.codec import PacketCodec
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink, RsiLoop
from robot_bridges.kuka_rsi.peer import resolve_ipv4
from robot_bridges.kuka_rsi.pipe import FramedPipe, PipeClosed
from robot_bridges.kuka_rsi.rt_process import spawn
from robot_bridges.kuka_rsi.slots import CommandKind, RobotSlots, Status, layout, robot_block_size
from robot_bridges.kuka_rsi.streaming import Space, ToolPath, check_tool_path, load_tool_path

RunnerMode = Literal["thread", "process"]


class CurrentPosition(NamedTuple):
    """ITRA's getCurrPos: the latest actual TCP and axes, with the loop's receive time."""

    t_us: float  # microseconds of the loop's monotonic clock
    ipoc: int
    cartesian: tuple[float, ...]  # x, y, z (m), A, B, C (rad)
    joints: tuple[float, ...]  # A1..A6 (rad)


@dataclass(frozen=True)
class RobotState:
    """Everything the loop published after its latest reply to one robot."""

    t_ns: int
    ipoc: int
    cycles: int
    delay: int
    status: int
    digouts: int  # bit i: the i-th BOOL of the <Rob> packet
    done_id: int
    done_ok: int
    active_id: int
    rejected: int
    clamped: int  # correction steps the limiter held back
    actual_cartesian: tuple[float, ...]  # RIst: m, rad
    set_cartesian: tuple[float, ...]  # RSol, as the controller reports it
    actual_joints: tuple[float, ...]  # AIPos: rad
    set_joints: tuple[float, ...]  # ASPos, as the controller reports it: for display, never to plan from
    commanded_joints: tuple[float, ...]  # the set point the external system commands: plan from this

    @property
    def connected(self) -> bool:
        return bool(self.status & Status.CONNECTED) and not self.status & Status.LOST

    @property
    def moving(self) -> bool:
        return bool(self.status & Status.MOVING)

    @property
    def correcting(self) -> bool:
        return bool(self.status & Status.CORRECTING)

    def tcp(self) -> Pose:
        x, y, z, a, b, c = self.actual_cartesian
        return Pose.from_xyz_rpy(x, y, z, roll=c, pitch=b, yaw=a)


class LoopEvents:
    """What the loop reported through the pipe, kept for whoever asks."""

    def __init__(self, robots: int) -> None:
        self.address: tuple[str, int] | None = None
        self.tuning = ""
        self.faults: list[tuple[int, str, str]] = []
        self.warnings: list[str] = []
        self.notes: list[str] = []  # what the loop found out once (the controller's set-point convention)
        self.inputs: list[dict[str, Any]] = [{} for _ in range(robots)]  # numeric signals the robot sends, by name
        self.inputs_cycle = [0] * robots  # the packet (loop count) they were last read from
        self.outputs: list[dict[str, tuple[Any, str]]] = [{} for _ in range(robots)]  # set signals: value sent or None, why not
        self.done: dict[int, tuple[bool, str, str]] = {}  # command id -> ok, message, fault kind
        self.progress: dict[int, float] = {}  # stream command id -> the path index it had reached when superseded
        self.connected = [False] * robots
        self.feedback: list[str | None] = [None] * robots  # the file each robot's packets are saved to
        self.flags_sent: list[int] = [0] * robots  # the <Sen> BOOLs of the latest reply that changed them
        self.stopped = False
        self.stats: tuple[Any, ...] | None = None
        self.peers: list[str | None] = [None] * robots  # the address each robot speaks from, once it has
        self.summary: str | None = None  # the loop's account of the run, when it has ended
        self.suspicious = False  # the summary names senders that are not the robots, or refusals

    def absorb(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "ready":
            self.address = (str(message[1]), int(message[2]))
            self.tuning = str(message[3])
        elif kind == "fault":
            self.faults.append((int(message[1]), str(message[2]), str(message[3])))
        elif kind == "warn":
            self.warnings.append(str(message[2]))
            del self.warnings[:-100]
        elif kind == "inputs":
            self.inputs[int(message[1])] = dict(message[2])
            self.inputs_cycle[int(message[1])] = int(message[3])
        elif kind == "output":
            self.outputs[int(message[1])][str(message[2])] = (message[3], str(message[4]))
        elif kind == "note":
            self.notes.append(str(message[3]))
            del self.notes[:-100]
        elif kind == "done":
            self.done[int(message[2])] = (bool(message[3]), str(message[4]), str(message[5]))
            if len(self.done) > 10_000:
                for key in list(self.done)[:5000]:
                    del self.done[key]
        elif kind == "progress":
            self.progress[int(message[2])] = float(message[3])
            if len(self.progress) > 1000:
                for key in list(self.progress)[:500]:
                    del self.progress[key]
        elif kind == "flags":
            self.flags_sent[int(message[1])] = int(message[2])
        elif kind == "feedback":
            self.feedback[int(message[1])] = message[2]
        elif kind == "connected":
            self.connected[int(message[1])] = True
        elif kind == "stopped":
            self.stopped = True
        elif kind == "stats":
            self.stats = message[1:]
        elif kind == "peer":
            self.peers[int(message[1])] = str(message[2])
        elif kind == "summary":
            self.summary, self.suspicious = str(message[1]), bool(message[2])


class RsiInterface:
    """The RSI manager and ITRA's setters and getters over it."""

    def __init__(
        self,
        links: Sequence[RobotLink],
        settings: LoopSettings = LoopSettings(),
        *,
        mode: RunnerMode = "process",
        now_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        """``now_ns`` is the timestamp source of the getters (and, for a loop thread, of the loop):
        the system-wide monotonic clock by default, so both sides of a process boundary agree."""
        if not links:
            raise ValueError("at least one robot")
        if mode not in ("thread", "process"):
            raise ValueError(f"runner mode is 'thread' or 'process', not {mode!r}")
        if mode == "process":
            # The loop owns this interpreter: collector off, short switch interval, and -- where the
            # system allows it -- a real-time scheduling class (priority 0 asks for none).
            priority = 10 if settings.realtime_priority is None else settings.realtime_priority
            settings = LoopSettings(
                **{
                    **settings.__dict__,
                    "gc_control": True,
                    "switch_interval": settings.switch_interval or 1e-4,
                    "realtime_priority": priority or None,
                }
            )
        # Names are resolved once, here: the loop compares the addresses datagrams come from as IPs.
        self.links = tuple(replace(link, host=resolve_ipv4(link.host, f"the address of robot {link.name}")) for link in links)
        self.settings = replace(settings, host=resolve_ipv4(settings.host, "the RSI listen address"))
        self.mode = mode
        self.now_ns = now_ns
        configs = [link.rsi_config() for link in self.links]
        self._flag_bits = [
            {f.key: bit for bit, f in enumerate(f for f in PacketCodec.sen(c).fields if f.type == "BOOL")} for c in configs
        ]
        self._digout_bits = [
            {f.key: bit for bit, f in enumerate(f for f in PacketCodec.rob(c).fields if f.type == "BOOL")} for c in configs
        ]
        self._flags = [0] * len(self.links)
        self._lock = threading.Lock()  # one writer per record among the application's threads
        self._ids = itertools.count(1)
        self._stream_keys = itertools.count(1)
        self.events = LoopEvents(len(self.links))
        self._mmap: mmap.mmap | None = None
        self._view: memoryview | None = None
        self._slots: list[RobotSlots] = []
        self._pipe: FramedPipe | None = None
        self._thread: threading.Thread | None = None
        self._process: subprocess.Popen[bytes] | None = None
        self.loop: RsiLoop | None = None  # the loop object itself, in thread mode (tests inspect it)

    # ------------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the loop (ITRA's openConn + startRSIManager); :meth:`wait_ready` or the
        ``ready`` event tells when the socket is bound."""
        size = robot_block_size() * len(self.links)
        if self.mode == "thread":
            ours, theirs = FramedPipe.pair()
            self._view = memoryview(bytearray(size))
            self._slots = layout(self._view, len(self.links))
            self.loop = RsiLoop(
                self.links, self.settings, self._slots, FramedPipe(theirs, blocking_send=False), self.now_ns
            )
            self._thread = threading.Thread(target=self.loop.run, name="rsi-manager", daemon=True)
            self._thread.start()
        else:
            self._process, self._mmap, ours = spawn(self.links, self.settings, size)
            self._view = memoryview(self._mmap)
            self._slots = layout(self._view, len(self.links))
        self._pipe = FramedPipe(ours, blocking_send=True)

    def close(self, timeout: float = 5.0) -> None:
        """Stop the loop and release everything (ITRA's terminateRSIManager + closeConn)."""
        if self._pipe is not None:
            try:
                self._pipe.send(("shutdown",))
            except PipeClosed:
                pass
        if self._thread is not None:
            self._thread.join(timeout)
        if self._process is not None:
            try:
                self._process.wait(timeout)
            except subprocess.TimeoutExpired:
                self._process.terminate()  # our own child, by its handle
                self._process.wait(timeout)
        if self._pipe is not None:
            try:
                self.poll_events()
            except PipeClosed:
                pass
            self._pipe.close()
            self._pipe = None
        self._slots = []
        if self._view is not None:
            self._view.release()
            self._view = None
        if self._mmap is not None:
            self._mmap.close()
            self._mmap = None

    def fileno(self) -> int:
        """The pipe to watch for events (asyncio ``add_reader``)."""
        assert self._pipe is not None, "start() first"
        return self._pipe.fileno()

    def poll_events(self) -> list[tuple[Any, ...]]:
        """Every event that has arrived, absorbed into :attr:`events` and returned."""
        assert self._pipe is not None, "start() first"
        messages = self._pipe.receive()
        for message in messages:
            self.events.absorb(message)
        return messages

    def wait_event(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Blocking wait (for scripts and benchmarks) until ``predicate()``; False after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            ready, _, _ = select.select([self.fileno()], [], [], remaining)
            if ready:
                try:
                    self.poll_events()
                except PipeClosed:
                    return predicate()
        return True

    def wait_ready(self, timeout: float = 30.0) -> tuple[str, int]:
        if not self.wait_event(lambda: self.events.address is not None or bool(self.events.faults) or self.events.stopped, timeout):
            raise TimeoutError(f"the RSI loop did not start within {timeout:g} s")
        if self.events.address is None:
            why = self.events.faults[-1][2] if self.events.faults else "the loop stopped"
            raise ConnectionError(why)
        return self.events.address

    # --------------------------------------------------------------------------- setters
    def set_axial_pos(self, robot: int, joints: Sequence[float], speed: float, accel: float, fraction: float = 0.0) -> int:
        """Aim robot ``robot`` at ``joints`` (rad) with at most ``speed`` (rad/s) and ``accel``
        (rad/s^2) per axis -- and, if ``fraction`` > 0, at most that fraction of each axis's own
        maximum speed; retargets a running move smoothly.  Returns the command id."""
        cmd = next(self._ids)
        j = joints
        with self._lock:
            self._slots[robot].command.write(CommandKind.JOINT, cmd, j[0], j[1], j[2], j[3], j[4], j[5], 0.0, speed, accel, fraction, 0.0)
        return cmd

    def set_cart_pos(
        self, robot: int, pose: Pose, speed: float, accel: float, angular_speed: float = 1.0, angular_accel: float = 2.0
    ) -> int:
        """Aim the TCP at ``pose`` (base frame) at most at ``speed`` (m/s), ``accel`` (m/s^2) and the
        angular limits (rad/s, rad/s^2); retargets a running move smoothly.  Returns the command id."""
        cmd = next(self._ids)
        p = pose
        with self._lock:
            self._slots[robot].command.write(
                CommandKind.CART, cmd, p.x, p.y, p.z, p.qx, p.qy, p.qz, p.qw, speed, accel, angular_speed, angular_accel
            )
        return cmd

    def halt(self, robot: int) -> int:
        """Brake to rest at the current limits and forget the target."""
        cmd = next(self._ids)
        with self._lock:
            self._slots[robot].command.write(CommandKind.HALT, cmd, *(0.0,) * 11)
        return cmd

    def set_speed_override(self, robot: int, rate: float) -> None:
        """Play every move and stream of robot ``robot`` at ``rate`` (0..1) of its speed, on its path, from the next cycle
        (a record of its own: it changes the running command, never supersedes it)."""
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"a speed override rate lies in [0, 1], got {rate!r}")
        with self._lock:
            self._slots[robot].override.write(float(rate))

    def set_tool_path(self, robot: int, path: ToolPath, *, max_speed: float = 2.0, max_angular_speed: float = 3.0) -> int:
        """Stream ``path`` one point per cycle (checked completely first: speeds, accelerations, an
        end at rest, against the link's limits); returns the command id."""
        link = self.links[robot]
        max_speed = min(max_speed, link.max_linear_speed)
        max_angular_speed = min(max_angular_speed, link.max_angular_speed)
        check_tool_path(
            path, link.cycle_ms / 1000.0, lower=np.array(link.lower), upper=np.array(link.upper),
            max_joint_speed=np.array(link.max_joint_speed), max_speed=max_speed, max_angular_speed=max_angular_speed,
            max_joint_accel=np.array(link.max_joint_accel), max_accel=link.max_linear_accel, max_angular_accel=link.max_angular_accel,
        )
        key = next(self._stream_keys)
        assert self._pipe is not None
        points = np.ascontiguousarray(path.points, dtype=np.float64)
        self._pipe.send(("stage", robot, key, path.space, points.tobytes(), len(path), path.source, path.lines))
        cmd = next(self._ids)
        with self._lock:
            self._slots[robot].command.write(CommandKind.STREAM, cmd, float(key), *(0.0,) * 6, max_speed, 0.0, max_angular_speed, 0.0)
        return cmd

    def set_tool_path_from_file(self, robot: int, file: str, space: Space, **limits: float) -> int:
        """ITRA's setToolPathFromFile: load, check, stream (see :mod:`.streaming` for the format)."""
        return self.set_tool_path(robot, load_tool_path(file, space), **limits)

    def set_flag(self, robot: int, tag: str, value: bool) -> None:
        """Set a BOOL of the ``<Sen>`` packet (a handshake flag, a tool output, Stop)."""
        bits = self._flag_bits[robot]
        if tag not in bits:
            raise KeyError(f"{tag!r} is not a BOOL the configuration sends to robot {self.links[robot].name} (has {', '.join(bits)})")
        with self._lock:
            if value:
                self._flags[robot] |= 1 << bits[tag]
            else:
                self._flags[robot] &= ~(1 << bits[tag])
            self._slots[robot].flags.write(self._flags[robot])

    # ITRA's logical setters: raise a flag, wait for the KRL program to acknowledge it on one of
    # its outputs, lower the flag.  They block (ITRA's took 10 to 100 ms); the back end has
    # asynchronous equivalents bounded in robot cycles.
    def handshake(self, robot: int, flag: str, ack: str, timeout: float = 5.0) -> None:
        """Raise ``flag``, wait (at most ``timeout`` s) until output ``ack`` is set, lower ``flag``."""
        raised = self.state(robot).cycles
        self.set_flag(robot, flag, True)
        try:
            # The flag leaves with the next reply and the robot answers in the packet after:
            # an acknowledgement counts from two packets on, never from what was there before.
            fresh = lambda: (st := self.state(robot)).cycles >= raised + 2 and self.digout(robot, ack, st)  # noqa: E731
            if not self.wait_event(fresh, timeout):
                raise TimeoutError(f"robot {self.links[robot].name} did not acknowledge {flag} on {ack} within {timeout:g} s")
        finally:
            self.set_flag(robot, flag, False)

    def allow_robot_start(self, robot: int, timeout: float = 5.0) -> None:
        roles = self.links[robot].roles
        self.handshake(robot, roles.allow_start, roles.task_active, timeout)

    def allow_robot_move(self, robot: int, timeout: float = 5.0) -> None:
        roles = self.links[robot].roles
        self.handshake(robot, roles.allow_move, roles.correction_active, timeout)

    def request_realtime_end(self, robot: int, timeout: float = 5.0) -> None:
        roles = self.links[robot].roles
        self.handshake(robot, roles.request_end, roles.realtime_ended, timeout)

    def allow_robot_finish(self, robot: int, timeout: float = 5.0) -> None:
        """Let the KRL task end (RSI stops then); returns once a reply has carried the flag."""
        tag = self.links[robot].roles.allow_finish
        self.set_flag(robot, tag, True)
        if not self.wait_event(lambda: self.flag_sent(robot, tag), timeout):
            raise TimeoutError(f"no reply to robot {self.links[robot].name} carried {tag} within {timeout:g} s")

    def flag_sent(self, robot: int, tag: str) -> bool:
        """Whether the latest reply that changed the flags carried ``tag`` set."""
        return bool(self.events.flags_sent[robot] >> self._flag_bits[robot][tag] & 1)

    def has_flag(self, robot: int, tag: str) -> bool:
        """Whether ``tag`` is a BOOL of the ``<Sen>`` packet (a flag :meth:`set_flag` can raise)."""
        return tag in self._flag_bits[robot]

    def flag(self, robot: int, tag: str) -> bool:
        return bool(self._flags[robot] >> self._flag_bits[robot][tag] & 1)

    def set_output(self, robot: int, key: str, value: object) -> None:
        """Set a numeric value of the ``<Sen>`` packet (a LONG, DOUBLE or STRING signal); ``events.outputs``
        tells once the loop has put it in a reply, or why it could not.  BOOLs are flags (:meth:`set_flag`)."""
        assert self._pipe is not None
        self.events.outputs[robot].pop(key, None)
        self._pipe.send(("output", robot, key, value))

    def set_feedback_output(self, robot: int, path: str | None) -> None:
        """ITRA's setRobFeedbackOutput: save every packet of ``robot`` to ``path`` (None: stop)."""
        assert self._pipe is not None
        self._pipe.send(("feedback", robot, path))

    def wake_at(self, robot: int, cycle: int) -> None:
        """Ask for a ``tick`` event once the loop has seen ``cycle`` packets of ``robot``."""
        assert self._pipe is not None
        self._pipe.send(("wake", robot, cycle))

    def withhold_replies(self, robot: int, count: int) -> None:
        """Fault injection: leave the next ``count`` packets of ``robot`` unanswered."""
        assert self._pipe is not None
        self._pipe.send(("withhold", robot, count))

    def request_stats(self) -> None:
        assert self._pipe is not None
        self._pipe.send(("stats",))

    # --------------------------------------------------------------------------- getters
    def get_curr_pos(self, robot: int) -> CurrentPosition:
        """ITRA's getCurrPos: the actual TCP and axes from the latest packet."""
        _, v = self._slots[robot].state.read()
        return CurrentPosition(v[0] / 1000.0, v[1], v[11:17], v[23:29])  # type: ignore[arg-type, operator]

    def get_timestamp(self) -> float:
        """ITRA's getTimestamp: microseconds of the clock the loop stamps packets with."""
        return self.now_ns() / 1000.0

    def state(self, robot: int) -> RobotState:
        _, v = self._slots[robot].state.read()
        ints = [int(x) for x in v[:11]]  # type: ignore[call-overload]
        return RobotState(*ints, v[11:17], v[17:23], v[23:29], v[29:35], v[35:41])  # type: ignore[arg-type]

    def digout(self, robot: int, tag: str, state: RobotState | None = None) -> bool:
        """A BOOL of the latest ``<Rob>`` packet by its tag (a handshake acknowledgement, a tool output)."""
        bits = self._digout_bits[robot]
        if tag not in bits:
            raise KeyError(f"{tag!r} is not a BOOL robot {self.links[robot].name} sends (has {', '.join(bits)})")
        st = state or self.state(robot)
        return bool(st.digouts >> bits[tag] & 1)

    def has_digout(self, robot: int, tag: str) -> bool:
        return tag in self._digout_bits[robot]

    def is_rsi_running(self, robot: int) -> bool:
        """ITRA's isRSIRunning: packets arrive from ``robot``."""
        return self.state(robot).connected
