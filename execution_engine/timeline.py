"""The run's timeline (the paper's Fig. 12): one lane per robot group, what each did and when.

A model only -- no drawing: the report renders it with matplotlib (:mod:`cell_runner.run_report`)
and the operator station draws it live in the browser, so both show the same thing from the same
events.  It is built from trace records (the dicts of :mod:`execution_engine.observers`, as a
JSON-lines trace holds them and as :mod:`execution_engine.recorder.reading` rebuilds them from a
recording), one at a time (:meth:`TimelineBuilder.add`), so a live view feeds it as events
arrive and asks for a :meth:`TimelineBuilder.snapshot` whenever it redraws.

Per lane: a bar per function (operation, function, start, end, outcome, the state it was in
longest -- its colour), the primitives inside it (each with the working state that ran it), and
the idle gaps between functions, the flag and zone waits among them named after what they waited
for and who they waited on (the group that set the flag, the group that held the zone).  Across
lanes: the operation boundaries (first start to last end of the operation's functions), errors,
retries (a function sent again in the same operation) and operator actions.  A bar still open has
``t_end`` None: it ran up to ``now``.  Given the dry run's plan (:func:`planned_functions`), each
bar carries its function's planned duration and :func:`plan_deltas` compares them; the critical
path is :mod:`execution_engine.timeline_path`'s.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

#: Colours of the states a bar can show (fill colours; the report and the station use the same).
STATE_COLOURS: dict[str, str] = {
    "Motion": "#4e79a7",
    "FullBodyMotion": "#2f4b7c",
    "RecordTrajectory": "#76b7b2",
    "TrajectoryExecution": "#59a14f",
    "EndEffector": "#f28e2b",
    "Vision": "#b07aa1",
    "MasterSlave": "#9c755f",
    "Pause": "#bab0ac",
    "Stop": "#e15759",
    "ErrorHandling": "#e15759",
    "Ready": "#d9d9d9",
}
#: Edge colours of a function bar by outcome (None: still running).
OUTCOME_COLOURS: dict[str | None, str] = {
    "succeeded": "#2ca02c", "aborted": "#d62728", "preempted": "#ff7f0e", None: "#1f77b4",
}


@dataclass
class PrimitiveBar:
    name: str
    index: int
    state: str  # the working state that ran it (Motion, Vision, ...)
    t_start: float
    t_end: float | None = None
    outcome: str | None = None  # done / error / ... as the machine reported it
    result: Mapping[str, Any] | None = None  # what the robot reported (a vision pose, joints)

    @property
    def colour(self) -> str:
        return STATE_COLOURS.get(self.state, "#888888")


@dataclass
class FunctionBar:
    group: str
    operation: str
    function: str
    t_start: float
    t_end: float | None = None
    outcome: str | None = None  # succeeded / aborted / preempted; None while running
    attempt: int = 1  # 2 and more: a retry of the same function in the same operation
    error: str | None = None
    primitives: list[PrimitiveBar] = field(default_factory=list)
    id: str = ""  # "group:n", the n-th bar of its lane from 0: the same in every snapshot of the run
    planned: float | None = None  # the dry run's seconds for this function (group, operation); None: not planned

    def end(self, now: float) -> float:
        return self.t_end if self.t_end is not None else now

    @property
    def state(self) -> str:
        """The state the function spent most of its time in (its colour)."""
        spent: dict[str, float] = {}
        for p in self.primitives:
            spent[p.state] = spent.get(p.state, 0.0) + ((p.t_end if p.t_end is not None else p.t_start) - p.t_start)
        if self.outcome in ("aborted", "preempted"):
            return "ErrorHandling"
        return max(spent, key=lambda s: spent[s]) if spent else "Ready"

    @property
    def colour(self) -> str:
        return STATE_COLOURS.get(self.state, "#888888")

    @property
    def edge(self) -> str:
        return OUTCOME_COLOURS.get(self.outcome, "#1f77b4")


@dataclass(frozen=True)
class IdleGap:
    group: str
    t_start: float
    t_end: float
    waiting: str | None = None  # "flag X" / "zone Z": the group waited for it here (sync="flags"); None: just idle
    by: str | None = None  # the group that set the flag / held the zone (None: not known yet, or nobody)
    outcome: str | None = None  # how the wait ended: passed / timeout / stopped; None while it lasts
    released: float | None = None  # when ``by`` set the flag / left the zone (the wait ends a moment later)

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start

    @property
    def label(self) -> str:
        """What the operator reads on the wait: "waiting for flag part_ready set by right_arm"."""
        if not self.waiting:
            return "idle"
        kind = self.waiting.split(" ", 1)[0]
        if self.outcome in ("timeout", "stopped"):
            return f"waiting for {self.waiting} ({'timed out' if self.outcome == 'timeout' else 'stopped'})"
        if self.by is None:
            return f"waiting for {self.waiting} ({'not set yet' if kind == 'flag' else 'its turn'})"
        return f"waiting for {self.waiting} {'set by' if kind == 'flag' else 'held by'} {self.by}"


@dataclass
class Lane:
    group: str
    bars: list[FunctionBar] = field(default_factory=list)
    idle: list[IdleGap] = field(default_factory=list)
    busy: float = 0.0  # seconds inside functions
    waits: list[list[Any]] = field(default_factory=list)  # [what, t_start, t_end or None, by, outcome, released]: flag and zone waits


@dataclass
class OperationSpan:
    id: str
    t_start: float
    t_end: float | None = None
    iteration: str = ""  # the loop iteration or call the operation was made for (the trace's ``iteration``)


@dataclass(frozen=True)
class Mark:
    """A point in time worth a marker: an error, an operator action, an engine state change."""

    t: float
    kind: str  # error / operator / engine_state / flag / outcome (a tested function's) / branch (an operation left out) / breakpoint
    group: str
    text: str


@dataclass
class Timeline:
    lanes: dict[str, Lane]
    operations: list[OperationSpan]
    marks: list[Mark]
    t_start: float
    t_end: float
    retries: int = 0

    def idle_total(self, group: str) -> float:
        return sum(g.duration for g in self.lanes[group].idle)


class TimelineBuilder:
    """Folds trace records into a timeline, one record at a time (records of any group, in order)."""

    def __init__(self, groups: Iterable[str] = (), planned: Mapping[tuple[str, str], float] | None = None) -> None:
        self._lanes: dict[str, Lane] = {g: Lane(g) for g in groups}
        self.planned = dict(planned or {})  # (group, operation) -> the dry run's seconds (:func:`planned_functions`)
        self._setters: dict[str, tuple[str, float]] = {}  # flag -> the group that set it, when
        self._holders: dict[str, str] = {}  # zone -> the group inside it now
        self._leavers: dict[str, tuple[str, float]] = {}  # zone -> the group that left it last, when
        self._open: dict[str, FunctionBar] = {}
        self._operations: dict[str, OperationSpan] = {}
        self._attempts: dict[tuple[str, str], int] = {}
        self.marks: list[Mark] = []
        self.retries = 0
        self.t_first: float | None = None
        self.t_last = 0.0
        self._waiting: dict[tuple[str, str], list[list[Any]]] = {}  # (group, what) -> its waits still open, oldest first

    def add_all(self, records: Iterable[Mapping[str, Any]]) -> TimelineBuilder:
        for record in records:
            self.add(record)
        return self

    def add(self, record: Mapping[str, Any]) -> None:
        if record.get("event") == "plan":  # the plan the run was checked against (run_plan.py): stamped at the check, no event of the run
            return
        t = float(record.get("t", 0.0))
        self.t_first = t if self.t_first is None else min(self.t_first, t)
        self.t_last = max(self.t_last, t)
        event, group = record.get("event"), str(record.get("group", "?"))
        if event == "breakpoint":  # the run paused before an operation: a mark on the held group's lane, or the engine's
            self.marks.append(Mark(t, "breakpoint", group, str(record.get("message") or f"paused before {record.get('operation')}")))
            return
        if group == "engine":
            self._engine(record, t)
            return
        lane = self._lanes.setdefault(group, Lane(group))
        if event == "flag":
            self._flag(lane, record, t)
        elif event == "function_start":
            self._start_function(lane, record, t)
        elif event == "function_end":
            self._end_function(group, record, t)
        elif event == "primitive_start":
            bar = self._open.get(group)
            if bar is not None:
                bar.primitives.append(PrimitiveBar(str(record.get("primitive", "")), _whole(record.get("index")), str(record.get("state", "")), t))
        elif event == "primitive_end":
            bar = self._open.get(group)
            if bar is not None and bar.primitives and bar.primitives[-1].t_end is None:
                primitive = bar.primitives[-1]
                primitive.t_end, primitive.outcome, primitive.result = t, record.get("outcome"), record.get("result")
        elif event == "outcome":  # on the lane of the group whose function an <if> tests
            self.marks.append(Mark(t, "outcome", group, str(record.get("message") or f"{record.get('function')} ended {record.get('outcome')}")))
        elif event == "error":
            text = str(record.get("error", ""))
            self.marks.append(Mark(t, "error", group, text))
            bar = self._open.get(group)
            if bar is None and lane.bars and lane.bars[-1].t_end == t and lane.bars[-1].error is None:
                bar = lane.bars[-1]  # written just after its function's end, at the same instant
            if bar is not None:
                bar.error = text

    def _start_function(self, lane: Lane, record: Mapping[str, Any], t: float) -> None:
        operation, function = str(record.get("operation") or ""), str(record.get("function") or "")
        key = (lane.group, operation)
        attempt = self._attempts.get(key, 0) + 1
        self._attempts[key] = attempt
        if attempt > 1:
            self.retries += 1
        bar = FunctionBar(lane.group, operation, function, t, attempt=attempt, id=f"{lane.group}:{len(lane.bars)}", planned=self.planned.get(key))
        lane.bars.append(bar)
        self._open[lane.group] = bar
        span = self._operations.setdefault(operation, OperationSpan(operation, t, iteration=str(record.get("iteration") or "")))
        span.t_start = min(span.t_start, t)

    def _end_function(self, group: str, record: Mapping[str, Any], t: float) -> None:
        bar = self._open.pop(group, None)
        if bar is None:
            return
        bar.t_end, bar.outcome = t, record.get("outcome")
        if record.get("error") and bar.error is None:
            bar.error = str(record.get("error"))
        for primitive in bar.primitives:  # a stop abandons the primitive in flight
            if primitive.t_end is None:
                primitive.t_end = t
        span = self._operations[bar.operation]
        span.t_end = t if span.t_end is None else max(span.t_end, t)

    def _flag(self, lane: Lane, record: Mapping[str, Any], t: float) -> None:
        """A wait for a flag (or zone) opens at ``waiting`` and closes at passed/timeout/stopped; a set is a mark.
        Who it waited on: the setter of a flag; for a zone, who was inside when the wait began, and the last
        other group to leave it when it ended (the one whose leaving let this group in)."""
        kind, name, state, group = str(record.get("kind", "flag")), str(record.get("flag")), record.get("state"), lane.group
        what = f"{kind} {name}"
        if kind == "zone" and state == "passed":
            self._holders[name] = group
            for other in self._lanes:  # who waits for the zone now waits on the group inside it
                for wait in self._waiting.get((other, what), []) if other != group else []:
                    wait[3] = wait[3] or group
        elif kind == "zone" and state == "left":
            if self._holders.get(name) == group:
                del self._holders[name]
            self._leavers[name] = (group, t)
            return
        if state == "waiting":
            holder = self._holders.get(name) if kind == "zone" else None
            wait: list[Any] = [what, t, None, holder if holder != group else None, None, None]
            lane.waits.append(wait)
            self._waiting.setdefault((group, what), []).append(wait)
        elif state == "set":
            self._setters[name] = (group, t)
            self.marks.append(Mark(t, "flag", group, str(record.get("message") or f"set {what}")))
        else:
            still = self._waiting.get((group, what))
            if still:  # the latest wait for it closes (one lookup: a file of many waits costs no more than their number)
                wait = still.pop()
                wait[2], wait[4] = t, str(state)
                by = self._setters.get(name) if kind == "flag" else self._leavers.get(name)
                if by is not None and by[0] != group and by[1] >= wait[1]:  # set or left while it waited
                    wait[3], wait[5] = by

    def _engine(self, record: Mapping[str, Any], t: float) -> None:
        event = record.get("event")
        if event == "operator":
            answer = "accepted" if record.get("accepted") else "refused"
            self.marks.append(Mark(t, "operator", "engine", f"{record.get('command')} from {record.get('source')}: {answer}"))
        elif event == "error":
            self.marks.append(Mark(t, "error", "engine", str(record.get("error", ""))))
        elif event == "branch":
            self.marks.append(Mark(t, "branch", "engine", str(record.get("message") or f"{record.get('operation')} left out")))
        elif event == "engine_state":
            self.marks.append(Mark(t, "engine_state", "engine", f"{record.get('from')} -> {record.get('to')}"))

    def snapshot(self, now: float | None = None) -> Timeline:
        """The timeline up to ``now`` (default: the latest record); open bars end at ``now``."""
        t_start = self.t_first if self.t_first is not None else 0.0
        t_end = max(self.t_last, now if now is not None else self.t_last)
        lanes = {}
        for group, lane in self._lanes.items():
            copy = Lane(group, list(lane.bars))
            cursor = t_start
            for bar in copy.bars:
                if bar.t_start > cursor:
                    copy.idle.append(IdleGap(group, cursor, bar.t_start))
                copy.busy += bar.end(t_end) - bar.t_start
                cursor = max(cursor, bar.end(t_end))
            if t_end > cursor:
                copy.idle.append(IdleGap(group, cursor, t_end))
            copy.waits = [list(w) for w in lane.waits]
            waits = _disjoint(copy.waits, t_end)
            inside = _within_functions(group, copy.bars, waits, t_end)  # a zone wait holds a function before its motion
            copy.busy -= sum(g.duration for g in inside)
            copy.idle = sorted(_split(copy.idle, waits) + inside, key=lambda g: g.t_start)
            lanes[group] = copy
        operations = sorted(self._operations.values(), key=lambda s: s.t_start)
        return Timeline(lanes, operations, list(self.marks), t_start, t_end, self.retries)


#: A wait as the sweeps below take it: what, start, end, by, outcome, released.
Wait = tuple[str, float, float, "str | None", "str | None", "float | None"]


def _disjoint(waits: list[list[Any]], now: float) -> list[Wait]:
    """The waits as (what, start, end, by, outcome, released) in time order, none overlapping the one before (a group
    waits for one thing at a time; a file that says otherwise is clipped), so the sweeps below stay linear."""
    out: list[Wait] = []
    cursor = -math.inf
    for what, start, end, by, outcome, released in sorted(waits, key=lambda w: w[1]):
        a, b = max(start, cursor), now if end is None else end
        if b > a:
            out.append((what, a, b, by, outcome, released))
            cursor = b
    return out


def _within_functions(group: str, bars: list[FunctionBar], waits: list[Wait], now: float) -> list[IdleGap]:
    """The parts of waits that fall inside a function (a zone: its motion waits, the function has
    started): idle time named after the wait, not busy time.  One sweep over both, in time order."""
    spans: list[tuple[float, float]] = []
    for bar in sorted(bars, key=lambda b: b.t_start):
        start = max(bar.t_start, spans[-1][1]) if spans else bar.t_start
        if bar.end(now) > start:
            spans.append((start, bar.end(now)))
    pieces, first = [], 0
    for what, start, stop, by, outcome, released in waits:
        while first < len(spans) and spans[first][1] <= start:
            first += 1
        index = first
        while index < len(spans) and spans[index][0] < stop:
            a, b = max(start, spans[index][0]), min(stop, spans[index][1])
            if b > a:
                pieces.append(IdleGap(group, a, b, what, by, outcome, released))
            index += 1
    return pieces


def _split(gaps: list[IdleGap], waits: list[Wait]) -> list[IdleGap]:
    """Idle gaps (in time order) cut where the group waited for a flag or zone: each wait's share named,
    the rest plain idle.  One sweep over both."""
    pieces, first = [], 0
    for gap in gaps:
        cursor = gap.t_start
        while first < len(waits) and waits[first][2] <= gap.t_start:
            first += 1
        index = first
        while index < len(waits) and waits[index][1] < gap.t_end:
            what, start, end, by, outcome, released = waits[index]
            a, b = max(cursor, start), min(gap.t_end, end)
            if b > a:
                if a > cursor:
                    pieces.append(IdleGap(gap.group, cursor, a))
                pieces.append(IdleGap(gap.group, a, b, what, by, outcome, released))
                cursor = b
            index += 1
        if gap.t_end > cursor:
            pieces.append(IdleGap(gap.group, cursor, gap.t_end))
    return pieces


def _whole(value: object) -> int:
    """A primitive's index as the record gives it; 0 when it gives none (or nonsense)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return 0
    return int(value)


def build_timeline(records: Iterable[Mapping[str, Any]], groups: Iterable[str] = (), planned: Mapping[tuple[str, str], float] | None = None) -> Timeline:
    """The whole timeline of a finished (or cut) record."""
    return TimelineBuilder(groups, planned).add_all(records).snapshot()


class PlannedSpan(Protocol):
    """A span of the dry run's timeline (cell_runner.dry_run.report.Span): a primitive of a function."""

    group: str
    operation: str
    function: str
    start: float
    end: float


def planned_functions(spans: Iterable[PlannedSpan]) -> dict[tuple[str, str], float]:
    """Each function's planned seconds from the dry run's primitives: (group, operation) -> from its first
    primitive's start to its last one's end (a function the dry run saw no primitive of is not planned)."""
    reach: dict[tuple[str, str], tuple[float, float]] = {}
    for span in spans:
        key = (span.group, span.operation)
        start, end = reach.get(key, (span.start, span.end))
        reach[key] = (min(start, span.start), max(end, span.end))
    return {key: end - start for key, (start, end) in reach.items()}


@dataclass(frozen=True)
class PlanDelta:
    """A function planned against what it took: from its first attempt's start to its last one's end."""

    group: str
    operation: str
    function: str
    planned: float
    actual: float
    attempts: int
    done: bool  # False: still running (or cut): ``actual`` is up to the snapshot's end

    @property
    def delta(self) -> float:
        """Seconds more than planned (negative: faster)."""
        return self.actual - self.planned


def plan_deltas(timeline: Timeline) -> list[PlanDelta]:
    """Every planned function of the timeline against its actual time, per lane in time order."""
    out: list[PlanDelta] = []
    for group, lane in timeline.lanes.items():
        calls: dict[str, list[FunctionBar]] = {}
        for bar in lane.bars:
            calls.setdefault(bar.operation, []).append(bar)
        for operation, bars in calls.items():
            planned = bars[0].planned
            if planned is None:
                continue
            last = bars[-1]
            out.append(PlanDelta(group, operation, last.function, planned, last.end(timeline.t_end) - bars[0].t_start, len(bars), last.t_end is not None))
    return out
