"""Editing a paused ``sync="flags"`` run: where each group stands, and which edits leave what they started alone.

With ``sync="flags"`` there is no one frontier: each group runs its own calls in document order
(:mod:`.flags_mode`), so when the run is paused one group may be inside operation 5 while another
waits before operation 2.  An operation is *started* once some group has entered its call (or gone
past it, left out by its ``<if>``); it stays exactly as it is.  Everything no group has started may
change -- including operations a group has passed without a call there, as long as the edit gives
that group nothing behind where it stands (it would never run it).

:class:`GroupWalk` is each group's way through its calls, kept by the engine's group tasks: how many
of its steps it has entered, which one it is inside, whether it is through.  The tasks read their
next step afresh from the run's application (:meth:`GroupWalk.step`), so after a swap every group
goes on with the edited application from its own position.  :func:`flags_refusal` says why an edit
cannot be taken; each group's step list in the edited application must begin with the steps that
group has entered, operation for operation.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from core_functions.catalog import BindContext, Catalog
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.machine.table import PAUSE

Step = tuple[Operation, Call]


def bare_wait(call: Call, catalog: Catalog, app: Application) -> bool:
    """A call its group sits out: a wait of no time (a left-out group's implicit one among them) -- no step of it,
    in flags mode as in lock-step; the engine's test, and the station's for the builder's marks."""
    if call.function != "wait":
        return False
    if call.params in ((), ("0",)):  # the implicit wait of a group left out: no parsing needed
        return True
    spec = catalog.get("wait")
    assert spec is not None
    (seconds,) = spec.bind(call.params, BindContext(app.robot, call.group, app.cell))
    return bool(seconds == 0)


def group_steps(app: Application, group: str, sits_out: Callable[[Call], bool]) -> list[Step]:
    """The calls a group runs in flags mode, in document order: left-out groups' and bare waits dropped."""
    return [(op, op.calls[group]) for op in app.operations if group in op.calls and not op.calls[group].implicit and not sits_out(op.calls[group])]


def operation_form(operation: Operation) -> list[Any]:
    """An operation as the run knows it, without where it is written: equal forms run the same."""
    calls = [[g, c.function, list(c.params), c.implicit] for g, c in sorted(operation.calls.items())]
    when = [[c.operation, c.group, c.outcome, c.holds] for c in operation.when]
    return [operation.id, operation.name, operation.origin, when, calls]


def form_sha(form: Any) -> str:
    return hashlib.sha256(json.dumps(form, separators=(",", ":"), ensure_ascii=True, default=str).encode()).hexdigest()


@dataclass(frozen=True)
class GroupAt:
    """Where one group of a ``sync="flags"`` run stands."""

    done: tuple[str, ...] = ()  # operations whose call of this group ended, or that its <if> left out
    inside: str | None = None  # the operation it is in: started, not ended
    finished: bool = False  # through all its calls

    @property
    def entered(self) -> int:
        """How many of its steps it has started (the one it is in counted)."""
        return len(self.done) + (self.inside is not None)


@dataclass
class GroupWalk:
    """sync="flags": every group's position in its own steps (:func:`~.flags_mode.group_steps`)."""

    at: dict[str, GroupAt] = field(default_factory=dict)
    #: The engine's test for a call a group sits out (a bare wait): as the group tasks count steps.
    sits_out: Callable[[Call], bool] = lambda call: False
    _steps: dict[str, list[Step]] = field(default_factory=dict)
    _index: dict[str, int] = field(default_factory=dict)
    _of: Application | None = None

    def start(self, groups: Sequence[str], sits_out: Callable[[Call], bool]) -> None:
        self.at = {g: GroupAt() for g in groups}
        self.sits_out = sits_out
        self._steps, self._index, self._of = {}, {}, None

    def steps(self, app: Application, group: str) -> list[Step]:
        """``group``'s steps in ``app`` (kept until the application is another one: a swap)."""
        if app is not self._of:
            self._steps, self._index, self._of = {}, {}, app
        if group not in self._steps:
            self._steps[group] = group_steps(app, group, self.sits_out)
        return self._steps[group]

    def step(self, app: Application, group: str) -> Step | None:
        """The step ``group`` takes next, from ``app`` as it is now (None: it has none left)."""
        steps, k = self.steps(app, group), self.at[group].entered
        return steps[k] if k < len(steps) else None

    def enter(self, group: str, operation: Operation) -> None:
        self.at[group] = replace(self.at[group], inside=operation.id)

    def passed(self, group: str, operation: Operation) -> None:
        """``group``'s call in ``operation`` ended, or its <if> left it out."""
        at = self.at[group]
        self.at[group] = replace(at, done=(*at.done, operation.id), inside=None)

    def finish(self, group: str) -> None:
        self.at[group] = replace(self.at[group], finished=True)

    def snapshot(self) -> tuple[tuple[str, GroupAt], ...]:
        """Every group's position, to tell whether the run moved meanwhile."""
        return tuple(sorted(self.at.items()))

    def where(self, app: Application, group: str) -> tuple[str, int]:
        """(``in`` / ``before`` / ``finished``, the operation's index in ``app``; its count when finished)."""
        at = self.at[group]
        self.steps(app, group)  # the caches are this application's
        if not self._index:  # the status asks at every change: built once per application
            self._index = {op.id: i for i, op in enumerate(app.operations)}
        index = self._index
        if at.inside is not None:
            return "in", index.get(at.inside, len(app.operations))
        step = None if at.finished else self.step(app, group)
        if step is None:
            return "finished", len(app.operations)
        return "before", index.get(step[0].id, len(app.operations))

    def position(self, app: Application, group: str) -> str:
        """``group``'s place as the engine's status carries it (``in:4``, ``before:5``, ``finished:8``: operations
        counted from 1, as in the swap event's answer); "" for a group this walk does not know."""
        if group not in self.at:
            return ""
        kind, index = self.where(app, group)
        return f"{kind}:{index + 1}"

    def frontier(self, app: Application) -> int:
        """The first operation some group has not started (its index)."""
        places = [(index + 1 if kind == "in" else index) for kind, index in (self.where(app, g) for g in self.at)]
        return min(places, default=0)


def describe_where(kind: str, index: int, app: Application) -> str:
    """``in operation 4 'insert'``, ``before operation 5 'home'``, ``finished``."""
    if kind == "finished":
        return "finished"
    return f"{kind} operation {index + 1} {app.operations[index].id!r}"


def still(walk: GroupWalk, group: str, link_state: str | None, waiting: str | None) -> bool:
    """Whether ``group`` stands still while the run is paused: through, before an operation (held there), or in one
    with its machine paused or waiting for a flag or a zone (nothing moves it on but another group)."""
    at = walk.at[group]
    return at.finished or at.inside is None or link_state == PAUSE or waiting is not None


def flags_refusal(walk: GroupWalk, old: Application, new: Application) -> str | None:
    """Why ``new`` cannot replace what no group of the paused run has started; None when it may be checked."""
    index = {op.id: i for i, op in enumerate(old.operations)}
    new_index = {op.id: i for i, op in enumerate(new.operations)}
    for group, at in sorted(walk.at.items(), key=lambda item: old.robot.group_names.index(item[0]) if item[0] in old.robot.group_names else 0):
        then, now = walk.steps(old, group)[: at.entered], walk.steps(new, group)
        for k, (operation, _) in enumerate(then):
            state = "is running" if at.inside == operation.id else "has already run"
            where = f"operation {index[operation.id] + 1} {operation.id!r}"
            if k < len(now) and operation_form(now[k][0]) == operation_form(operation):
                continue
            kept = next((op for op in new.operations if op.id == operation.id), None)
            if k < len(now) and kept is not None and operation_form(kept) == operation_form(operation):
                added = now[k][0]
                where = f"operation {new_index[operation.id] + 1} {operation.id!r}"  # both as the edited file counts them
                return (f"edit: operation {new_index[added.id] + 1} {added.id!r} gives {group} a call before {where}, which {group} "
                        f"{'is in' if state == 'is running' else 'has run'}: it would never run it; only what no group has started may change")
            return (f"edit: {where} {state} ({group} started it); only operations no group has started may change")
        if at.finished and len(now) > len(then):
            added = now[len(then)][0]
            return (f"edit: operation {new_index[added.id] + 1} {added.id!r} gives {group} a call, but {group} has finished its calls: "
                    "it would never run it")
    if [operation_form(op) for op in new.operations] == [operation_form(op) for op in old.operations]:
        return "edit: nothing to change: the operations no group has started are the run's"
    return None
