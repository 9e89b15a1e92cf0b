"""Writing a run's checkpoint as it goes: a sink of the machines' status, like the trace.

Every function start and every function result (``function_start`` / ``function_end`` on the
groups' status topics) becomes one transaction in the :class:`CheckpointStore`, the result with
what it changed: what the hand holds afterwards (the catalog's ``leaves``), the trajectory a
recording function stored, and the error-policy counters (errors, retries).  Operator commands
(the engine's events) are counted too.  Operations that are not the application's (the way to a
safe pose) are not checkpointed: a resume never replays them.
"""
from __future__ import annotations

import logging
import sqlite3

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Application, Call
from execution_engine.checkpoint.resume import app_meta
from execution_engine.checkpoint.store import STARTED, CheckpointStore
from execution_engine.engine.remainder_swap import Swap
from node_transport.wire import EngineEvent, SmStatus

log = logging.getLogger(__name__)


def recorded_trajectory(catalog: Catalog, call: Call) -> str | None:
    """The trajectory name a recording function stores (its ``name`` param), else None."""
    spec = catalog.get(call.function)
    if spec is None or "record" not in spec.name:
        return None
    for index, param in enumerate(spec.params):
        if param.name == "name" and index < len(call.params):
            return call.params[index]
    return None


class CheckpointWriter:
    """Folds status events into the checkpoint; a failing disk is reported once, never stops the run."""

    def __init__(self, store: CheckpointStore, app: Application, catalog: Catalog) -> None:
        self.store = store
        self.app = app
        self.catalog = catalog
        self._index = {op.id: i for i, op in enumerate(app.operations)}
        self._attempts: dict[tuple[int, str], int] = {}
        self.error: str = ""
        self.reason: str = ""  # the database's words for the first failure (database or disk is full)

    def on_status(self, status: SmStatus) -> None:
        if status.event not in ("function_start", "function_end") or status.operation not in self._index:
            return
        index = self._index[status.operation]
        key = (index, status.group)
        call = self.app.operations[index].calls.get(status.group)
        function = status.function or (call.function if call else "")
        if status.event == "function_start":
            self._attempts[key] = self._attempts.get(key, 0) + 1
            attempt = self._attempts[key]
            self._guard(lambda: self.store.function_event(index, status.operation or "", status.group, function, attempt, STARTED, status.t))
            return
        attempt = self._attempts.get(key, 1)
        outcome = status.outcome or "aborted"
        spec = self.catalog.get(function)
        holds = spec.leaves.value if spec is not None and spec.leaves is not None else None
        trajectory = recorded_trajectory(self.catalog, call) if call is not None else None
        counters = {"errors": 0 if outcome == "succeeded" else 1, "retries": 1 if attempt > 1 and outcome == "succeeded" else 0}
        self._guard(lambda: self.store.function_result(
            index, status.operation or "", status.group, function, attempt, outcome, status.t, holds, trajectory, counters
        ))

    def swapped(self, app: Application, swap: Swap) -> None:
        """A paused run's remainder was edited (the engine's hook, engine/remainder_swap.py): the checkpoint now belongs
        to the new application, by its file and digest, and indexes the functions by its operations."""
        self.app = app
        self._index = {op.id: i for i, op in enumerate(app.operations)}

        def record() -> None:  # sync="flags": where each group stood, as the meta key swap_<n>_groups
            where = {f"swap_{len(self.store.swaps()) + 1}_groups": swap.where()} if swap.groups else {}
            self.store.swap(swap.t, swap.frontier, swap.operation, swap.old_digest, swap.new_digest, {**app_meta(app), **where})

        self._guard(record)

    def on_event(self, event: EngineEvent) -> None:
        if event.event == "operator" and event.accepted:
            self._guard(lambda: self.store.count({"operator_actions": 1}))
        elif event.event == "outcome" and event.operation in self._index and event.source and event.answer:
            index, group, outcome = self._index[event.operation], event.source, event.answer
            self._guard(lambda: self.store.outcome(index, event.operation or "", group, outcome))

    def _guard(self, change: object) -> None:
        if self.error:
            return
        try:
            change()  # type: ignore[operator]
        except sqlite3.Error as error:
            self.reason = str(error)
            self.error = f"checkpoint {self.store.path}: {error}"
            log.error("%s; the run goes on without checkpoints", self.error)
