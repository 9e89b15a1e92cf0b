"""Editing a paused run: the operations not yet started are swapped for an edited application's, only if it passes.

A paused run (an operator's pause, a step done, a safety stop) has a frontier: the operations before
it have run or are running and stay as they are; those from it on have not started and may change.
An edit is the whole application again, as the builder or a file has it; the engine takes it only
when

* the run is paused: in lock-step (``sync="operation"``) every group at one frontier; with
  ``sync="flags"`` each group where it stands (:mod:`.remainder_groups`), every one of them still --
  held, paused, waiting for a flag or a zone, or through -- and the edit changes nothing any group
  has started, nor gives a group a call behind where it stands;
* the robot, its groups, the cell and the sync mode are the run's (a paused run cannot change cells);
* (lock-step) every operation before the frontier is the run's, compared in their canonical form
  (:func:`operation_form`: id, name, iteration, conditions, each group's function and params --
  not the line it is written on, which an edit above it moves);
* the check the wiring passes in (``RemainderCheck``: the dry run of the new remainder from where
  the robot is now, with the flags set, the zones held and the frames vision located so far; with
  ``sync="flags"`` each group from its own position) finds nothing.

Then, and only then, the run's application becomes the new one, between two operations of the
engine's loop (which reads its operations afresh, :meth:`Remainder.operations`); the swap is an
engine event (``swap``: both applications' digests and where it happened) that the trace, the
recording and the checkpoint keep, and a line of the run report.  Anything refused changes nothing:
the run stays paused with the remainder it had.  The dry run lives in the wiring (cell_runner);
the engine only calls it, as the studio's Start does.
"""
from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from core_functions.geometry import Pose
from execution_engine.app_model.diagnostics import Diagnostic
from execution_engine.app_model.model import Application, Operation
from execution_engine.engine.flags import FlagBoard
from execution_engine.engine.group_link import GroupLink
from execution_engine.engine.remainder_groups import GroupAt, GroupWalk, describe_where, flags_refusal, form_sha, operation_form, still
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
    #: sync="flags": each group's position (none in lock-step, where ``frontier`` is every group's).
    groups: Mapping[str, GroupAt] = field(default_factory=dict)
    #: The zones held now: zone -> (operation, group) of the call inside it.
    zones: Mapping[str, tuple[str, str]] = field(default_factory=dict)


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
    #: sync="flags": where each group stood, in the old application -- (group, "in"/"before"/"finished", index).
    groups: tuple[tuple[str, str, int], ...] = ()

    def where(self) -> str:
        """sync="flags": ``left_arm before operation 5, right_arm in operation 3`` ("" in lock-step)."""
        return ", ".join(f"{g} {kind}" if kind == "finished" else f"{g} {kind} operation {index + 1}" for g, kind, index in self.groups)

    def line(self) -> str:
        """The run report's line."""
        if self.groups:
            return (f"edited while paused at {self.t:.2f} s by {self.source} ({self.where()}): the operations no group had started swapped "
                    f"for {self.file}'s; application {self.old_digest[:12]} -> {self.new_digest[:12]}")
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


def operation_digest(operation: Operation) -> str:
    return _sha(operation_form(operation))


def application_digest(app: Application) -> str:
    """The hex SHA-256 of what an application runs: robot, groups, cell, mode, error policy and every operation's form."""
    cell = [app.cell.name, str(app.cell.path or "")] if app.cell is not None else None
    policy = {k: v for k, v in asdict(app.error_policy).items()}
    return _sha([app.name, app.robot.name, list(app.robot.group_names), cell, app.sync, policy, [operation_form(op) for op in app.operations]])


def _sha(form: Any) -> str:
    return form_sha(form)


def encode_answer(swap: Swap) -> str:
    """The swap event's ``answer`` on the wire (EngineEvent has no fields of its own for it): ``OLD NEW FRONTIER``,
    then with sync="flags" one ``GROUP=KIND:OPERATION`` per group (KIND in/before/finished, OPERATION counted from 1)."""
    return " ".join([swap.old_digest, swap.new_digest, str(swap.frontier), *(f"{g}={kind}:{index + 1}" for g, kind, index in swap.groups)])


def decode_answer(answer: str | None) -> tuple[str, str, int] | None:
    """``(old digest, new digest, frontier)`` of a swap event's ``answer``; None when it is not one."""
    parts = (answer or "").split()
    if len(parts) < 3 or not parts[2].isdigit() or not all(_group_token(p) for p in parts[3:]):
        return None
    return parts[0], parts[1], int(parts[2])


def decode_groups(answer: str | None) -> dict[str, dict[str, Any]]:
    """sync="flags": where each group stood at the swap, from its event's ``answer``: ``{group: {"where": "in", "operation": 4}}``
    (operations counted from 1, in the application before the edit); {} in lock-step or when it is not a swap's."""
    if decode_answer(answer) is None:
        return {}
    out: dict[str, dict[str, Any]] = {}
    for part in (answer or "").split()[3:]:
        group, _, place = part.partition("=")
        kind, _, number = place.partition(":")
        out[group] = {"where": kind, "operation": int(number)}
    return out


def _group_token(part: str) -> bool:
    group, eq, place = part.partition("=")
    kind, colon, number = place.partition(":")
    return bool(group) and bool(eq) and bool(colon) and kind in ("in", "before", "finished") and number.isdigit()


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
    links: dict[str, GroupLink]


class Remainder:
    """The run's frontier and its swaps; the engine's loop takes its operations from here."""

    def __init__(self, publish: Callable[[EngineEvent], None], located: Callable[[], dict[str, Pose]]) -> None:
        self.publish = publish  # the engine's events
        self.located = located  # the frames vision located in this run so far
        self.frontier = 0
        self.started: str | None = None  # the last operation started
        self.swaps: list[Swap] = []
        self.groups = GroupWalk()  # sync="flags": each group's own position (engine/remainder_groups.py)
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
    flags = engine.app is not None and engine.app.sync == "flags"
    frontier = remainder.groups.frontier(engine.app) if flags and engine.app is not None else remainder.frontier
    groups = dict(remainder.groups.at) if flags else {}
    return PresentState(frontier, dict(remainder.located()), engine.flags.names_set(), outcomes, groups, dict(engine.zones.inside))


def refusal(engine: ExecutionEngine, new: Application) -> str | None:
    """Why ``new`` cannot replace the run's remainder, before any check; None when it may be checked."""
    old, frontier = engine.app, engine.remainder.frontier
    if old is None or engine.state != "paused":
        return f"edit: the run is not paused ({engine.state}); pause it first"
    for what, then, now in (("robot", old.robot.name, new.robot.name), ("groups", ", ".join(old.robot.group_names), ", ".join(new.robot.group_names)),
                            ("sync", old.sync, new.sync)):
        if then != now:
            return (f"edit: the edited application changes the {what} ({then} -> {now}); a paused run keeps its robot, groups, "
                    "cell and sync mode: stop it and start the edited application")
    if (old.cell is None) != (new.cell is None) or (old.cell is not None and new.cell is not None and old.cell != new.cell):
        name = lambda app: app.cell.name if app.cell is not None else "(none)"  # noqa: E731
        return (f"edit: the edited application changes the cell ({name(old)} -> {name(new)}, or its frames); a paused run keeps its robot, "
                "groups, cell and sync mode: stop it and start the edited application")
    if old.sync == "flags":
        return moving(engine, old) or flags_refusal(engine.remainder.groups, old, new)
    running = engine.report is not None and engine.report.operations_done < frontier  # paused inside it, not after it
    for index in range(frontier):
        if index >= len(new.operations) or operation_form(new.operations[index]) != operation_form(old.operations[index]):
            state = "is running" if running and index == frontier - 1 else "has already run"
            return f"edit: operation {index + 1} {old.operations[index].id!r} {state}; only operations from {frontier + 1} on may change"
    if [operation_form(op) for op in new.operations[frontier:]] == [operation_form(op) for op in old.operations[frontier:]]:
        return f"edit: nothing to change: the operations from {frontier + 1} on are the run's"
    return None


def moving(engine: ExecutionEngine, app: Application) -> str | None:
    """sync="flags": a group that still moves while the run counts as paused (a breakpoint holds only some groups,
    the others go on until they need them) -- its joints are no start for a check; None when all stand still."""
    walk = engine.remainder.groups
    for group in app.robot.group_names:
        link = engine.links.get(group)
        if group in walk.at and not still(walk, group, link.state if link is not None else None, engine.flags.waiting_for(group)):
            kind, index = walk.where(app, group)
            return (f"edit: {group} is still running ({describe_where(kind, index, app)}): the run holds only some groups; "
                    "pause it (Pause) and apply again")
    return None


def _last_started(engine: ExecutionEngine, app: Application) -> str | None:
    """sync="flags": the latest operation (in application order) some group has started."""
    index = {op.id: i for i, op in enumerate(app.operations)}
    started = [i for at in engine.remainder.groups.at.values() for i in (index.get(o) for o in (*at.done, at.inside)) if i is not None]
    return app.operations[max(started)].id if started else None


async def swap_remainder(engine: ExecutionEngine, new: Application, check: RemainderCheck, file: str, source: str) -> SwapAnswer:
    """Check ``new`` against the paused run and its present state; swap its remainder in only if it all passes."""
    why = refusal(engine, new)
    if why is not None:
        return SwapAnswer(False, why)
    old, frontier, swaps = engine.app, engine.remainder.frontier, len(engine.remainder.swaps)
    assert old is not None
    flags = old.sync == "flags"
    walk = engine.remainder.groups
    positions = walk.snapshot()
    state = present_state(engine)
    what = "the operations no group has started" if flags else f"operations {frontier + 1}.."
    findings = tuple(await check(new, state))
    if findings:
        return SwapAnswer(False, f"edit: not swapped: {len(findings)} problem(s) found by the dry run of {what} "
                                 "from where the robot is; the run stays paused with its own", findings)
    if (engine.state != "paused" or engine.app is not old or engine.remainder.frontier != frontier or len(engine.remainder.swaps) != swaps
            or walk.snapshot() != positions or (flags and moving(engine, old) is not None)):
        return SwapAnswer(False, f"edit: not swapped: the run moved on while the edit was checked (it is {engine.state}); pause it and apply again")
    groups = tuple((g, *walk.where(old, g)) for g in old.robot.group_names if g in walk.at) if flags else ()
    started = _last_started(engine, old) if flags else engine.remainder.started
    swap = Swap(engine.clock.now(), state.frontier, started, application_digest(old), application_digest(new), file, source, groups)
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
    if flags:
        left = sum(max(0, len(walk.steps(new, g)) - walk.at[g].entered) + (walk.at[g].inside is not None) for g in walk.at)
        return SwapAnswer(True, f"edit: swapped: the operations no group has started are {file}'s ({swap.where()}; {left} call(s) to run); "
                                "resume to continue", swap=swap)
    return SwapAnswer(True, f"edit: swapped: operations from {frontier + 1} on are {file}'s ({len(new.operations) - frontier} to run); "
                            "resume to continue", swap=swap)
