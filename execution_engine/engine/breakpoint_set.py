"""Which operations a run pauses before, where each group is, and how an operator names an operation.

Kept apart from the engine's side of breakpoints (:mod:`.breakpoints`) because it is plain
bookkeeping: the file's ``break="true"`` operations, changed at run time (never written back), the
one-shot "run to here" target, the groups held before an operation now, and the run time they were
held (a ``wait_flag`` does not count it against its timeout: the operator's look at a held group
is not the application being late).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from core_functions.printable import printable
from execution_engine.app_model.model import Application, Operation
from node_transport.clock import Clock

#: What the breakpoint service takes (``clear_all``: every breakpoint and the run-to target).
ACTIONS = ("set", "clear", "toggle", "clear_all")
#: Why a group holds before an operation: a breakpoint, the run-to target, the end of a step.
KINDS = ("break", "run_to", "step")


def describe(index: int, operation: Operation) -> str:
    """How the operator reads an operation: ``operation 4 'insert_left' (line 37)``, with its loop iteration."""
    made = f", {operation.origin}" if operation.origin else ""
    return f"operation {index + 1} {printable(operation.id)!r} (line {operation.line}{made})"


def pause_message(kind: str, where: str, groups: Iterable[str] = (), flags: bool = False) -> str:
    """Why the run paused: ``paused at breakpoint before operation 4 'insert_left' (line 37)``."""
    head = {
        "break": f"paused at breakpoint before {where}",
        "run_to": f"paused before {where}: the run-to target is reached",
        "step": f"one step done: paused before {where}",
    }[kind]
    held = list(groups)
    if flags and held:
        head += f"; {', '.join(held)} {'holds' if len(held) == 1 else 'hold'} there, the other groups go on until they need {'it' if len(held) == 1 else 'them'}"
    return head


@dataclass
class Hold:
    """A group held before an operation, and why."""

    index: int
    kind: str


@dataclass
class BreakpointSet:
    """The breakpoints of the run under way (a new run starts from its file's again)."""

    operations: tuple[Operation, ...] = ()
    index: dict[str, int] = field(default_factory=dict)
    active: set[str] = field(default_factory=set)  # the ids the run pauses before
    target: str | None = None  # "run to here": paused before once, then forgotten
    at: dict[str, int] = field(default_factory=dict)  # each group: the index of the next operation it starts
    finished: set[str] = field(default_factory=set)  # sync="flags": groups through all their calls
    held: dict[str, Hold] = field(default_factory=dict)  # groups holding before an operation now
    waiting: set[str] = field(default_factory=set)  # sync="flags": groups waiting for a held partner
    stepping: set[str] = field(default_factory=set)  # sync="flags": groups to hold before their next operation
    paused: set[str] = field(default_factory=set)  # sync="flags": groups at a barrier with a held group, paused meanwhile
    taken: set[str] = field(default_factory=set)  # operations a hold before was continued: passed from now on
    run: object | None = None  # the report of the run these belong to
    app: Application | None = None  # the application they were read from (an edit of a paused run swaps it)
    first: int = 0
    _held_total: float = 0.0
    _held_since: float | None = None

    def ensure(self, app: Application, run: object, first: int = 0) -> None:
        """Start over from ``app``'s breakpoints when ``run`` is another run than the last one seen."""
        if run is self.run:
            return
        self.run, self.first, self.app = run, first, app
        self.operations = app.operations
        self.index = {op.id: i for i, op in enumerate(app.operations)}
        self.active = {op.id for op in app.operations if op.breakpoint}
        self.target = None
        for each in (self.at, self.held, self.finished, self.waiting, self.stepping, self.taken, self.paused):
            each.clear()
        self._held_total, self._held_since = 0.0, None

    def adopt(self, app: Application) -> None:
        """The same run goes on with an edited application (engine/remainder_swap.py): its file's breakpoints
        replace the old file's; those set at run time stay where their operations still are."""
        if app is self.app:
            return
        old_file = {op.id for op in self.operations if op.breakpoint}
        self.app, self.operations = app, app.operations
        self.index = {op.id: i for i, op in enumerate(app.operations)}
        self.active = {i for i in self.active - old_file if i in self.index} | {op.id for op in app.operations if op.breakpoint}
        if self.target is not None and self.target not in self.index:
            self.target = None

    def ids(self) -> list[str]:
        """The operations the run pauses before, in run order."""
        return sorted(self.active, key=lambda i: self.index.get(i, 0))

    def find(self, text: str) -> int | str:
        """The index of the operation ``text`` names (its id, or #N / N for the N-th); a one-line refusal otherwise."""
        text = text.strip()
        if not text:
            nxt = self.next_index()
            return nxt if nxt is not None else "no operation is left to run"
        if text in self.index:
            return self.index[text]
        number = text[1:] if text.startswith("#") else text
        if number.isdigit() and 1 <= int(number) <= len(self.operations):
            return int(number) - 1
        return (f"no operation {printable(text)!r} in this run: give an operation's id or #N "
                f"(1 to {len(self.operations)}, as the engine's status counts them)")

    def next_index(self) -> int | None:
        """The first operation not yet started by every group that is still running (None: all started)."""
        going = [i for g, i in self.at.items() if g not in self.finished]
        nxt = min(going) if going else (self.first if not self.at else None)
        return nxt if nxt is not None and nxt < len(self.operations) else None

    def holding_at(self, index: int) -> bool:
        return any(hold.index == index for hold in self.held.values())

    def due(self, group: str | None, index: int) -> str | None:
        """Why ``group`` (None: every group, lock-step) must hold before operation ``index``, if it must."""
        if group is not None and group in self.stepping:
            return "step"
        operation = self.operations[index]
        if group is not None:  # another group holds there already: this one joins it
            joined = next((hold.kind for hold in self.held.values() if hold.index == index), None)
            if joined is not None:
                return joined
        if operation.id == self.target:
            return "run_to"
        if operation.id in self.active and operation.id not in self.taken:
            return "break"
        return None

    def hold(self, groups: Iterable[str], index: int, kind: str, clock: Clock) -> None:
        if not self.held:
            self._held_since = clock.now()
        for group in groups:
            self.held[group] = Hold(index, kind)
            self.stepping.discard(group)

    def release(self, clock: Clock, step: bool = False) -> set[str]:
        """Let every held group go on (``step``: each holds again before its next operation); the groups released."""
        released = set(self.held)
        for hold in self.held.values():
            operation = self.operations[hold.index].id
            self.taken.add(operation)
            if operation == self.target:
                self.target = None
        if step:
            self.stepping |= released
        self.held.clear()
        if self._held_since is not None:
            self._held_total += clock.now() - self._held_since
            self._held_since = None
        return released

    def passed(self, index: int) -> None:
        """Lock-step: every group went past operation ``index``'s hold."""
        operation = self.operations[index].id
        if operation == self.target:
            self.target = None
        self.taken.add(operation)

    def held_seconds(self, now: float) -> float:
        """Run time so far during which some group was held before an operation."""
        return self._held_total + (now - self._held_since if self._held_since is not None else 0.0)
