"""The loaded application: what the engine runs, checked and normalised, with source positions.

Immutable, so the engine, the CLI and viewers can share one instance without copies.  Params stay
the texts of ``<param value=...>`` -- the group machine parses them with the same catalog that
validated them -- but positional and complete: optional params left out are filled with their
defaults, and a group left out of an operation gets an explicit, ``implicit=True`` wait call.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from core_functions.robots import RobotModel
from execution_engine.app_model.cell import Cell

ErrorAction = Literal["abort", "safe_pose", "alarm"]
#: How long an alarm waits for an operator by default: ten minutes of wall time, time enough to walk
#: to the cell and look, short enough that an unattended cell does not sit in an alarm for a shift.
#: (Nobody to answer at all -- no terminal, no service client -- ends the run at once.)
ALARM_TIMEOUT = 600.0
WAIT = "wait"


@dataclass(frozen=True)
class ErrorPolicy:
    """What the engine does when a function fails (paper: error handling; docs/application_xml.md)."""

    retries: int = 0
    action: ErrorAction = "abort"
    safe_pose: str | None = None  # a robot pose or a cell <joint_pose>; None when the robot has none
    alarm_timeout: float = ALARM_TIMEOUT  # wall seconds an alarm waits for an operator reset; 0 = the longest, a day
    safe_speed: float = 0.3  # speed fraction of the move to the safe pose (after the retreat)
    retreat: float = 0.05  # m an arm backs out along its tool axis before the safe pose; 0 = none


@dataclass(frozen=True, slots=True)  # slots: a 10^5-call application holds 10^5 of these
class Call:
    """One group's function in one operation."""

    group: str
    function: str
    params: tuple[str, ...]
    implicit: bool = False  # True: the group was left out of the operation and waits
    file: str = ""
    line: int = 0
    col: int = 0

    @property
    def is_wait(self) -> bool:
        return self.function == WAIT


@dataclass(frozen=True, slots=True)
class Condition:
    """An ``<if>`` an operation is inside: ``group``'s function in operation ``operation`` ended
    with ``outcome`` (``holds``) or with any other (``not holds``: the ``<else>``)."""

    operation: str
    group: str
    outcome: str
    holds: bool = True

    def met(self, outcome: str | None) -> bool:
        return (outcome == self.outcome) == self.holds

    def describe(self) -> str:
        return f"{self.group} {self.operation} {'==' if self.holds else '!='} {self.outcome}"


@dataclass(frozen=True, slots=True)
class Operation:
    """One step: every group of the robot has a call (in the robot's group order).

    ``origin``: the iteration an operation written inside a loop or a called application was
    made for (``for_each hole=drill_3``, nested ones joined by `` > ``); "" for one written at the
    top of the file.  Its ``line`` and ``col`` are those of the ``<operation>`` inside the loop."""

    id: str
    name: str | None
    line: int
    col: int
    calls: Mapping[str, Call]
    origin: str = ""
    #: The <if>/<else> it is inside, outermost first: it runs only when every one is met.
    when: tuple[Condition, ...] = ()
    #: ``break="true"``: the run pauses before it (execution_engine/engine/breakpoints.py); an operation a
    #: loop makes from it breaks in every iteration.  Not part of equality: it changes nothing the robot does, so
    #: a dry run's kept verdict (its key digests the application) holds with breakpoints set or cleared.
    breakpoint: bool = field(default=False, compare=False)


@dataclass(frozen=True)
class Application:
    """A validated application file."""

    name: str
    path: Path
    robot: RobotModel
    cell: Cell | None
    error_policy: ErrorPolicy
    operations: tuple[Operation, ...]
    description: str = ""
    version: str | None = None
    #: ``operation`` (lock-step: every operation a barrier) or ``flags`` (each group in its own
    #: order, waiting only at wait_flag, synchronised functions and zones).
    sync: str = "operation"
    #: The applications its ``<call>`` elements include (resolved paths, each once): a resume
    #: checks them as it checks the application itself.
    includes: tuple[Path, ...] = ()
    #: Functions an <if> tested before its branches were resolved (a dry run's pass): their outcome
    #: faults stay outcomes, not findings, though no operation carries the condition any more.
    resolved_tests: frozenset[tuple[str, str]] = frozenset()

    def tested(self) -> frozenset[tuple[str, str]]:
        """(operation, group) of every function an <if> tests: its outcome faults end it with that outcome."""
        return self.resolved_tests | frozenset((c.operation, c.group) for operation in self.operations for c in operation.when)

    def iterations(self) -> dict[str, str]:
        """The origin of every operation made by a loop or a call, by operation id."""
        return {operation.id: operation.origin for operation in self.operations if operation.origin}

    def operation(self, operation_id: str) -> Operation:
        for operation in self.operations:
            if operation.id == operation_id:
                return operation
        raise KeyError(operation_id)
