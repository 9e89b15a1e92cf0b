"""Resuming a run from its checkpoint: where to start, and what to ask the operator first.

The rules (issue 11): a checkpoint of another application or cell is refused, naming the file
that changed; a function that completed (or that an operator skipped) is never run again; in the
operation that was in flight, every group whose function had not completed was *interrupted*:
it may have moved half-way, inserted half a rivet, so it is brought back under operator control
before anything moves -- the engine raises an alarm "interrupted: ... — reset to redo the
function, or skip" -- unless the answer was given in advance (``--on-interrupted redo|skip``).
Groups of that operation that completed, and groups that sit it out, wait; operations after it
run as usual.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from core_functions.catalog import BindContext, Catalog
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.checkpoint.store import DONE, SUCCEEDED, CheckpointError, CheckpointStore
from execution_engine.engine.dispatch import ApplicationAborted
from execution_engine.engine.operator import CONSOLE_KEYS
from execution_engine.recorder.recorder import file_digest
from execution_engine.trace_report import read_trace
from node_transport.wire import engine_service

if TYPE_CHECKING:
    from execution_engine.engine.engine import ExecutionEngine

def sits_out(app: Application, catalog: Catalog, call: Call) -> bool:
    """A ``wait`` without seconds is never sent to the machine: nothing of it can be interrupted."""
    if call.function != "wait":
        return False
    if call.params in ((), ("0",)):
        return True
    spec = catalog.get("wait")
    return spec is not None and spec.bind(call.params, BindContext(app.robot, call.group, app.cell))[0] == 0


def app_meta(app: Application) -> dict[str, str]:
    """What a checkpoint remembers of the application, to refuse resuming another one."""
    cell = app.cell.path if app.cell is not None else None
    meta = {
        "application": app.name,
        "application_path": str(app.path),
        "application_sha256": file_digest(app.path),
        "cell_path": str(cell or ""),
        "cell_sha256": file_digest(cell),
        "robot": app.robot.name,
    }
    if app.includes:  # the applications its <call>s bring in: a changed block changes the operations too
        meta["includes_sha256"] = "\n".join(f"{path}={file_digest(path)}" for path in app.includes)
    return meta


def check_same(store: CheckpointStore, app: Application) -> None:
    """CheckpointError naming what changed since the checkpoint was written."""
    then, now = store.meta(), app_meta(app)
    if not then:
        raise CheckpointError(f"{store.path}: holds no run to resume")
    changed = []
    if then.get("application_sha256") != now["application_sha256"]:
        changed.append(f"the application {now['application_path']} (was {then.get('application_path')}, sha256 "
                       f"{then.get('application_sha256', '?')[:12]}… then, {now['application_sha256'][:12]}… now)")
    if then.get("includes_sha256", "") != now.get("includes_sha256", ""):
        changed.append("an application it calls (" + ", ".join(_changed_includes(then.get("includes_sha256", ""), now.get("includes_sha256", ""))) + ")")
    if then.get("cell_sha256") != now["cell_sha256"]:
        changed.append(f"the cell model {now['cell_path'] or '(none)'} (was {then.get('cell_path') or '(none)'}, sha256 "
                       f"{then.get('cell_sha256', '?')[:12] or '-'}… then, {now['cell_sha256'][:12] or '-'}… now)")
    edits = store.swaps()
    if changed and edits and then.get("application_sha256") != now["application_sha256"]:  # the run goes on with the edited file
        _, frontier, operation, _, _, path = edits[-1]
        raise CheckpointError(
            f"{store.path}: cannot resume with {now['application_path']}: the run was edited while paused (after operation "
            f"{operation or '-'}) and goes on with {path} (sha256 {then.get('application_sha256', '?')[:12]}…), operations from "
            f"{frontier + 1} on as that file has them; resume with that file, or start the run afresh without --resume"
        )
    if changed:
        raise CheckpointError(
            f"{store.path}: cannot resume: {' and '.join(changed)} changed since the checkpoint; resuming would skip or repeat "
            "the wrong functions. Restore the files, or start the run afresh without --resume"
        )


def _changed_includes(then: str, now: str) -> list[str]:
    """The called files whose digest differs (or that came or went) between two checkpoints' lists."""
    before = dict(item.rsplit("=", 1) for item in then.splitlines() if "=" in item)
    after = dict(item.rsplit("=", 1) for item in now.splitlines() if "=" in item)
    return sorted(path for path in before.keys() | after.keys() if before.get(path) != after.get(path))


@dataclass
class ResumePlan:
    """Where a resumed run starts and what it must ask first (the engine calls :meth:`first_operation`)."""

    index: int  # the first operation not complete (len(operations): nothing left)
    done: frozenset[str]  # groups of that operation that completed
    interrupted: dict[str, Call]  # groups whose function was in flight when the run stopped
    answer: str  # ask / redo / skip
    checkpoint: str
    continues: str  # the trace / recording this run continues
    #: The named outcome of each tested function done before, by "operation/group": the branches taken again.
    outcomes: dict[str, str] = field(default_factory=dict)
    on_skip: Callable[[int, Operation, str], None] = field(default=lambda index, op, group: None)
    #: sync="flags" (each group its own order, :meth:`position_groups`): the calls done before, by (operation id, group),
    #: and those started but not done -- by id, since an edit of the paused run may have moved the indexes.
    calls_done: frozenset[tuple[str, str]] = frozenset()
    calls_started: frozenset[tuple[str, str]] = frozenset()

    def message(self, engine: ExecutionEngine, operation: Operation, group: str, call: Call | None = None) -> str:
        call = call or self.interrupted[group]
        where = f"{call.file}:{call.line}" if call.file else f"operation {operation.id}"
        if operation.origin:
            where += f", {operation.origin}"
        reset, skip, stop = (engine.node.resolve(engine_service(c)) for c in ("reset", "skip", "stop"))
        return (
            f"interrupted: {group} was running {call.function} of operation {operation.id} ({where}) when the run stopped "
            f"— reset to redo the function, or skip (keys {CONSOLE_KEYS['reset']!r} / {CONSOLE_KEYS['skip']!r} of run --interactive, "
            f"or call {reset} / {skip}; {stop} ends the run)"
        )

    async def first_operation(self, engine: ExecutionEngine, operation: Operation) -> Operation:
        """The operation to run first, once every interrupted group has its answer; ApplicationAborted on stop."""
        calls = dict(operation.calls)
        for group in self.done:
            calls[group] = Call(group, "wait", (), implicit=True)
        for group in sorted(self.interrupted):
            if await self._answer(engine, operation, group, self.interrupted[group]) == "skip":
                calls[group] = Call(group, "wait", (), implicit=True)
                self.on_skip(self.index, operation, group)
        engine.announce(f"resumed from {self.checkpoint} at operation {operation.id}; continues {self.continues or '(no earlier record)'}")
        return replace(operation, calls=calls)

    async def _answer(self, engine: ExecutionEngine, operation: Operation, group: str, call: Call) -> str:
        """redo or skip for ``group``'s interrupted ``call``: given in advance, or the operator's; ApplicationAborted on stop."""
        if self.answer != "ask":
            return self.answer
        reply = await engine.hold_for_answer(self.message(engine, operation, group, call))
        if reply == "unanswerable":
            raise ApplicationAborted(
                f"{group} was interrupted and nobody can answer (run with --interactive at a terminal, "
                "or give the answer in advance: --on-interrupted redo|skip)"
            )
        if reply == "stop":
            raise ApplicationAborted(f"stopped while {group} waited for an answer to its interruption")
        return "redo" if reply == "reset" else "skip"

    async def position_groups(self, engine: ExecutionEngine, steps: Mapping[str, Sequence[tuple[Operation, Call]]]) -> dict[str, int]:
        """sync="flags": how many of each group's steps (its calls in its own order) are behind it -- every one up to
        its last call done, the flags and waits among them included (a group goes its calls in order; the engine's
        flags are not checkpointed); a call started and not done after them is interrupted: redo (it stays) or skip."""
        where: dict[str, int] = {}
        for group, calls in steps.items():
            k = 1 + max((i for i, (operation, _) in enumerate(calls) if (operation.id, group) in self.calls_done), default=-1)
            if k < len(calls) and (calls[k][0].id, group) in self.calls_started:
                operation, call = calls[k]
                if await self._answer(engine, operation, group, call) == "skip":
                    assert engine.app is not None
                    self.on_skip(engine.app.operations.index(operation), operation, group)
                    k += 1
            where[group] = k
        at = ", ".join(f"{g} after {k} call(s)" for g, k in where.items())
        engine.announce(f"resumed from {self.checkpoint} ({at}); continues {self.continues or '(no earlier record)'}")
        return where


def reconcile(store: CheckpointStore, app: Application, *, write: bool = True, outcomes: dict[str, str] | None = None) -> set[tuple[int, str]]:
    """Take over results that reached an earlier run's trace but not the checkpoint.

    The trace is written first, the checkpoint right after (a kill can land between the two); a
    trace line is only there if the function completed, so such a function counts as done.
    Returns every (operation index, group) done; ``write`` False only works it out (a store opened
    read-only, to check a ``--resume`` before anything is written)."""
    index = {op.id: i for i, op in enumerate(app.operations)}
    done = store.done()
    found = outcomes if outcomes is not None else {}
    found.update({f"{operation}/{group}": outcome for _, operation, group, outcome in store.outcomes()})

    def take(record: dict[str, object], run: int) -> None:
        operation, group = str(record.get("operation")), str(record.get("group"))
        if record.get("event") == "outcome" and operation in index and record.get("outcome"):
            outcome = str(record.get("outcome"))  # a tested function's outcome, in the trace and not yet the checkpoint
            if f"{operation}/{group}" not in found:
                found[f"{operation}/{group}"] = outcome
                done.add((index[operation], group))
                if write:
                    store.outcome(index[operation], operation, group, outcome)
            return
        if record.get("event") == "function_end" and record.get("outcome") == SUCCEEDED and operation in index:
            if (index[operation], group) not in done:
                done.add((index[operation], group))
                if write:
                    store.function_event(index[operation], operation, group, str(record.get("function", "")), 0, SUCCEEDED, float(str(record.get("t", 0.0))), run)

    for run, trace, _ in store.runs():
        if trace and Path(trace).is_file():
            read_trace(trace, lambda record, run=run: take(record, run))
    return done


def plan_resume(store: CheckpointStore, app: Application, catalog: Catalog, answer: str, *, write: bool = True) -> ResumePlan:
    """Where to start: the first operation with a group whose function has not completed (``write``:
    see :func:`reconcile`)."""
    check_same(store, app)
    outcomes: dict[str, str] = {}
    done = reconcile(store, app, write=write, outcomes=outcomes)
    touched = {r.op_index for r in store.functions()}
    ids = [op.id for op in app.operations]
    calls_done = frozenset({(r.operation, r.group) for r in store.functions() if r.outcome in DONE}
                           | {(o, g) for _, o, g, _ in store.outcomes()} | {(ids[i], g) for i, g in done - store.done() if i < len(ids)})  # the trace's
    by_id = {"calls_done": calls_done, "calls_started": frozenset((r.operation, r.group) for r in store.functions()) - calls_done}
    runs = store.runs()
    continues = ", ".join(p for _, trace, record in runs[-1:] for p in (trace, record) if p)
    for index, operation in enumerate(app.operations):
        if not all(c.met(outcomes.get(f"{c.operation}/{c.group}")) for c in operation.when):
            if all(f"{c.operation}/{c.group}" in outcomes for c in operation.when):
                continue  # its branch was not taken before the crash: left out again
        needed = {g for g, call in operation.calls.items() if not sits_out(app, catalog, call)}
        finished = {g for g in needed if (index, g) in done}
        if needed - finished:
            interrupted = {g: operation.calls[g] for g in needed - finished} if index in touched else {}
            return replace(ResumePlan(index, frozenset(finished), interrupted, answer, str(store.path), continues, outcomes), **by_id)
    return replace(ResumePlan(len(app.operations), frozenset(), {}, answer, str(store.path), continues, outcomes), **by_id)


def next_name(path: str, run: int) -> str:
    """The file a resumed run writes instead of ``path``: ``run.jsonl`` -> ``run.resume2.jsonl``."""
    p = Path(path)
    stem = p.stem.split(".resume")[0]
    return str(p.with_name(f"{stem}.resume{run}{p.suffix}"))
