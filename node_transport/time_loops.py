"""The event loops that carry simulated time: virtual (``--speed max``) and paced (``--speed 10``).

A simulated robot's time must not depend on how fast the computer is.  If it did, rendering a
camera image, finding a hole with OpenCV, encoding a recording or simply sharing two cores with
another program would all pass as robot time: at ten times real time, 0.3 s of rendering is 3 s
of the robot standing still, the cycle time comes out longer than the dry run's, and a 5 s
"bridge did not accept" bound is half a second of a busy computer.  So both loops count only the
time the loop spends *waiting with nothing to do*:

* :class:`VirtualTimeLoop` never waits: when every task waits for a timer, time jumps to it.
* :class:`PacedLoop` waits for real, so a scaled run can be watched, but only its idle waits
  count, and never past the timer it waits for.  Work done on the loop (a callback, a render,
  a detection) takes no time at all; a stall of the process (the kernel gave the core to
  someone else) while the loop waits moves time to the next timer at most; and something that
  arrived during that wait is handled before the timer fires, so an answer that did come is
  never beaten by its own timeout.  Unpaced (the default) it is a plain wall-clock loop, which
  a real controller needs: its timeouts are the controller's, in wall seconds.

On both, work the loop waits for in a worker thread (``run_in_executor``, ``asyncio.to_thread``)
holds time still until it is done, as does :meth:`node_transport.clock.Clock.held` (a person,
a file being finished).  While time is held the loop waits for real events only.

The wall clock a :class:`PacedLoop` reads is injectable, so tests can burn or stall "wall time"
without sleeping.
"""
from __future__ import annotations

import asyncio
import selectors
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Executor
from typing import Any, TypeVar

T = TypeVar("T")

__all__ = ["PacedLoop", "VirtualTimeLoop", "Wall"]

#: Monotonic wall seconds (``time.monotonic``, or a test's fake).
Wall = Callable[[], float]

#: How far short of the timer it waits for a paced wait ends when something arrived during it, in
#: loop seconds: far below any period of the project, far above the loop's clock resolution.
EVENT_LEAD = 1e-6
#: A paced wait that overran its timeout by up to this much (wall s) overran by the wait's own
#: granularity (epoll waits whole milliseconds) or a late wake-up (the cores are shared): the
#: overrun is carried and spent on the next waits instead of waiting again, so robot time keeps
#: pace with the wall clock without ever passing a timer.  A longer overrun is a stall of the
#: process and is not made up: after it the run goes on at its pace instead of racing.
CATCH_UP = 0.05


class _HeldExecutorWork:
    """``run_in_executor`` that holds the loop's time until the worker thread is done."""

    holds: int

    def _held_future(self, future: asyncio.Future[T]) -> asyncio.Future[T]:
        self.holds += 1
        future.add_done_callback(self._release)
        return future

    def _release(self, _future: asyncio.Future[Any]) -> None:
        self.holds -= 1


class _OwnSelector(selectors.BaseSelector):
    """The real selector behind a loop's own ``select``: everything but ``select`` is handed to it."""

    def __init__(self) -> None:
        self._real = selectors.DefaultSelector()

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.modify(fileobj, events, data)

    def close(self) -> None:
        self._real.close()

    def get_key(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.get_key(fileobj)

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._real.get_map()


class _VirtualSelector(_OwnSelector):
    """Selector that turns an idle wait into a jump of the loop's virtual time.

    asyncio computes how long it may block until the next timer and passes that to
    ``select``.  We poll the real file descriptors without blocking; if nothing is ready and a
    timer is pending, we advance virtual time to it instead of sleeping.  With no timer pending
    (``timeout is None``) only another thread or a socket can wake the loop, so we block for
    real.  Loopback sockets served by tasks of the same loop deliver data synchronously, so a
    TCP or UDP peer simulated in-process works under virtual time too.

    Loopback delivery is almost always synchronous, but the kernel may defer it under load; so
    when sockets other than the loop's own wake-up pipe are registered, an idle loop first waits
    ``io_grace`` wall seconds for late data before jumping.  Pure in-process runs pay nothing.
    """

    io_grace = 0.001

    def __init__(self, loop: VirtualTimeLoop) -> None:
        super().__init__()
        self._loop = loop

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = self._real.select(0)
        if ready:
            return ready
        if timeout is None or (self._loop.holds and timeout > 0):  # held: only the outside world moves on
            return self._real.select(None)
        if timeout > 0:
            if len(self._real.get_map()) > 1:
                ready = self._real.select(min(timeout, self.io_grace))
                if ready:
                    return ready
            self._loop.advance(timeout)
        return []


class VirtualTimeLoop(_HeldExecutorWork, asyncio.SelectorEventLoop):
    """An asyncio loop whose ``time()`` is virtual and jumps over idle waits."""

    def __init__(self) -> None:
        self._virtual_now = 0.0
        self.holds = 0  # Clock.held() depth and executor work pending: time stands still while positive
        super().__init__(_VirtualSelector(self))

    def time(self) -> float:
        return self._virtual_now

    def advance(self, seconds: float) -> None:
        """Move virtual time forward (never backward)."""
        if seconds > 0:
            self._virtual_now += seconds

    def run_in_executor(self, executor: Executor | None, func: Callable[..., T], *args: Any) -> asyncio.Future[T]:
        """No jump while a worker thread does what the loop waits for (a file closed, a name resolved)."""
        return self._held_future(super().run_in_executor(executor, func, *args))


class _PacedSelector(_OwnSelector):
    """The real selector, timing each idle wait of a paced loop: what it counts is the loop's time."""

    def __init__(self, loop: PacedLoop) -> None:
        super().__init__()
        self._loop = loop
        self._carried = 0.0  # wall seconds already waited past earlier timers (at most CATCH_UP)
        self._worked = 0.0  # wall seconds the loop worked since it last waited, not yet spent on a wait (at most CATCH_UP)
        self._since: float | None = None  # the wall time the last wait ended

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        loop = self._loop
        if not loop.paced:
            return self._real.select(timeout)
        ready = self._real.select(0)
        if ready or (timeout is not None and timeout <= 0):
            return ready
        if loop.holds > 0:  # nothing counts until the work is done or the person answered
            self._since = None
            return self._real.select(None)
        start = loop.wall()
        until = loop.held_until(start)
        if until is not None:  # a bounded hold: waiting for another process's answer, for a while
            self._since = None
            return self._real.select(until - start)
        if self._since is not None:
            self._worked = min(self._worked + max(0.0, start - self._since), CATCH_UP)
        if timeout is None:  # no timer: whatever wakes the loop, the wait was idle
            ready = self._real.select(None)
            end = loop.wall()
            loop.advance(max(0.0, end - start))
            self._carried = self._worked = 0.0
        elif self._carried >= timeout:  # waited for already, past an earlier timer
            self._carried -= timeout
            loop.advance(timeout)
            end = start
        else:
            need = timeout - self._carried
            # The work just done overlaps the wait, so robot time keeps pace with the wall clock, but for
            # half of it at most: whatever the loop waits for outside (a thread, another process) always
            # gets the other half for real.  Time itself still moves only here, and only to the timer.
            spent = min(self._worked, need / 2)
            self._worked -= spent
            ready = self._real.select(need - spent)
            end = loop.wall()
            waited = self._carried + spent + max(0.0, end - start)
            overrun = waited - timeout
            self._carried = overrun if 0.0 < overrun <= CATCH_UP else 0.0
            counted = min(waited, timeout)
            if ready and counted > timeout - EVENT_LEAD:
                counted = max(0.0, timeout - EVENT_LEAD)  # what arrived is handled before the timer is due
            loop.advance(counted)
        self._since = end
        return ready


class PacedLoop(_HeldExecutorWork, asyncio.SelectorEventLoop):
    """A wall-clock asyncio loop which, once paced, lets time pass only while it waits idle.

    Unpaced, ``time()`` is the wall clock.  :meth:`pace` (a scaled clock binding to the loop)
    freezes it where it is; from then on it advances only by the idle waits, each at most to the
    timer waited for.
    """

    def __init__(self, wall: Wall = time.monotonic) -> None:
        self.wall = wall
        self.paced = False
        self.holds = 0  # Clock.held() depth and executor work pending: time stands still while positive
        self._bounded: dict[object, float] = {}  # hold_for(): key -> wall time it ends at the latest
        self._now = 0.0
        super().__init__(_PacedSelector(self))

    def time(self) -> float:
        return self._now if self.paced else self.wall()

    def pace(self) -> None:
        """From now on only idle waits count (time goes on from where the wall clock is: no jump)."""
        if not self.paced:
            self._now = self.wall()
            self.paced = True

    def advance(self, seconds: float) -> None:
        """Selector: ``seconds`` of idle waiting pass as loop time."""
        if seconds > 0:
            self._now += seconds

    def hold_for(self, key: object, wall_seconds: float) -> None:
        """Paced: time stands still until :meth:`release` of ``key`` or ``wall_seconds`` from now, whichever
        comes first; unlike :attr:`holds`, a hold that nobody releases ends by itself.

        For work done in another process that the robot would not wait for in a cell on one loop
        (a machine choosing its next primitive): that work takes no robot time while it stays
        within the bound, and time goes on past the bound, so a peer that went quiet delays the
        simulation by the bound at most, never stops it.  Unpaced (a real controller) it is ignored.
        """
        if self.paced:
            self._bounded[key] = self.wall() + max(0.0, wall_seconds)

    def release(self, key: object) -> None:
        """End :meth:`hold_for`'s hold of ``key`` (no matter if it has ended by itself)."""
        self._bounded.pop(key, None)

    def held_until(self, wall_now: float) -> float | None:
        """The wall time the latest live bounded hold ends at; None when none is live (expired ones go)."""
        for key in [k for k, end in self._bounded.items() if end <= wall_now]:
            del self._bounded[key]
        return max(self._bounded.values(), default=None)

    def run_in_executor(self, executor: Executor | None, func: Callable[..., T], *args: Any) -> asyncio.Future[T]:
        """Paced: time stands still while a worker thread does what the loop waits for."""
        return self._held_future(super().run_in_executor(executor, func, *args))
