"""The dry run's plan a run was checked against, kept with the run's record so that a replay shows it.

Live, the station draws each function's planned seconds against its actual ones and compares the cycle time
with the prediction; a replay could not, since neither a trace nor a recording held the plan.  Now the start
check (``cell_runner/dry_run/start.py``, every path that checks a run: ``run``, the studio, ``launch``)
publishes the plan it proved on the latched topic :data:`PLAN_TOPIC` as a
``dual_arm_executive_interfaces/msg/RunPlan``: the recorder records it as any topic (its schema is the
``.msg``'s, so Foxglove and ``ros2 bag`` decode it), and the trace writer turns it into ``plan`` records
(:func:`plan_records`).  A run with ``--no-check`` publishes none: it has no plan.

A trace line is bounded (``trace_report.MAX_LINE``), so a long application's plan is written in parts of at
most :data:`PART_ITEMS` entries (``part`` k of ``parts``).  Whoever reads a record back -- a trace or a
recording from another computer -- reads it through :class:`PlanReader`: every field checked (finite
seconds within a run's times, names that are text, no operation twice, parts that belong together), and a
plan that fails any check is ignored with one line saying why, never half taken.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from core_functions.printable import printable
from execution_engine.record_limits import TIME_BOUND
from execution_engine.timeline import PlannedSpan, planned_functions
from node_transport import mirrors
from node_transport.clock import Clock
from node_transport.msgs import Header
from node_transport.port import Node, Publisher
from node_transport.qos import LATCHED
from node_transport.typed import PACKAGE, RunPlanMsg, stamp_of

PlannedFunctionMsg = mirrors.mirror(f"{PACKAGE}/msg/PlannedFunction")
PLAN_TOPIC = "execution_engine/plan"
PLAN_EVENT = "plan"
#: What the plan was proved from: the simulator's start (fresh or kept verdict), or the robot's measured joints.
BASES = ("start", "measured")
#: Entries (operations plus functions) per trace record: a part stays far below a trace line's megabyte.
PART_ITEMS = 4000
#: Operations (and functions) a plan may hold: the record limits' scale, far above any application.
MAX_ITEMS = 1_000_000
MAX_NAME = 1000  # characters of an operation id or a group name


class PlanError(ValueError):
    """A plan record or message that cannot be taken: the one line says which field and why."""


@dataclass(frozen=True)
class RunPlan:
    """The plan: the predicted cycle time, each operation's and each function's planned seconds."""

    cycle_time: float
    basis: str
    operations: tuple[tuple[str, float], ...]  # (operation id, seconds from its start to the next one's), in order
    functions: tuple[tuple[str, str, float], ...]  # (group, operation id, seconds)
    app: str = ""

    @property
    def durations(self) -> list[float]:
        """Planned seconds per operation, in order (the ETA's and the run summary's plan)."""
        return [seconds for _, seconds in self.operations]

    def functions_json(self) -> list[dict[str, Any]]:
        """The planned functions as the station's feed keeps them (the timeline's planned bars)."""
        return [{"group": g, "operation": o, "planned": s} for g, o, s in self.functions]


class DryRunVerdict(Protocol):
    """What a plan is made of (cell_runner.dry_run.report.DryRunReport)."""

    @property
    def timeline(self) -> Sequence[PlannedSpan]: ...

    @property
    def cycle_time(self) -> float: ...


def operation_durations(spans: Iterable[PlannedSpan], cycle_time: float, operation_ids: Sequence[str]) -> list[float]:
    """Each operation's planned duration from a dry run's timeline: from its first span's start to the next
    operation's (the last one's to the predicted cycle time), so the waits between operations count too.
    The plan's clock never goes back: with sync="flags" a group runs ahead into an operation listed after one
    still going, so each operation starts at the latest start so far (the first at 0) -- the durations add up
    to the predicted cycle time, as the ETA (operator_station/eta.py) and the run summary take them."""
    starts: dict[str, float] = {}
    for span in spans:
        starts[span.operation] = min(starts.get(span.operation, math.inf), span.start)
    position, at = 0.0, []
    for op in operation_ids:  # an operation the dry run never reached takes no time
        position = max(position, starts.get(op, position))
        at.append(position)
    ends = [*at[1:], max(float(cycle_time), at[-1] if at else 0.0)]
    return [end - start for start, end in zip(at, ends)]


def plan_of(report: DryRunVerdict, operation_ids: Sequence[str], basis: str = "start", app: str = "") -> RunPlan:
    """The plan of a passed dry run of the operations ``operation_ids`` (the application's, expanded)."""
    durations = operation_durations(report.timeline, report.cycle_time, operation_ids)
    functions = tuple((g, o, s) for (g, o), s in planned_functions(report.timeline).items())
    return RunPlan(float(report.cycle_time), basis, tuple(zip(operation_ids, durations)), functions, app)


# --------------------------------------------------------------------------------------- the topic
class PlanPublisher:
    """The latched plan topic of one node: the run's plan, published once its start is checked."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._publisher: Publisher[Any] | None = None

    def publish(self, plan: RunPlan) -> None:
        if self._publisher is None:
            self._publisher = self.node.create_publisher(RunPlanMsg, PLAN_TOPIC, LATCHED)
        self._publisher.publish(plan_msg(plan, self.node.clock, self.node.clock.now()))


def plan_msg(plan: RunPlan, clock: Clock, t: float) -> Any:
    """The ``RunPlan`` message of ``plan``, stamped at run time ``t``."""
    return RunPlanMsg(
        header=Header(stamp=stamp_of(clock, t)), app=plan.app, basis=plan.basis, cycle_time=float(plan.cycle_time),
        operations=tuple(o for o, _ in plan.operations), operation_seconds=tuple(float(s) for _, s in plan.operations),
        functions=tuple(PlannedFunctionMsg(group=g, operation=o, seconds=float(s)) for g, o, s in plan.functions),
    )


def plan_from_fields(msg: Any) -> RunPlan:
    """The plan of a received or recorded ``RunPlan`` (any object with its fields); PlanError naming the field."""
    operations = _sequence(getattr(msg, "operations", None), "operations")
    seconds = _sequence(getattr(msg, "operation_seconds", None), "operation_seconds")
    if len(seconds) != len(operations):
        raise PlanError(f"operation_seconds: {len(seconds)} values for {len(operations)} operations")
    functions = _sequence(getattr(msg, "functions", None), "functions")
    return _checked(
        getattr(msg, "cycle_time", None), getattr(msg, "basis", None), getattr(msg, "app", ""),
        [(o, s) for o, s in zip(operations, seconds)],
        [(getattr(f, "group", None), getattr(f, "operation", None), getattr(f, "seconds", None)) for f in functions],
    )


# ------------------------------------------------------------------------------------- the trace
def plan_records(plan: RunPlan, t: float, part_items: int = PART_ITEMS) -> list[dict[str, Any]]:
    """The trace's ``plan`` records of ``plan`` at run time ``t``: one, or parts of at most ``part_items`` entries."""
    entries: list[tuple[str, Any]] = [("operations", [o, round(s, 6)]) for o, s in plan.operations]
    entries += [("functions", [g, o, round(s, 6)]) for g, o, s in plan.functions]
    chunks = [entries[i:i + part_items] for i in range(0, len(entries), part_items)] or [[]]
    records = []
    for k, chunk in enumerate(chunks, 1):
        record: dict[str, Any] = {"t": round(t, 6), "event": PLAN_EVENT, "group": "engine", "operation": None, "part": k, "parts": len(chunks),
                                  "app": plan.app, "basis": plan.basis, "cycle_time": round(plan.cycle_time, 6), "operations": [], "functions": []}
        for key, value in chunk:
            record[key].append(value)
        records.append(record)
    return records


def damaged_record(t: float, reason: str) -> dict[str, Any]:
    """What a recording's plan message that cannot be taken becomes: a ``plan`` record saying so."""
    return {"t": t, "event": PLAN_EVENT, "group": "engine", "operation": None, "damaged": reason}


@dataclass
class PlanReader:
    """The plan of a run's records, part by part; :meth:`take` tells plan records from the others."""

    where: str = "the record"
    plan: RunPlan | None = None
    notes: list[str] = field(default_factory=list)
    _parts: list[Mapping[str, Any]] = field(default_factory=list)

    def take(self, record: Mapping[str, Any]) -> bool:
        """Whether ``record`` is one of the plan's (then it is read, not shown as a record of the run)."""
        if record.get("event") != PLAN_EVENT:
            return False
        try:
            self._take(record)
        except PlanError as error:
            self._parts = []
            self.notes.append(f"{self.where}: its plan record at {_at(record)} cannot be taken ({printable(str(error))}): no planned bars from it")
        return True

    def _take(self, record: Mapping[str, Any]) -> None:
        if "damaged" in record:
            raise PlanError(str(record["damaged"])[:300])
        part, parts = _count(record.get("part"), "part"), _count(record.get("parts"), "parts")
        if not 1 <= part <= parts:
            raise PlanError(f"part {part} of {parts}")
        if part == 1:
            self._parts = []
        elif len(self._parts) != part - 1 or self._parts[0].get("parts") != parts:
            raise PlanError(f"part {part} of {parts} without the parts before it")
        self._parts.append(record)
        if part < parts:
            return
        first = self._parts[0]
        for other in self._parts[1:]:
            if any(other.get(k) != first.get(k) for k in ("app", "basis", "cycle_time")):
                raise PlanError("parts of different plans")
        operations = [item for p in self._parts for item in _sequence(p.get("operations"), "operations")]
        functions = [item for p in self._parts for item in _sequence(p.get("functions"), "functions")]
        self._parts = []
        self.plan = _checked(first.get("cycle_time"), first.get("basis"), first.get("app", ""),
                             [_pair(item, 2, f"operations[{i}]") for i, item in enumerate(operations)],
                             [_pair(item, 3, f"functions[{i}]") for i, item in enumerate(functions)])

    def finish(self) -> RunPlan | None:
        """The plan read (the last whole one), after the last record; parts left over are said."""
        if self._parts:
            self.notes.append(f"{self.where}: its plan is cut ({len(self._parts)} of {printable(str(self._parts[0].get('parts')))} parts): no planned bars from it")
            self._parts = []
        return self.plan


# ------------------------------------------------------------------------------------- checking
def _checked(cycle_time: Any, basis: Any, app: Any, operations: list[tuple[Any, Any]], functions: list[tuple[Any, Any, Any]]) -> RunPlan:
    if basis not in BASES:
        raise PlanError(f"basis {str(basis)[:40]!r} is neither of {', '.join(BASES)}")
    cycle = _seconds(cycle_time, "cycle_time")
    seen: set[str] = set()
    ops = []
    for i, (name, seconds) in enumerate(operations):
        op = _name(name, f"operations[{i}]")
        if op in seen:
            raise PlanError(f"operations[{i}]: {op[:80]!r} listed twice")
        seen.add(op)
        ops.append((op, _seconds(seconds, f"operation_seconds[{i}]")))
    keys: set[tuple[str, str]] = set()
    funcs = []
    for i, (group, op, seconds) in enumerate(functions):
        key = (_name(group, f"functions[{i}].group"), _name(op, f"functions[{i}].operation"))
        if key in keys:
            raise PlanError(f"functions[{i}]: {key[0][:40]!r} in {key[1][:80]!r} listed twice")
        keys.add(key)
        funcs.append((*key, _seconds(seconds, f"functions[{i}].seconds")))
    return RunPlan(cycle, str(basis), tuple(ops), tuple(funcs), app if isinstance(app, str) else "")


def _seconds(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not 0 <= value <= TIME_BOUND:
        raise PlanError(f"{name}: {printable(str(value)[:40])} is no run time in seconds (0 to {TIME_BOUND:.0f})")
    return float(value)


def _name(value: Any, name: str) -> str:
    if not isinstance(value, str) or not value or len(value) > MAX_NAME:
        raise PlanError(f"{name}: not a name (text of 1 to {MAX_NAME} characters)")
    return value


def _count(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 < value <= MAX_ITEMS:
        raise PlanError(f"{name}: {printable(str(value)[:40])} is not a count")
    return value


def _sequence(value: Any, name: str) -> list[Any]:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (list, tuple)):
        raise PlanError(f"{name}: not a list")
    if len(value) > MAX_ITEMS:
        raise PlanError(f"{name}: {len(value):,} items, over the limit of {MAX_ITEMS:,}")
    return list(value)


def _pair(value: Any, size: int, name: str) -> tuple[Any, ...]:
    if not isinstance(value, list) or len(value) != size:
        raise PlanError(f"{name}: not a list of {size}")
    return tuple(value)


def _at(record: Mapping[str, Any]) -> str:
    t = record.get("t")
    return f"{t:.3f} s" if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t) else "an unknown time"
