"""Flags (paper §2.2.3: "flags and synchronization tools"): set once, waited for, and every wait kept.

``set_flag(name)`` and ``wait_flag(name, timeout)`` are carried out here, never by a group
machine: a flag is the engine's to hold, set once and never cleared during a run.  In lock-step
(``sync="operation"``) they take part in their operation like any function (a wait_flag holds its
group in the operation until another group of it, or of an earlier one, set the flag).  With
``sync="flags"`` each group runs through its own functions (engine/flags_mode.py) and waits only
where the application says so: a ``wait_flag``, a synchronised function or, before a motion, a zone
(engine/zones.py, in both modes).

Every wait is kept (:class:`~.waits.FlagWait`) for the run report's idle split and published as an
EngineEvent (``event="flag"``: ``source`` the group, ``command`` the flag, ``state`` waiting /
passed / timeout / set) so the trace and the Fig. 12 timeline show it.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

from core_functions.catalog import BindContext, Catalog
from execution_engine.app_model.model import Application
from node_transport.clock import Clock
from execution_engine.engine.waits import FlagWait
from node_transport.wire import FaultKind, SmRequest, SmResult

SET_FLAG, WAIT_FLAG = "set_flag", "wait_flag"
ENGINE_FUNCTIONS = (SET_FLAG, WAIT_FLAG)


class ZoneWaits(Protocol):
    """What the flags ask of the run's zones (engine/zones.py's ZoneBoard): who waits for which zone now."""

    @property
    def waiting(self) -> dict[str, str]: ...


class FlagBoard:
    """The flags of one run and the waits for them."""

    def __init__(self, clock: Clock, publish: Callable[..., None], stopped: Callable[[], bool] = lambda: False) -> None:
        self.clock = clock
        self.publish = publish  # (group, flag, state, operation[, kind]) -> an EngineEvent
        self.stopped = stopped  # an operator stopped the run: every wait ends
        self._set: dict[str, asyncio.Event] = {}
        self.waits: list[FlagWait] = []
        self.waiting: dict[str, str] = {}  # group -> "flag X" it waits for now
        self.zones: ZoneWaits | None = None  # the run's zones (their waits are kept in ``waits`` too)
        self.held: Callable[[], float] = lambda: 0.0  # run time some group was held at a breakpoint (engine/breakpoints.py)

    def waiting_for(self, group: str) -> str | None:
        """What ``group`` waits for now: "flag X", "zone Z" or None."""
        return self.waiting.get(group) or (self.zones.waiting.get(group) if self.zones is not None else None)

    def _event(self, name: str) -> asyncio.Event:
        return self._set.setdefault(name, asyncio.Event())

    def is_set(self, name: str) -> bool:
        return self._event(name).is_set()

    def names_set(self) -> tuple[str, ...]:
        """Every flag set so far in this run (an edited remainder is checked with them set)."""
        return tuple(sorted(name for name, event in self._set.items() if event.is_set()))

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
            held = self.held()  # a group held at a breakpoint meanwhile: the operator's time, not the wait's
            outcome = await until(self.clock, event, lambda: start + timeout + self.held() - held, self.stopped)
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


async def until(clock: Clock, event: asyncio.Event, deadline: Callable[[], float], stopped: Callable[[], bool]) -> str:
    """Wait for ``event``: "passed", "timeout" at ``deadline()`` (run time, looked at again on every poll) or
    "stopped" when ``stopped()``."""
    while not event.is_set():
        if stopped():
            return "stopped"
        left = deadline() - clock.now()
        if left <= _EPSILON:  # float sums never land on a deadline exactly: closer than this is reached
            return "timeout"
        try:
            await clock.wait_for(event.wait(), min(left, STOP_POLL))
        except asyncio.TimeoutError:
            continue
    return "passed"
