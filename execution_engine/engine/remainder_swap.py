"""Editing a paused run: the operations not yet started are swapped for an edited application's, only if it passes.

A paused run (an operator's pause, a step done, a safety stop) has a frontier: the operations before
it have run or are running and stay as they are; those from it on have not started and may change.
An edit is the whole application again, as the builder or a file has it; the engine takes it only
when

* the run is paused, in lock-step (``sync="operation"``: one frontier for every group);
* the robot, its groups, the cell and the sync mode are the run's (a paused run cannot change cells);
* every operation before the frontier is the run's, compared in their canonical form
  (:func:`operation_form`: id, name, iteration, conditions, each group's function and params --
  not the line it is written on, which an edit above it moves);
* the check the wiring passes in (``RemainderCheck``: the dry run of the new remainder from where
  the robot is now, with the flags set and the frames vision located so far) finds nothing.

Then, and only then, the run's application becomes the new one, between two operations of the
engine's loop (which reads its operations afresh, :meth:`Remainder.operations`); the swap is an
engine event (``swap``: both applications' digests and where it happened) that the trace, the
recording and the checkpoint keep, and a line of the run report.  Anything refused changes nothing:
the run stays paused with the remainder it had.  The dry run lives in the wiring (cell_runner);
the engine only calls it, as the studio's Start does.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Awaitable, Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from core_functions.geometry import Pose
from execution_engine.app_model.diagnostics import Diagnostic
from execution_engine.app_model.model import Application, Operation
from execution_engine.engine.flags import FlagBoard
from execution_engine.engine.report import RunReport
from execution_engine.engine.zones import ZoneBoard
from node_transport.clock import Clock
from node_transport.wire import EngineEvent


@dataclass(frozen=True)
class PresentState:
    """Where a paused run stands: what the check of a new remainder starts from (besides the joints, which
    the wiring measures itself, from the robot)."""

    frontier: int  # the first operation (index) not started: the remainder starts there
    located: Mapping[str, Pose] = field(default_factory=dict)  # frames vision located so far, world poses
    flags: tuple[str, ...] = ()  # flags set so far
    outcomes: Mapping[str, str] = field(default_factory=dict)  # "operation/group" -> the outcome a tested function ended with


#: The wiring's check of a new application's remainder from the present state: its findings (none: it passes).
RemainderCheck = Callable[[Application, PresentState], Awaitable[Sequence[Diagnostic]]]


@dataclass(frozen=True)
class Swap:
    """One swap: where, and the digests of the application before and after (:func:`application_digest`)."""

    t: float
    frontier: int  # the first operation (index) of the new remainder
    operation: str | None  # the last operation started before the pause (None: none yet)
    old_digest: str
    new_digest: str
    file: str  # where the new application came from (the builder's path, a file)
    source: str  # who edited: studio, a terminal console

    def line(self) -> str:
        """The run report's line."""
        after = f"after operation {self.operation}" if self.operation else "before the first operation"
        return (f"edited while paused at {self.t:.2f} s by {self.source} ({after}): operations from {self.frontier + 1} on swapped "
                f"for {self.file}'s; application {self.old_digest[:12]} -> {self.new_digest[:12]}")


@dataclass(frozen=True)
class SwapAnswer:
    """What the editor is told: taken or not, one line why, and the findings placed at their lines."""

    ok: bool
    message: str
    findings: tuple[Diagnostic, ...] = ()
    swap: Swap | None = None


def operation_form(operation: Operation) -> list[Any]:
    """An operation as the run knows it, without where it is written: equal forms run the same."""
    calls = [[g, c.function, list(c.params), c.implicit] for g, c in sorted(operation.calls.items())]
    when = [[c.operation, c.group, c.outcome, c.holds] for c in operation.when]
    return [operation.id, operation.name, operation.origin, when, calls]


def operation_digest(operation: Operation) -> str:
    return _sha(operation_form(operation))


def application_digest(app: Application) -> str:
    """The hex SHA-256 of what an application runs: robot, groups, cell, mode, error policy and every operation's form."""
    cell = [app.cell.name, str(app.cell.path or "")] if app.cell is not None else None
    policy = {k: v for k, v in asdict(app.error_policy).items()}
    return _sha([app.name, app.robot.name, list(app.robot.group_names), cell, app.sync, policy, [operation_form(op) for op in app.operations]])


def _sha(form: Any) -> str:
    return hashlib.sha256(json.dumps(form, separators=(",", ":"), ensure_ascii=True, default=str).encode()).hexdigest()


def encode_answer(swap: Swap) -> str:
    """The swap event's ``answer`` on the wire (EngineEvent has no fields of its own for it): ``OLD NEW FRONTIER``."""
    return f"{swap.old_digest} {swap.new_digest} {swap.frontier}"


def decode_answer(answer: str | None) -> tuple[str, str, int] | None:
    """``(old digest, new digest, frontier)`` of a swap event's ``answer``; None when it is not one."""
    parts = (answer or "").split()
    if len(parts) != 3 or not parts[2].isdigit():
        return None
    return parts[0], parts[1], int(parts[2])


class ExecutionEngine(Protocol):
    """What the swap reads and changes of the engine (:class:`~execution_engine.engine.engine.ExecutionEngine`)."""

    app: Application | None
    state: str
    report: RunReport | None
    tested: frozenset[tuple[str, str]]
    clock: Clock
    flags: FlagBoard
    zones: ZoneBoard
    remainder: Remainder


class Remainder:
    """The run's frontier and its swaps; the engine's loop takes its operations from here."""

    def __init__(self, publish: Callable[[EngineEvent], None], located: Callable[[], dict[str, Pose]]) -> None:
        self.publish = publish  # the engine's events
        self.located = located  # the frames vision located in this run so far
        self.frontier = 0
        self.started: str | None = None  # the last operation started
        self.swaps: list[Swap] = []
        #: Called with the new application and its swap once it is in (a checkpoint writer re-indexes by it).
        self.hooks: list[Callable[[Application, Swap], None]] = []
        self._seen = 0  # swaps when the loop took its latest operation

    def operations(self, engine: ExecutionEngine, locked: int = 0) -> Iterator[tuple[int, Operation]]:
        """(index, operation) of the run's application, read afresh at each step (a swap changes what follows);
        ``locked``: operations before it are not to change (a resumed run's first one ran in part)."""
        self.frontier, self.started, self.swaps, self._seen = 0, None, [], 0
        index = 0
        while engine.app is not None and index < len(engine.app.operations):
            self.frontier = max(index, locked)
            self._seen = len(self.swaps)
            yield index, engine.app.operations[index]
            index += 1

    def take(self, engine: ExecutionEngine, index: int, operation: Operation) -> Operation:
        """The operation at ``index`` as it is about to run: the edited one if a swap replaced it while the run was
        paused before it; from now on it is running and no edit may change it."""
        assert engine.app is not None
        if len(self.swaps) > self._seen and index >= self.swaps[-1].frontier:
            operation = engine.app.operations[index]
        self.frontier, self.started = index + 1, operation.id
        return operation


def present_state(engine: ExecutionEngine) -> PresentState:
    """The state a new remainder is checked from."""
    remainder = engine.remainder
    outcomes = dict(engine.report.outcomes) if engine.report is not None else {}
    return PresentState(remainder.frontier, dict(remainder.located()), engine.flags.names_set(), outcomes)


def refusal(engine: ExecutionEngine, new: Application) -> str | None:
    """Why ``new`` cannot replace the run's remainder, before any check; None when it may be checked."""
    old, frontier = engine.app, engine.remainder.frontier
    if old is None or engine.state != "paused":
        return f"edit: the run is not paused ({engine.state}); pause it first"
    if old.sync == "flags":
        return ('edit: a run with sync="flags" has no single point all groups stopped at (each group goes its own order): '
                "stop it and start the edited application")
    for what, then, now in (("robot", old.robot.name, new.robot.name), ("groups", ", ".join(old.robot.group_names), ", ".join(new.robot.group_names)),
                            ("sync", old.sync, new.sync)):
        if then != now:
            return (f"edit: the edited application changes the {what} ({then} -> {now}); a paused run keeps its robot, groups, "
                    "cell and sync mode: stop it and start the edited application")
    if (old.cell is None) != (new.cell is None) or (old.cell is not None and new.cell is not None and old.cell != new.cell):
        name = lambda app: app.cell.name if app.cell is not None else "(none)"  # noqa: E731
        return (f"edit: the edited application changes the cell ({name(old)} -> {name(new)}, or its frames); a paused run keeps its robot, "
                "groups, cell and sync mode: stop it and start the edited application")
    running = engine.report is not None and engine.report.operations_done < frontier  # paused inside it, not after it
    for index in range(frontier):
        if index >= len(new.operations) or operation_form(new.operations[index]) != operation_form(old.operations[index]):
            state = "is running" if running and index == frontier - 1 else "has already run"
            return f"edit: operation {index + 1} {old.operations[index].id!r} {state}; only operations from {frontier + 1} on may change"
    if [operation_form(op) for op in new.operations[frontier:]] == [operation_form(op) for op in old.operations[frontier:]]:
        return f"edit: nothing to change: the operations from {frontier + 1} on are the run's"
    return None


async def swap_remainder(engine: ExecutionEngine, new: Application, check: RemainderCheck, file: str, source: str) -> SwapAnswer:
    """Check ``new`` against the paused run and its present state; swap its remainder in only if it all passes."""
    why = refusal(engine, new)
    if why is not None:
        return SwapAnswer(False, why)
    old, frontier, swaps = engine.app, engine.remainder.frontier, len(engine.remainder.swaps)
    assert old is not None
    state = present_state(engine)
    findings = tuple(await check(new, state))
    if findings:
        return SwapAnswer(False, f"edit: not swapped: {len(findings)} problem(s) found by the dry run of operations {frontier + 1}.. "
                                 "from where the robot is; the run stays paused with its own", findings)
    if engine.state != "paused" or engine.app is not old or engine.remainder.frontier != frontier or len(engine.remainder.swaps) != swaps:
        return SwapAnswer(False, f"edit: not swapped: the run moved on while the edit was checked (it is {engine.state}); pause it and apply again")
    swap = Swap(engine.clock.now(), frontier, engine.remainder.started, application_digest(old), application_digest(new), file, source)
    engine.app, engine.tested = new, new.tested()
    if engine.report is not None:
        engine.report.operations_total = len(new.operations)
        engine.report.edits.append(swap.line())
    engine.zones.swap(new)
    engine.remainder.swaps.append(swap)
    for hook in engine.remainder.hooks:
        hook(new, swap)
    message = swap.line()
    engine.remainder.publish(EngineEvent("swap", swap.t, engine.state, swap.operation, message=message, command=file, source=source,
                                         accepted=True, answer=encode_answer(swap)))
    return SwapAnswer(True, f"edit: swapped: operations from {frontier + 1} on are {file}'s ({len(new.operations) - frontier} to run); "
                            "resume to continue", swap=swap)
