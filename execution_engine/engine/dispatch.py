"""A function the engine sent to a group and has no result of yet, and the end of a run that cannot go on.

Shared by the engine's two ways of running an application, operation by operation (engine/engine.py)
and each group on its own (``sync="flags"``, engine/flags_mode.py), and by a resumed run's first
operation (checkpoint/resume.py), which all end a run by raising :class:`ApplicationAborted`.
"""
from __future__ import annotations

import asyncio
from collections.abc import Iterable
from dataclasses import dataclass

from execution_engine.app_model.model import Call
from node_transport.clock import Clock
from node_transport.wire import SmRequest, SmResult


@dataclass
class Dispatch:
    """A function sent to a group and not yet answered."""

    call: Call
    request: SmRequest
    future: asyncio.Future[SmResult]
    deadline: float
    wakes: bool = False  # its future's resolver calls the engine's ResultWaiter itself (a GroupLink)


class ResultWaiter:
    """The engine's wait for the first result of the functions it dispatched: one future.

    ``asyncio.wait`` costs two turns of the loop per result (the result's done-callback runs on one
    turn and wakes the waiting task on the next) and a callback per waited future; a group link
    calls this waiter when it resolves a result (:meth:`wake`), so the engine is woken on the next
    turn, and only the futures resolved by others (the engine's own flag functions) get a callback."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self._waiters: list[asyncio.Future[None]] = []  # one per wait under way (the engine has one at a time)

    def wake(self, _: object = None) -> None:
        for waiter in self._waiters:
            if not waiter.done():
                waiter.set_result(None)

    async def first(self, dispatches: Iterable[Dispatch], timeout: float) -> list[Dispatch]:
        """The dispatches answered (in the order given), waiting up to ``timeout`` run seconds for
        one if none is yet; empty after the timeout."""
        dispatches = list(dispatches)
        done = [d for d in dispatches if d.future.done()]
        if done:
            return done
        waiter: asyncio.Future[None] = self.clock.loop.create_future()
        self._waiters.append(waiter)
        timer = self.clock.call_later(timeout, _expire, waiter)
        others = [d.future for d in dispatches if not d.wakes]
        for future in others:
            future.add_done_callback(self.wake)
        try:
            await waiter
        finally:
            timer.cancel()
            for future in others:
                future.remove_done_callback(self.wake)
            self._waiters.remove(waiter)
        return [d for d in dispatches if d.future.done()]


def _expire(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)  # woken with nothing answered: the caller sees the timeout


class ApplicationAborted(Exception):
    """The run cannot go on (policy exhausted, operator stop); the report says why."""
