"""The range of every numeric setting: command-line options, back-end options, ROS node parameters.

A setting can be a perfectly good float and still mean nothing: ``--speed 1e-300`` (a cycle in
10^293 years), ``connect_timeout=inf`` (a wait for ever), ``control_period=1e308`` (one step per
motion: no limit or collision check along it).  Python takes them all.  So every reader of a
numeric setting -- the CLI, the back ends' option parsers, the nodes' parameters -- takes its
range from this one table and refuses anything outside it in one line naming the setting and its
range.  The ranges are generous; what they exclude is a typo, a unit mix-up or a value no robot
cell could mean.  docs/faults.md, README.md and the back ends' docs show them.

The speed factor's limits are :data:`execution_engine.clock.MIN_SPEED` and ``MAX_SPEED``; the
``speed`` row here is the same interval, for the tables and the readers below the clock.
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
    """The closed interval a setting may take, in ``unit``; ``integer`` settings take whole numbers."""

    lower: float
    upper: float
    unit: str = ""
    integer: bool = False

    def describe(self) -> str:
        """``[0.1, 600] s``: the interval as users read it (whole numbers for an integer setting)."""
        low, high = (f"{int(v)}" if self.integer else f"{v:g}" for v in (self.lower, self.upper))
        return f"[{low}, {high}]" + (f" {self.unit}" if self.unit else "")

    def contains(self, value: float) -> bool:
        return math.isfinite(value) and self.lower <= value <= self.upper and (not self.integer or float(value).is_integer())

    def check(self, name: str, value: object) -> float:
        """``value`` (a number, or its text) as a float within the range; RangeError naming ``name`` otherwise."""
        number = self._number(value)
        if number is None or not self.contains(number):
            kind = "a whole number" if self.integer else "a number"
            raise RangeError(f"{name} must be {kind} in {self.describe()}, got {_shown(value)}")
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

#: Every numeric setting by name: (range, where it is read, what it is).
OPTIONS: dict[str, tuple[Range, str, str]] = {
    # -- the run (CLI)
    "speed": (Range(0.01, 1000.0, "x real time"), "run/launch --speed, bridge parameter speed, vplus controller_speed",
              "simulated seconds per wall second ('max' for simulated time, where offered)"),
    "seed": (Range(0, 2**32 - 1, integer=True), "--seed, bridge parameter seed", "the simulator's random seed (vision noise)"),
    "port": (PORT, "--port, bridge parameter port", "the controller's port"),
    "grace": (Range(0.0, 600.0, "s"), "launch --grace", "how long the engine may end its run by itself after another node died"),
    "stop_timeout": (Range(0.1, 600.0, "s"), "launch --stop-timeout, bridge parameter stop_timeout",
                     "how long a node (a stopped primitive) may take to stop"),
    # -- the Nextage simulator
    "control_period": (Range(0.001, 0.5, "s"), "nextage-sim option and parameter control_period",
                       "simulation step: joint limits and collisions are checked at every one (the dry run uses 0.5)"),
    # -- V+
    "timeout": (ANSWER, "vplus option and parameter timeout", "ack allowance per command on top of its motion time"),
    "retries": (Range(0, 100, integer=True), "vplus option and parameter retries", "connection attempts after the first"),
    # -- KUKA RSI
    "rsi_timeout": (Range(1, 100_000, integer=True), "kuka-rsi option timeout", "late packets in a row that stop the simulated RSI"),
    "axis_monitor": (Range(0.001, 360.0, "deg"), "kuka-rsi option axis_monitor", "the simulated AXISCORRMON limit"),
    "silence": (Range(0.01, 10.0, "s"), "kuka-rsi option silence", "time without packets that means the robot is lost"),
    "connect_timeout": (ANSWER, "kuka-rsi option connect_timeout", "time to the controller's first valid packet"),
    "linear_speed": (Range(0.001, 10.0, "m/s"), "kuka-rsi option linear_speed", "TCP speed at 100 %"),
    "linear_accel": (Range(0.001, 100.0, "m/s^2"), "kuka-rsi option linear_accel", "TCP acceleration at 100 %"),
    "tolerance": (Range(0.001, 10.0, "deg"), "kuka-rsi option tolerance", "how far a reported axis set point may lie from the commanded one"),
    "tolerance_mm": (Range(0.001, 100.0, "mm"), "kuka-rsi option tolerance_mm", "how far the reported TCP may lie from the commanded one"),
    "sim_drop": (Range(0.0, 1.0), "kuka-rsi option sim_drop", "probability the simulated controller discards a reply"),
    # -- node parameters
    "startup_timeout": (Range(0.1, 3600.0, "s"), "engine parameter", "how long to wait for the group machines"),
    "function_timeout": (Range(1.0, 86_400.0, "s"), "engine parameter", "longest a function may take"),
    "service_timeout": (ANSWER, "engine parameter", "machine service call timeout"),
    "bridge_timeout": (ANSWER, "machine parameter", "how fast a bridge must acknowledge a command"),
    "primitive_timeout": (Range(1.0, 86_400.0, "s"), "machine parameter", "longest a primitive may run"),
    "sync_timeout": (Range(0.1, 3600.0, "s"), "machine parameter", "how long partners may take to meet at a barrier"),
    "state_period": (Range(0.001, 1.0, "s"), "bridge parameter", "joint_states / tcp_pose period"),
    "camera_timeout": (Range(0.01, 600.0, "s"), "bridge parameter", "longest wait for an image from a ROS camera"),
}


def bounds(name: str) -> Range:
    """The range of setting ``name`` (KeyError for a name the table lacks: a defect)."""
    return OPTIONS[name][0]


def check(name: str, value: object, *, label: str | None = None) -> float:
    """``value`` of setting ``name`` within its range; RangeError naming ``label`` (default ``name``)."""
    return bounds(name).check(label or name, value)


def check_int(name: str, value: object, *, label: str | None = None) -> int:
    return bounds(name).check_int(label or name, value)


def argument_type(name: str) -> Callable[[str], float]:
    """An argparse ``type=`` taking a value of setting ``name`` in its range: argparse's own one-line error otherwise."""
    allowed = bounds(name)

    def parse(text: str) -> float:
        try:
            value = allowed.check(name, text)
        except RangeError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return int(value) if allowed.integer else value

    parse.__name__ = name  # argparse names the type in some messages
    return parse


def table() -> list[tuple[str, str, str, str]]:
    """(setting, range, where, what) for the docs."""
    return [(name.removeprefix("rsi_"), r.describe(), where, what) for name, (r, where, what) in OPTIONS.items()]
