"""The range of every numeric setting: command-line options, back-end options, ROS node parameters.

A setting can be a perfectly good float and still mean nothing: ``--speed 1e-300`` (a cycle in
10^293 years), ``connect_timeout=inf`` (a wait for ever), ``control_period=1e308`` (one step per
motion: no limit or collision check along it).  Python takes them all.  So every reader of a
numeric setting -- the CLI, the back ends' option parsers, the nodes' parameters -- takes its
range from this one table and refuses anything outside it in one line naming the setting and its
range.  The ranges are generous; what they exclude is a typo, a unit mix-up or a value no robot
cell could mean.  docs/faults.md, README.md and the back ends' docs show them.

One name, one range -- except where a back end reads an option of the same name with a meaning
of its own (``timeout``, ``tolerance_mm``): then each has its entry, scoped to that back end
(:class:`Setting`), and the docs show both.  The speed factor's limits are
:data:`node_transport.clock.MIN_SPEED` and ``MAX_SPEED``; the ``speed`` row here is the same
interval, for the tables and the readers below the clock.
"""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass


class RangeError(ValueError):
    """A setting outside its range (or not a number); the message names it and the range."""


@dataclass(frozen=True)
class Range:
    """The closed interval a setting may take, in ``unit``; ``integer`` settings take whole numbers.

    ``choices``: a setting that takes only some values of its interval (a KUKA controller's RSI
    cycle is 4 or 12 ms, nothing between) lists them, and only they are in range."""

    lower: float
    upper: float
    unit: str = ""
    integer: bool = False
    choices: tuple[float, ...] = ()

    def describe(self) -> str:
        """``[0.1, 600] s``, or ``4 or 12 ms``: the values as users read them (whole numbers for an integer setting)."""
        def shown(v: float) -> str:
            return f"{int(v)}" if self.integer else f"{v:g}"

        unit = f" {self.unit}" if self.unit else ""
        if self.choices:
            *first, last = (shown(v) for v in self.choices)
            return (f"{', '.join(first)} or {last}" if first else last) + unit
        return f"[{shown(self.lower)}, {shown(self.upper)}]{unit}"

    def contains(self, value: float) -> bool:
        inside = math.isfinite(value) and self.lower <= value <= self.upper and (not self.integer or float(value).is_integer())
        return inside and (not self.choices or value in self.choices)

    def check(self, name: str, value: object) -> float:
        """``value`` (a number, or its text) as a float within the range; RangeError naming ``name`` otherwise."""
        number = self._number(value)
        if number is None or not self.contains(number):
            kind = "a whole number" if self.integer else "a number"
            allowed = self.describe() if self.choices else f"{kind} in {self.describe()}"
            raise RangeError(f"{name} must be {allowed}, got {_shown(value)}")
        return number

    def check_int(self, name: str, value: object) -> int:
        """:meth:`check` for an integer setting, as an int."""
        return int(self.check(name, value))

    @staticmethod
    def _number(value: object) -> float | None:
        if isinstance(value, bool):
            return None
        if isinstance(value, (int, float)):
            return float(value)
        if isinstance(value, str):
            try:
                return float(value.strip())
            except ValueError:
                return None
        return None


def _shown(value: object) -> str:
    return repr(value) if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)


#: Seconds a peer may take to answer a command or a call: a tenth of a second to ten minutes.
ANSWER = Range(0.1, 600.0, "s")
#: The TCP/UDP port of a controller (0: pick a free one, where a simulator is started).
PORT = Range(0, 65535, integer=True)
#: A probability.
CHANCE = Range(0.0, 1.0)


@dataclass(frozen=True)
class Setting:
    """One numeric setting: its range, where it is read and what it is.

    ``scope`` is empty for a setting with one range wherever it is read; a back end (or program)
    that reads an option of the same name with a meaning of its own -- ``timeout`` is an ack
    allowance in seconds for V+ and a count of late packets for KUKA RSI -- has its own entry
    under that name with its name as ``scope``, and a reader of such a name must say whose it reads.
    """

    name: str
    allowed: Range
    where: str
    what: str
    scope: str = ""

    @property
    def shown(self) -> str:
        """``tolerance_mm (vplus)``: the name as the docs' table shows it."""
        return f"{self.name} ({self.scope})" if self.scope else self.name


#: Why a run may not start at speed_override 0 %: nothing would move, and its dry run could not plan it
#: (the command line, the run's settings and the engine's next-run answer say the same; here, below all three).
START_HELD = "a run cannot start at 0 %: every motion would wait before it began (0 % holds a running motion on its path)"

#: Every numeric setting.
SETTINGS: tuple[Setting, ...] = (
    # -- the run, launch and the nodes they start (CLI, node parameters)
    Setting("speed", Range(0.01, 1000.0, "x real time"),
            "run/launch/studio --speed, bridge parameter speed, vplus controller_speed, the simulators' --speed",
            "simulated seconds per wall second ('max' for simulated time, where offered)"),
    Setting("speed_override", Range(0.0, 100.0, "%"), "run --speed-override, engine parameter speed_override (changeable while it runs), the studio's slider",
            "the share of the application's own speed every motion runs at, on its path (0: held on the path)"),
    Setting("seed", Range(0, 2**32 - 1, integer=True), "--seed, bridge parameter seed, the KR C4 simulator's --seed",
            "the simulator's random seed (vision noise, injected faults)"),
    Setting("port", PORT, "run --port, studio --port and --controller-port, bridge parameter port, the simulators' --port and --flood-port",
            "a TCP/UDP port (0: a free one, where this program listens)"),
    Setting("grace", Range(0.0, 600.0, "s"), "launch --grace", "how long the engine may end its run by itself after another node died"),
    Setting("stop_timeout", Range(0.1, 600.0, "s"), "launch --stop-timeout, bridge parameter stop_timeout",
            "how long a node (a stopped primitive) may take to stop"),
    # -- the Nextage simulator
    Setting("control_period", Range(0.001, 0.5, "s"), "nextage-sim option and parameter control_period",
            "simulation step: joint limits are checked at every one, collisions once per motion (the dry run uses 0.5)"),
    # -- V+
    Setting("timeout", ANSWER, "vplus option and parameter timeout", "ack allowance per command on top of its motion time", "vplus"),
    Setting("retries", Range(0, 100, integer=True), "vplus option and parameter retries", "connection attempts after the first"),
    Setting("tolerance_mm", Range(0.01, 50.0, "mm"), "vplus option and parameter tolerance_mm",
            "how far a reported position may lie from the commanded one", "vplus"),
    Setting("tolerance_deg", Range(0.01, 10.0, "deg"), "vplus option and parameter tolerance_deg",
            "how far a reported orientation may lie from the commanded one"),
    Setting("max_clients", Range(1, 1000, integer=True), "V+ simulator --max-clients", "clients served at once"),
    Setting("idle_timeout", Range(0.001, 86_400.0, "s"), "V+ simulator --idle-timeout", "a client that sent no whole message this long is closed"),
    Setting("reclaim_after", Range(0.001, 86_400.0, "s"), "V+ simulator --reclaim-after",
            "with every slot taken, a new client takes the slot of one idle this long"),
    Setting("run_for", Range(0.001, 604_800.0, "s"), "V+ simulator --run-for", "run time after which the simulator stops by itself (a week at most)"),
    # -- KUKA RSI and the KR C4 simulator
    Setting("cycle", Range(4, 12, "ms", integer=True, choices=(4, 12)), "kuka-rsi option and parameter cycle, KR C4 simulator --cycle",
            "the controller's RSI cycle: 4 or 12 ms, nothing between"),
    Setting("timeout", Range(1, 100_000, integer=True), "kuka-rsi option and parameter timeout, KR C4 simulator --timeout",
            "late packets in a row that stop the simulated RSI", "kuka-rsi"),
    Setting("axis_monitor", Range(0.001, 360.0, "deg"), "kuka-rsi option and parameter axis_monitor, KR C4 simulator --axis-monitor",
            "the simulated AXISCORRMON limit"),
    Setting("silence", Range(0.01, 10.0, "s"), "kuka-rsi option and parameter silence (the parameter's 0: the back end's default)",
            "time without packets that means the robot is lost"),
    Setting("connect_timeout", ANSWER, "kuka-rsi option and parameter connect_timeout", "time to the controller's first valid packet"),
    Setting("linear_speed", Range(0.001, 10.0, "m/s"), "kuka-rsi option and parameter linear_speed", "TCP speed at 100 %"),
    Setting("linear_accel", Range(0.001, 100.0, "m/s^2"), "kuka-rsi option and parameter linear_accel", "TCP acceleration at 100 %"),
    Setting("tolerance", Range(0.001, 10.0, "deg"), "kuka-rsi option and parameter tolerance",
            "how far a reported axis set point may lie from the commanded one"),
    Setting("tolerance_mm", Range(0.001, 100.0, "mm"), "kuka-rsi option and parameter tolerance_mm",
            "how far the reported TCP may lie from the commanded one", "kuka-rsi"),
    Setting("follow_time", Range(0.004, 1.0, "s"), "kuka-rsi option and parameter follow_time",
            "how long the actual axes may trail the commanded set point where the controller reports none that follows"),
    Setting("sim_drop", CHANCE, "kuka-rsi option sim_drop, KR C4 simulator --drop", "probability the simulated controller discards a reply"),
    Setting("loss", CHANCE, "KR C4 simulator --loss", "probability a packet the simulated controller sends is lost"),
    Setting("garbage", CHANCE, "KR C4 simulator --garbage", "probability a packet the simulated controller sends is garbage"),
    Setting("jitter_ms", Range(0.0, 1000.0, "ms"), "KR C4 simulator --jitter-ms", "random delay of each packet the simulated controller sends"),
    Setting("cycles", Range(1, 10**12, integer=True), "KR C4 simulator --cycles", "cycles after which the simulator stops by itself"),
    Setting("ipoc_step", Range(1, 1000, integer=True), "KR C4 simulator --ipoc-step", "the IPOC time stamp's step per cycle"),
    Setting("reply_grace", Range(0.0, 60.0, "s"), "KR C4 simulator --reply-grace", "accelerated mode: wall time a reply is waited for (0: none)"),
    Setting("rt_priority", Range(0, 99, integer=True), "KR C4 simulator --rt-priority", "SCHED_FIFO priority asked for (0: none)"),
    # -- ros2-control (any robot whose driver serves FollowJointTrajectory)
    Setting("acceleration_time", Range(0.05, 60.0, "s"), "ros2-control option acceleration_time",
            "how long a joint takes to reach its URDF speed limit (sets the accelerations: URDF gives none)"),
    Setting("state_timeout", Range(0.01, 60.0, "s"), "ros2-control option state_timeout", "joint_states older than this while the robot is used is a fault"),
    Setting("start_timeout", ANSWER, "ros2-control option start_timeout", "wait for robot_description, joint_states and the controllers' actions at start"),
    Setting("goal_tolerance", Range(1e-5, 0.5, "rad"), "ros2-control option goal_tolerance", "how far from its target a joint may end a motion"),
    Setting("result_timeout", ANSWER, "ros2-control option result_timeout", "wait for a result after a trajectory's end, and for a stopped arm"),
    Setting("gripper_position", Range(-10.0, 10.0, "m"), "ros2-control options GROUP.gripper_open and GROUP.gripper_closed",
            "the GripperCommand position of an open and of a closed gripper"),
    Setting("gripper_effort", Range(0.0, 1e5, "N"), "ros2-control option GROUP.gripper_effort", "the GripperCommand max_effort (0: the controller's default)"),
    # -- vision detect
    Setting("focal_length", Range(0.1, 1e6, "px"), "vision detect --fx, --fy", "the camera's focal length"),
    Setting("principal_point", Range(-1e6, 1e6, "px"), "vision detect --cx, --cy", "the camera's principal point"),
    Setting("distance", Range(0.001, 100.0, "m"), "vision detect --distance", "distance of the plane along the optical axis"),
    Setting("diameter", Range(1e-5, 1.0, "m"), "vision detect --diameter", "the expected hole diameter"),
    # -- node parameters
    Setting("startup_timeout", Range(0.1, 3600.0, "s"), "engine parameter", "how long to wait for the group machines"),
    Setting("function_timeout", Range(1.0, 86_400.0, "s"), "engine parameter", "longest a function may take"),
    Setting("service_timeout", ANSWER, "engine parameter", "machine service call timeout"),
    Setting("bridge_timeout", ANSWER, "machine parameter", "how fast a bridge must acknowledge a command"),
    Setting("primitive_timeout", Range(1.0, 86_400.0, "s"), "machine parameter", "longest a primitive may run"),
    Setting("sync_timeout", Range(0.1, 3600.0, "s"), "machine parameter", "how long partners may take to meet at a barrier"),
    Setting("state_period", Range(0.001, 1.0, "s"), "bridge parameter", "joint_states / tcp_pose period"),
    Setting("camera_timeout", Range(0.01, 600.0, "s"), "bridge parameter; ros2-control option camera_timeout", "longest wait for an image from a ROS camera"),
    Setting("camera_rate", Range(0.1, 60.0, "Hz"), "camera-sim --rate", "images per second each simulated camera publishes"),
)

#: The settings by (scope, name).
OPTIONS: dict[tuple[str, str], Setting] = {(s.scope, s.name): s for s in SETTINGS}


def setting(name: str, scope: str = "") -> Setting:
    """Setting ``name`` as ``scope`` reads it: its own entry, else the one every reader shares
    (KeyError for a name the table lacks, or one with only scoped entries read without a scope: a defect)."""
    found = OPTIONS.get((scope, name)) or OPTIONS.get(("", name))
    if found is None:
        raise KeyError(f"no range for setting {name!r}" + (f" of {scope}" if scope else ""))
    return found


def bounds(name: str, scope: str = "") -> Range:
    """The range of setting ``name`` (as ``scope`` reads it)."""
    return setting(name, scope).allowed


def check(name: str, value: object, *, label: str | None = None, scope: str = "") -> float:
    """``value`` of setting ``name`` within its range; RangeError naming ``label`` (default ``name``)."""
    return bounds(name, scope).check(label or name, value)


def check_int(name: str, value: object, *, label: str | None = None, scope: str = "") -> int:
    return bounds(name, scope).check_int(label or name, value)


def argument_type(name: str, scope: str = "", *, label: str | None = None) -> Callable[[str], float]:
    """An argparse ``type=`` taking a value of setting ``name`` in its range: argparse's own one-line error otherwise.
    ``label``: how the refusal names the value (default the setting's name)."""
    allowed = bounds(name, scope)

    def parse(text: str) -> float:
        try:
            value = allowed.check(label or name, text)
        except RangeError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return int(value) if allowed.integer else value

    parse.__name__ = name  # argparse names the type in some messages
    return parse


def table() -> list[tuple[str, str, str, str]]:
    """(setting, range, where, what) for the docs; a scoped setting shown as ``name (scope)``."""
    return [(s.shown, s.allowed.describe(), s.where, s.what) for s in SETTINGS]
