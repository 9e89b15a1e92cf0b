"""The operator's speed override: one value for the whole cell, from the page, the terminal or a parameter.

The engine owns it because the engine is what operators talk to: the parameter ``speed_override``
(percent, 0..100, changeable while the node runs -- ``ros2 param set``), the terminal console of
``run --interactive`` and the studio's slider all come here, and every change is recorded like an
operator command (trace, events, the run report) with its source and run time.  The value travels
to every bridge in the engine's latched status (``EngineStatus.speed_override``); each back end
plays its running motion at that share of its planned speed on its path (robot_bridges/path_rate.py),
so the robot is never faster than the application wrote, and 0 % is a controlled stop on the path
that resumes where it stopped -- not a pause of the state machine, which goes on waiting for the
motion to end.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from core_functions.option_ranges import START_HELD, RangeError, bounds
from execution_engine.engine.report import OperatorAction
from node_transport.bounded import declare_bounded
from node_transport.parameters import ParameterValue
from node_transport.port import Node, ParameterChange

PARAMETER = "speed_override"
#: How the engine's status says the robot stands still at 0 %.
HOLDING = "speed override 0 %: holding on the path"
#: The operator command's name in the trace, the events and the report.
COMMAND = "speed_override"


def shown(percent: float) -> str:
    """``50 %``, ``12.5 %``."""
    return f"{percent:g} %"


def speed_for_next_run(percent: object) -> tuple[bool, str]:
    """Whether ``percent`` may be the next run's override, and the answer the operator reads."""
    value = percent if isinstance(percent, (int, float)) and not isinstance(percent, bool) else math.nan
    refusal = SpeedOverride.refusal(float(value)) or (START_HELD if value == 0 else "")
    return (False, refusal) if refusal else (True, f"speed override {shown(float(value))} for the next run")


@dataclass(frozen=True)
class SpeedChange:
    """One change of the override: when (run time), to what (percent), from where."""

    t: float
    percent: float
    source: str


class SpeedOverride:
    """The engine's speed override and its history."""

    def __init__(self, node: Node, record: Callable[[OperatorAction], None], publish: Callable[[], None], state: Callable[[], str]) -> None:
        self.node = node
        self._record = record
        self._publish = publish
        self._state = state
        self.percent = float(declare_bounded(node, PARAMETER, 100.0, "share of the application's own speed every motion runs at, on its path (0: held on the path); changeable while the engine runs"))
        node.changeable_parameter(PARAMETER, ParameterChange(self.refusal, self._from_parameter))
        self.changes: list[SpeedChange] = []

    @staticmethod
    def refusal(value: ParameterValue) -> str:
        """Why ``value`` cannot be the override ("" when it can)."""
        try:
            bounds(PARAMETER).check(f"parameter {PARAMETER!r}", value)
        except RangeError as error:
            return str(error)
        return ""

    def _from_parameter(self, value: ParameterValue) -> None:
        if value != self.percent:  # not the echo of a change that came another way (show_parameter)
            self.set(value, f"parameter {self.node.fully_qualified_name}/{PARAMETER}", parameter=False)

    def set(self, percent: object, source: str, *, parameter: bool = True) -> tuple[bool, str]:
        """Take (or refuse, changing nothing) a new override from ``source``; the answer the operator reads."""
        value = percent if isinstance(percent, (int, float)) and not isinstance(percent, bool) else math.nan
        refusal = self.refusal(float(value))
        now = self.node.clock.now()
        if refusal:
            self._record(OperatorAction(now, COMMAND, source, self._state(), False, refusal))
            return False, refusal
        value = float(value)
        previous, self.percent = self.percent, value
        if parameter:  # the parameter shows the value whichever way it came (ros2 param get)
            self.node.show_parameter(PARAMETER, value)
        self.changes.append(SpeedChange(now, value, source))
        answer = f"speed override {shown(value)} (was {shown(previous)})" + (f"; {HOLDING.split(': ', 1)[1]}" if value == 0.0 else "")
        self._record(OperatorAction(now, COMMAND, source, self._state(), True, answer, f"{value:g}"))  # the trace's percent
        self._publish()
        return True, answer

    def status_message(self, message: str) -> str:
        """The engine status's message: at 0 % it says the robot holds on its path."""
        if self.percent > 0.0:
            return message
        return HOLDING if not message else f"{message}; {HOLDING}"
