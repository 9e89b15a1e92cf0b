"""Flags and the asynchronous mode of the engine (paper §2.2.3: "flags and synchronization tools").

``set_flag(name)`` and ``wait_flag(name, timeout)`` are carried out here, never by a group
machine: a flag is the engine's to hold, set once and never cleared during a run.  In lock-step
(``sync="operation"``) they take part in their operation like any function (a wait_flag holds its
group in the operation until another group of it, or of an earlier one, set the flag).  With
``sync="flags"`` :func:`run_groups` drives every group through its own functions in document
order, each in its own task, with no barrier per operation: a group waits only where the
application says so -- a ``wait_flag``, a synchronised function (its machine meets the partners
at the barrier, as in lock-step: same barrier key, same partner list) or, before a motion, a zone
(engine/zones.py, in both modes).

Every wait is kept (:class:`FlagWait`) for the run report's idle split and published as an
EngineEvent (``event="flag"``: ``source`` the group, ``command`` the flag, ``state`` waiting /
passed / timeout / set) so the trace and the Fig. 12 timeline show it.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from core_functions.catalog import BindContext, Catalog
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.clock import Clock
from execution_engine.transport.wire import FaultKind, SmRequest, SmResult

if TYPE_CHECKING:
    from execution_engine.engine.engine import ExecutionEngine
    from execution_engine.engine.zones import ZoneBoard

SET_FLAG, WAIT_FLAG = "set_flag", "wait_flag"
ENGINE_FUNCTIONS = (SET_FLAG, WAIT_FLAG)


@dataclass(frozen=True)
class FlagWait:
    """One wait of a group: for a flag (or a zone: ``kind``), from ``t_start`` to ``t_end``, and how it ended."""

    group: str
    operation: str
    flag: str
    t_start: float
    t_end: float
    outcome: str  # passed / timeout / stopped
    kind: str = "flag"

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


def wait_totals(waits: Iterable[FlagWait], group: str | None = None) -> dict[tuple[str, str], float]:
    """Seconds waited per (kind, flag or zone) -- of ``group``, or of every group -- in the order
    first waited: what a run report and the dry run split a group's idle time into."""
    totals: dict[tuple[str, str], float] = {}
    for wait in waits:
        if group is None or wait.group == group:
            totals[(wait.kind, wait.flag)] = totals.get((wait.kind, wait.flag), 0.0) + wait.duration
    return totals


def costliest(totals: dict[tuple[str, str], float], count: int | None = None) -> list[tuple[tuple[str, str], float]]:
    """The totals longest first (ties in the order first waited), the first ``count`` of them."""
    return sorted(totals.items(), key=lambda kv: -kv[1])[:count]


class FlagBoard:
    """The flags of one run and the waits for them."""

    def __init__(self, clock: Clock, publish: Callable[..., None], stopped: Callable[[], bool] = lambda: False) -> None:
        self.clock = clock
        self.publish = publish  # (group, flag, state, operation[, kind]) -> an EngineEvent
        self.stopped = stopped  # an operator stopped the run: every wait ends
        self._set: dict[str, asyncio.Event] = {}
        self.waits: list[FlagWait] = []
        self.waiting: dict[str, str] = {}  # group -> "flag X" it waits for now
        self.zones: ZoneBoard | None = None  # the run's zones (their waits are kept in ``waits`` too)

    def waiting_for(self, group: str) -> str | None:
        """What ``group`` waits for now: "flag X", "zone Z" or None."""
        return self.waiting.get(group) or (self.zones.waiting.get(group) if self.zones is not None else None)

    def _event(self, name: str) -> asyncio.Event:
        return self._set.setdefault(name, asyncio.Event())

    def is_set(self, name: str) -> bool:
        return self._event(name).is_set()

    def set(self, group: str, name: str, operation: str) -> None:
        self._event(name).set()
        self.publish(group, name, "set", operation)

    async def wait(self, group: str, name: str, timeout: float, operation: str) -> str:
        """Wait until ``name`` is set ("passed"), ``timeout`` seconds of run time passed ("timeout") or
        the run is stopped ("stopped": looked at every :data:`STOP_POLL` seconds)."""
        event = self._event(name)
        if event.is_set():
            return "passed"
        start = self.clock.now()
        self.waiting[group] = f"flag {name}"
        self.publish(group, name, "waiting", operation)
        outcome = "stopped"
        try:
            outcome = await until(self.clock, event, start + timeout, self.stopped)
            return outcome
        finally:
            self.waiting.pop(group, None)
            self.waits.append(FlagWait(group, operation, name, start, self.clock.now(), outcome))
            self.publish(group, name, outcome, operation)

    def result(self, request: SmRequest, group: str, catalog: Catalog, app: Application) -> asyncio.Future[SmResult]:
        """Carry out a set_flag / wait_flag request; its result as a machine would send it."""
        spec = catalog.get(request.function)
        assert spec is not None
        values = spec.bind(request.params, BindContext(app.robot, group, app.cell))
        loop = asyncio.get_running_loop()
        future: asyncio.Future[SmResult] = loop.create_future()
        t0 = self.clock.now()

        def answer(ok: bool, error: str = "") -> SmResult:
            t = self.clock.now()
            return SmResult(
                id=request.id, group=group, operation=request.operation, function=request.function,
                outcome="succeeded" if ok else "aborted", error=error, t_start=t, t_end=t,
                fault=None if ok else FaultKind.TIMEOUT,
            )

        if request.function == SET_FLAG:
            self.set(group, values[0], request.operation)
            future.set_result(answer(True))
            return future

        async def waiting() -> None:
            name, timeout = values[0], float(values[1])
            try:
                outcome = await self.wait(group, name, timeout, request.operation)
            except asyncio.CancelledError:
                future.cancel()
                raise
            waited = self.clock.now() - t0
            if outcome == "stopped":
                future.set_result(replace(answer(False, f"stopped while waiting for flag {name!r}"), outcome="preempted", fault=FaultKind.STOPPED))
                return
            ok = outcome == "passed"
            future.set_result(answer(ok, "" if ok else f"flag {name!r} was not set within {timeout:g} s (waited {waited:.2f} s)"))

        task = loop.create_task(waiting())
        future.add_done_callback(lambda f: task.cancel() if f.cancelled() else None)
        return future


#: How often a wait looks whether the run was stopped (run seconds).
STOP_POLL = 0.5
#: Run seconds: a deadline this close is reached (a wait of 1e-16 s would never let simulated time move).
_EPSILON = 1e-9


async def until(clock: Clock, event: asyncio.Event, deadline: float, stopped: Callable[[], bool]) -> str:
    """Wait for ``event``: "passed", "timeout" at ``deadline`` (run time) or "stopped" when ``stopped()``."""
    while not event.is_set():
        if stopped():
            return "stopped"
        left = deadline - clock.now()
        if left <= _EPSILON:  # float sums never land on a deadline exactly: closer than this is reached
            return "timeout"
        try:
            await clock.wait_for(event.wait(), min(left, STOP_POLL))
        except asyncio.TimeoutError:
            continue
    return "passed"


def group_steps(app: Application, group: str, sits_out: Callable[[Call], bool]) -> list[tuple[Operation, Call]]:
    """The calls a group runs in flags mode, in document order: left-out groups' and bare waits dropped."""
    return [(op, op.calls[group]) for op in app.operations if group in op.calls and not op.calls[group].implicit and not sits_out(op.calls[group])]


async def run_groups(engine: ExecutionEngine, app: Application) -> None:
    """``sync="flags"``: each group through its own calls at once; the first failure ends them all."""
    groups = [g for g in app.robot.group_names if group_steps(app, g, engine._sits_out)]
    tasks = {g: asyncio.ensure_future(run_group(engine, g, group_steps(app, g, engine._sits_out))) for g in groups}
    try:
        done, _ = await asyncio.wait(tasks.values(), return_when=asyncio.FIRST_EXCEPTION)
        failed = next((t for t in done if not t.cancelled() and t.exception() is not None), None)
        if failed is not None:
            for task in tasks.values():
                task.cancel()
            await asyncio.gather(*tasks.values(), return_exceptions=True)
            error = failed.exception()
            assert error is not None
            raise error
    finally:
        for task in tasks.values():
            task.cancel()


def _meeting(operation: Operation, call: Call, catalog: Catalog) -> dict[str, Call]:
    """The group's call and, for a synchronised function, its partners' (one barrier key, one partner list)."""
    spec = catalog.get(call.function)
    if spec is None or not spec.sync:
        return {call.group: call}
    return {g: c for g, c in operation.calls.items() if (s := catalog.get(c.function)) is not None and s.sync == spec.sync}


async def run_group(engine: ExecutionEngine, group: str, steps: list[tuple[Operation, Call]]) -> None:
    """One group's calls in order, each when the one before succeeded (retried as the policy says)."""
    from execution_engine.engine.engine import ApplicationAborted  # the engine imports this module

    report = engine.report
    assert report is not None
    for operation, call in steps:
        if not await engine._gate():
            raise ApplicationAborted(engine._stop_reason or "stopped")
        engine._operation = operation
        index = engine.app.operations.index(operation) if engine.app is not None else 0
        engine._op_index = index
        attempt = 1
        while True:
            dispatch = engine._dispatch(operation, _meeting(operation, call, engine.catalog), attempt, only=group)[group]
            remaining = dispatch.deadline - engine.clock.now()
            try:
                result = await engine.clock.wait_for(asyncio.shield(dispatch.future), max(0.0, remaining))
            except asyncio.TimeoutError:
                await engine._abandon({group: dispatch}, group, f"no result within {engine.function_timeout:g} s")
                raise  # unreachable: _abandon raises ApplicationAborted
            report.group_busy[group] += max(0.0, result.t_end - result.t_start)
            report.group_functions[group] += 1
            if result.outcome == "succeeded":
                if call.function not in ENGINE_FUNCTIONS:
                    await engine._await_ready((group,))
                engine.zones.ended(operation.id, group)
                break
            await _on_failure(engine, group, operation, dispatch.request, result)
            attempt += 1


async def _on_failure(engine: ExecutionEngine, group: str, operation: Operation, request: SmRequest, result: SmResult) -> None:
    """The error policy for one group's failed function in flags mode; returns to retry, raises to end."""
    from execution_engine.engine.engine import ApplicationAborted
    from execution_engine.engine.report import GroupError
    from execution_engine.machine.table import ERROR_HANDLING, READY

    app, report = engine.app, engine.report
    assert app is not None and report is not None
    error = result.error or result.outcome
    fault = result.fault.value if result.fault is not None else None
    report.errors.append(GroupError(group, operation.id, request.function, error, request.attempt, engine.clock.now(), fault))
    if result.outcome == "preempted" or engine._stop_reason is not None:
        raise ApplicationAborted(engine._stop_reason or f"{group} was stopped: {error}")
    what = f"{group}: {request.function} failed: {error}"
    others = [g for g in engine.links if g != group]
    retry, plan = engine._retry_plan([result], request.attempt)
    engine._set_state("error", f"{what} - {plan}")
    await engine._pause_groups(others)
    unanswered = ""
    if app.error_policy.action == "alarm" and not retry:
        retry, unanswered = await engine._alarm(group, error, plan, app.error_policy.alarm_timeout)
    else:
        engine._note_recovery(plan)
    if not retry:
        for other in others:
            await engine.links[other].command("stop")
        if app.error_policy.action == "safe_pose" and app.error_policy.safe_pose:
            await engine._go_safe(list(engine.links))
        raise ApplicationAborted(what + unanswered)
    report.retries += 1
    link = engine.links[group]
    if link.state == ERROR_HANDLING:
        await link.command("reset")
    if not await link.wait_state((READY,), engine.service_timeout):
        raise ApplicationAborted(f"{group} could not be reset for a retry (it is in {link.state})")
    for other in others:
        await engine.links[other].command("resume")
    engine._set_state("running")
