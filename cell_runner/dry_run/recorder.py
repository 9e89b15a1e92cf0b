"""Collects what a dry run meets: findings at their XML calls, and the timeline of every group.

The back-end decorator and the trajectory store report here as the application runs; the
recorder knows which call of the application a group is in (the running function of that
group's machine) and where that call is written, so a problem found deep inside a skill is
reported at the line of the ``<function>`` that asked for it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from cell_runner.dry_run.report import Finding, FoundBody, JointPositions, Span, TimeBase
from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from execution_engine.app_model.model import Application, Call
from execution_engine.engine.waits import FlagWait
from node_transport.clock import Clock

#: Where a group is: (operation id, function) of the function its machine runs, or None.
CallLocator = Callable[[str], tuple[str, str] | None]


class ClockTiming:
    """Times on the application's simulated clock, relative to the start of the run."""

    base: TimeBase = "simulated clock"

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.origin = 0.0
        if not clock.simulated:  # a mixed cell's dry run with a robot in real time (dry_run/simulators.py)
            self.base = "wall clock"

    def start(self) -> None:
        self.origin = self.clock.now()

    def now(self) -> float:
        return self.clock.now() - self.origin

    def place(self, groups: tuple[str, ...], start: float, end: float) -> tuple[float, float]:
        return start, end

    def elapsed(self) -> float:
        return self.now()

    def of_clock(self, t: float) -> float:
        """A run time of the application's clock (an engine report's) on this time base."""
        return t - self.origin


class CycleTiming:
    """Times in the robot's own cycles, for a controller simulator that does not run on our clock.

    Such a simulator (RSI's accelerated KR C4) runs as fast as it is answered, so the time between
    two primitives says nothing; each primitive's duration in robot cycles does.  Primitives are
    laid back to back per group -- exact for the one-group robots these simulators drive.
    """

    base: TimeBase = "robot cycles"

    def __init__(self, read: Callable[[], float]) -> None:
        self.read = read
        self._cursor: dict[str, float] = {}

    def start(self) -> None:
        self._cursor.clear()

    def now(self) -> float:
        return self.read()

    def place(self, groups: tuple[str, ...], start: float, end: float) -> tuple[float, float]:
        at = max((self._cursor.get(g, 0.0) for g in groups), default=0.0)
        finish = at + max(0.0, end - start)
        for group in groups:
            self._cursor[group] = finish
        return at, finish

    def elapsed(self) -> float:
        return max(self._cursor.values(), default=0.0)

    def of_clock(self, t: float) -> float:
        """The application's clock says nothing about robot time here: as far as the robot got."""
        return self.elapsed()


Timing = ClockTiming | CycleTiming


@dataclass(frozen=True)
class Contradiction:
    """A tested function the pass assumed ended ``assumed``, which the simulated cell ended ``outcome`` (with
    ``kind`` on ``target``: vision not finding drill_3)."""

    assumed: str
    outcome: str
    kind: str
    target: str
    message: str


@dataclass(frozen=True)
class Deferred:
    """A fault met on a side of an ``<if>`` of the kind its tested function ends with, held back (:meth:`Recorder.defer`)."""

    group: str
    operation: str
    function: str
    kind: str
    primitive: str
    target: str
    message: str
    t: float
    tested: tuple[tuple[str, str], ...]
    span: int  # its place in Recorder.spans
    joints: JointPositions | None = None  # where the robot was (Finding.joints)
    where: Pose | None = None  # the TCP target refused (Finding.target)


class Recorder:
    """Findings (one per call and kind, counted) and spans, as the dry run goes."""

    def __init__(self, app: Application, timing: Timing) -> None:
        self.app = app
        self.robot: RobotModel = app.robot
        self.timing = timing
        self.locate: CallLocator = lambda group: None
        self._calls: dict[tuple[str, str], Call] = {
            (operation.id, group): call for operation in app.operations for group, call in operation.calls.items()
        }
        self._lines = {operation.id: (operation.line, operation.col) for operation in app.operations}
        self._origins = app.iterations()  # the loop iteration or call each expanded operation was made for
        self._findings: dict[tuple[str, str, str], Finding] = {}  # (operation, group, kind) -> the first one
        self._counts: dict[tuple[str, str, str], int] = {}
        self.spans: list[Span] = []
        self.waits: list[FlagWait] = []  # the engine's waits for flags and zones (sync="flags")
        self.notes: list[str] = []  # what could not be checked
        #: The fault kinds that end a tested function with an outcome, by (operation, group): the
        #: pass assumed that outcome (dry_run/branches.py), so meeting one is no finding.
        self.outcome_faults: dict[tuple[str, str], frozenset[str]] = {}
        #: The pass's assumption (dry_run/branches.py): the outcome assumed of each tested function, the outcome
        #: each of its faults stands for, and the tested functions each operation's side depends on.
        self.assumed: dict[tuple[str, str], str] = {}
        self.fault_outcomes: dict[tuple[str, str], dict[str, str]] = {}
        self.sides: dict[str, frozenset[tuple[str, str]]] = {}
        self._contradicted: dict[tuple[str, str], Contradiction] = {}
        self._deferred: list[Deferred] = []
        self._excused: dict[tuple[str, str], list[Deferred]] = {}

    def is_outcome(self, group: str, kind: str) -> bool:
        """Whether ``kind`` of a fault of the call ``group`` runs now is one of its tested outcomes."""
        where = self.locate(group)
        return where is not None and kind in self.outcome_faults.get((where[0], group), frozenset())

    # ------------------------------------------------------------------ assumed outcomes
    def outcome_met(self, group: str, kind: str, target: str, message: str) -> None:
        """The call ``group`` runs now, a tested one, ended with its outcome fault ``kind`` on ``target``: when the
        pass assumed another outcome (found, where the simulated cell has no hole), the cell contradicts it."""
        where = self.locate(group)
        if where is None:
            return
        key = (where[0], group)
        outcome, assumed = self.fault_outcomes.get(key, {}).get(kind), self.assumed.get(key)
        if outcome is not None and assumed is not None and outcome != assumed and key not in self._contradicted:
            self._contradicted[key] = Contradiction(assumed, outcome, kind, target, message)

    def defer(self, group: str, held: tuple[str, ...], kind: str, primitive: str, target: str, message: str, start: float, end: float, *,
              joints: JointPositions | None = None, pose: Pose | None = None) -> bool:
        """Hold back a fault met on a side of an ``<if>`` until the run ends (:meth:`findings`): it is no finding when
        it is the one the function the side tests met on the same target, the pass having assumed otherwise --
        the consequence of the assumption, not of the application.  Its span goes on the timeline now, marked
        with the fault if it turns out a finding.  False: not such a fault, report it now."""
        where = self.locate(group)
        if where is None or not target:
            return False
        tested = [key for key in self.sides.get(where[0], ()) if kind in self.fault_outcomes.get(key, {})]
        if not tested:
            return False
        span = self.span(group, held, primitive, start, end)
        held_back = Deferred(group, where[0], where[1], kind, primitive, target, message, span.end, tuple(tested), len(self.spans) - 1, joints, pose)
        self._deferred.append(held_back)
        return True

    def _settle(self) -> None:
        """Each held-back fault: excused by the contradicted assumption it follows from, or a finding after all."""
        for held in self._deferred:
            cause = next((key for key in held.tested if (c := self._contradicted.get(key)) is not None
                          and (c.kind, c.target) == (held.kind, held.target)), None)
            if cause is None:
                self.spans[held.span] = replace(self.spans[held.span], finding=held.kind)
                self.add(held.group, held.operation, held.function, held.kind, held.primitive, held.message, held.t, joints=held.joints, target=held.where)
            else:
                self._excused.setdefault(cause, []).append(held)
        self._deferred.clear()

    def assumption_notes(self) -> list[str]:
        """What each contradicted assumption left unchecked on its side, and what was checked instead."""
        self._settle()
        out = []
        for (operation, group), c in self._contradicted.items():
            calls = list(dict.fromkeys(f"{h.operation} {h.group} {h.function}" for h in self._excused.get((operation, group), [])))
            said = f"{operation} {group} assumed {c.assumed} where the simulated cell ended it {c.outcome} ({c.message})"
            if calls:
                out.append(f"{said}: on that side, the {c.kind} of {c.target} by {', '.join(calls)} not checked, "
                           f"their motions checked at {c.target}'s nominal pose")
            else:
                out.append(f"{said}: nothing on that side looked at {c.target} again")
        return out

    # ---------------------------------------------------------------------------- findings
    def finding(self, group: str, kind: str, primitive: str, message: str, t: float | None = None, *,
                joints: JointPositions | None = None, target: Pose | None = None) -> None:
        """A problem met by ``group`` in the call it is running now (at ``t``, default: now), the robot's joints then."""
        operation, function = self.locate(group) or ("?", "?")
        self.add(group, operation, function, kind, primitive, message, t, joints=joints, target=target)

    def add(self, group: str, operation: str, function: str, kind: str, primitive: str, message: str, t: float | None = None, *,
            joints: JointPositions | None = None, bodies: tuple[FoundBody, ...] = (), target: Pose | None = None) -> None:
        """A problem of call (``operation``, ``group``); the same kind again there only counts (the first one's instant kept)."""
        key = (operation, group, kind)
        if key in self._findings:
            self._counts[key] += 1
            return
        call = self._calls.get((operation, group))
        file = call.file if call is not None and call.file else str(self.app.path)
        line, col = (call.line, call.col) if call is not None and call.line else self._lines.get(operation, (0, 0))
        when = self.timing.elapsed() if t is None else t
        self._findings[key] = Finding(kind, group, operation, function, primitive, message, file, line, col, when, origin=self._origins.get(operation, ""),
                                      joints=joints, bodies=bodies, target=target)
        self._counts[key] = 1

    def findings(self) -> tuple[Finding, ...]:
        """Every finding, in the order found, with how often it came up in its call."""
        self._settle()
        return tuple(replace(finding, count=self._counts[key]) for key, finding in self._findings.items())

    # ---------------------------------------------------------------------------- timeline
    def span(self, group: str, groups: tuple[str, ...], primitive: str, start: float, end: float, finding: str | None = None) -> Span:
        """A primitive of ``group`` (holding ``groups``) that ran from ``start`` to ``end`` (time base's raw times)."""
        operation, function = self.locate(group) or ("?", "?")
        begin, finish = self.timing.place(groups, start, end)
        span = Span(group, groups, operation, function, primitive, begin, finish, finding)
        self.spans.append(span)
        return span
