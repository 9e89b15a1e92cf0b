"""The one injectable clock every duration in the project goes through.

Robot applications run for minutes of robot time, yet tests must run them in milliseconds and
deterministically, and an operator may want to watch a simulation at 10x.  So nothing in the
project calls ``time.sleep``, ``time.monotonic`` or ``asyncio.sleep`` directly: it asks a
:class:`Clock`.  Three kinds exist:

* :func:`real_clock` -- wall time, for real controllers;
* :func:`scaled_clock` -- wall time multiplied by a speed factor (the simulator at 10x or 100x);
* :func:`simulated_clock` -- virtual time on a :class:`VirtualTimeLoop`: whenever every task is
  waiting for a timer, time jumps straight to the next timer.  Runs are deterministic and take
  no wall time for waiting.

All three are the same :class:`Clock` class; what differs is the event loop they run on and the
speed factor.  A fourth, :class:`FollowingClock`, takes its time from outside the process (a
simulator's ``/clock`` on a ROS node with ``use_sim_time``).  "Run time" is seconds since the clock was started, so traces of real, scaled and
simulated runs read the same.
"""
from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import math
import selectors
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine, Iterator, Mapping
from typing import Any, TypeVar

T = TypeVar("T")

__all__ = [
    "Clock",
    "FollowingClock",
    "VirtualTimeLoop",
    "real_clock",
    "run_with_clock",
    "scaled_clock",
    "simulated_clock",
]


class Clock:
    """Run time in seconds, sleeps and timeouts, all scaled by ``speed``.

    The clock binds to the event loop it is first used on; ``now()`` may be read from any thread
    (a logging thread, the rclpy executor) because it only reads the loop's monotonic time.
    """

    def __init__(self, speed: float = 1.0, *, simulated: bool = False, epoch: float | None = None) -> None:
        if not (speed > 0 and math.isfinite(speed)):
            raise ValueError(f"clock speed must be a positive finite factor, got {speed!r}")
        if epoch is not None and not (math.isfinite(epoch) and epoch >= 0):
            raise ValueError(f"clock epoch must be a finite time since 1970 in seconds, got {epoch!r}")
        self._speed = float(speed)
        self._simulated = simulated
        self._loop: asyncio.AbstractEventLoop | None = None
        self._origin = 0.0
        self._epoch = epoch
        self._lock = threading.Lock()

    # ----------------------------------------------------------------------------- binding
    @property
    def speed(self) -> float:
        """Run seconds per wall second (1.0 real time); meaningless for a simulated clock."""
        return self._speed

    @property
    def simulated(self) -> bool:
        """True when time is virtual: waiting costs no wall time."""
        return self._simulated

    def bind(self, loop: asyncio.AbstractEventLoop | None = None) -> Clock:
        """Tie the clock to ``loop`` (default: the running loop) and start run time at 0."""
        loop = loop or asyncio.get_running_loop()
        with self._lock:
            if self._loop is not None and self._loop is not loop:
                raise RuntimeError("a Clock serves one event loop; create another Clock for another loop")
            if self._loop is None:
                if self._simulated and not isinstance(loop, VirtualTimeLoop):
                    raise RuntimeError("a simulated clock needs a VirtualTimeLoop; use run_with_clock()")
                self._loop = loop
                self._origin = loop.time()
                if self._epoch is None:
                    self._epoch = time.time()
        return self

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            self.bind()
        assert self._loop is not None
        return self._loop

    # ------------------------------------------------------------------------------- time
    def now(self) -> float:
        """Seconds of run time since the clock was bound."""
        loop = self._loop
        if loop is None:
            return 0.0
        return (loop.time() - self._origin) * self._speed

    @property
    def epoch(self) -> float:
        """Seconds since 1970 (UTC) at run time 0: the wall time when the clock was bound, unless given."""
        return self._epoch if self._epoch is not None else 0.0

    def epoch_now(self) -> float:
        """Run time as seconds since 1970: what stamps of messages carry when no ROS clock is at hand.

        A scaled or simulated clock starts at the wall time it was bound at and then runs at its
        own rate, like a simulator's ``/clock``.
        """
        return self.epoch + self.now()

    def to_wall(self, run_seconds: float) -> float:
        """Wall (loop) seconds that ``run_seconds`` of run time take."""
        return max(0.0, run_seconds) / self._speed

    async def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` of run time (0 or less just yields to other tasks)."""
        self.loop  # noqa: B018 - binds on first use
        await asyncio.sleep(self.to_wall(seconds))

    async def sleep_until(self, run_time: float) -> None:
        """Sleep until run time ``run_time``; returns at once if it has passed."""
        await self.sleep(run_time - self.now())

    async def wait_for(self, awaitable: Awaitable[T], timeout: float | None) -> T:
        """``asyncio.wait_for`` with the timeout in run seconds (None waits without bound)."""
        self.loop  # noqa: B018
        if timeout is None:
            return await awaitable
        return await asyncio.wait_for(awaitable, self.to_wall(timeout))

    def call_later(self, delay: float, callback: Callable[..., Any], *args: Any) -> asyncio.TimerHandle:
        """Schedule ``callback`` after ``delay`` run seconds on the clock's loop."""
        return self.loop.call_later(self.to_wall(delay), callback, *args)

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        """While a person is being waited for, simulated time stands still.

        Under a simulated clock the periodic tasks of a cell (state publishing, diagnostics)
        would otherwise make time race ahead, burning a core and hours of robot time while an
        alarm waits for an operator.  Inside ``held()`` the loop waits for real events only
        (a key, a service call, a wall-clock timer) and run time does not advance; real and
        scaled clocks are not affected.  Use it only where nothing but the outside world can move the
        run on: a person, or work done outside the loop that the run waits for (a recording being
        finished in its writer threads).
        """
        loop = self._loop
        if not isinstance(loop, VirtualTimeLoop):
            yield
            return
        loop.holds += 1
        try:
            yield
        finally:
            loop.holds -= 1

    def __repr__(self) -> str:
        kind = "simulated" if self._simulated else f"x{self._speed:g}"
        return f"Clock({kind}, now={self.now():.3f})"


class _SourceTimer:
    """A callback due at a run time of a :class:`FollowingClock`; ``cancel()`` like asyncio's handles."""

    __slots__ = ("due", "order", "callback", "args", "cancelled")

    def __init__(self, due: float, order: int, callback: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self.due, self.order, self.callback, self.args, self.cancelled = due, order, callback, args, False

    def __lt__(self, other: _SourceTimer) -> bool:
        return (self.due, self.order) < (other.due, other.order)

    def cancel(self) -> None:
        self.cancelled = True


class FollowingClock(Clock):
    """Run time taken from a time source outside the process: a simulator's ``/clock``.

    A ROS node with ``use_sim_time`` must measure every timeout and sleep in the simulator's
    time, or a run at ten times real time reports wall seconds and gives the robot a tenth of
    the time it was promised.  The source calls :meth:`advance_to` with its time (seconds since
    1970); run time 0 is its first tick, sleeps and timeouts fire when the source passes them.

    Nothing may wait forever on a source that stopped: when no tick came for ``stall_timeout``
    wall seconds while something waits, ``on_stall`` is told and every pending timer fires, so
    each wait ends in its own timeout and reports it.
    """

    def __init__(self, *, stall_timeout: float = 10.0, on_stall: Callable[[str], None] | None = None) -> None:
        super().__init__(1.0)
        if not (stall_timeout > 0 and math.isfinite(stall_timeout)):
            raise ValueError(f"stall_timeout must be a positive number of seconds, got {stall_timeout!r}")
        self.stall_timeout = stall_timeout
        self.on_stall = on_stall
        self._start: float | None = None  # source time at run time 0
        self._source = 0.0  # latest source time
        self._timers: list[_SourceTimer] = []
        self._order = itertools.count()
        self._last_tick_wall = 0.0
        self._rate = 1.0  # source seconds per wall second, measured between ticks
        self._watchdog: asyncio.TimerHandle | None = None
        self.stalls = 0

    @property
    def speed(self) -> float:
        """Source seconds per wall second, as measured between the last ticks."""
        return self._rate

    @property
    def epoch(self) -> float:
        return self._start if self._start is not None else 0.0

    def bind(self, loop: asyncio.AbstractEventLoop | None = None) -> Clock:
        first = self._loop is None
        super().bind(loop)
        if first:
            self._last_tick_wall = self.loop.time()  # silence before the first tick counts too
        return self

    @property
    def ticking(self) -> bool:
        """True once the source has given a time."""
        return self._start is not None

    def now(self) -> float:
        return 0.0 if self._start is None else self._source - self._start

    def epoch_now(self) -> float:
        return self._source

    def to_wall(self, run_seconds: float) -> float:
        return max(0.0, run_seconds) / self._rate

    def advance_to(self, source_seconds: float) -> None:
        """Loop thread: the source's time is now ``source_seconds``; due timers fire.  A time
        earlier than the last one (a source restarted) is ignored: run time never goes back."""
        if not math.isfinite(source_seconds):
            return
        wall = self.loop.time()
        if self._start is None:
            self._start = self._source = source_seconds
        elif source_seconds > self._source:
            elapsed = wall - self._last_tick_wall
            if elapsed > 1e-3:
                self._rate = max(1e-3, (source_seconds - self._source) / elapsed)
            self._source = source_seconds
        self._last_tick_wall = wall
        self._fire(lambda timer: timer.due <= self.now())

    def call_later(self, delay: float, callback: Callable[..., Any], *args: Any) -> asyncio.TimerHandle:
        """Run ``callback`` on the loop once the source has advanced ``delay`` run seconds."""
        timer = _SourceTimer(self.now() + max(0.0, delay), next(self._order), callback, args)
        if delay <= 0 and self._start is not None:
            self.loop.call_soon(callback, *args)
            return timer  # type: ignore[return-value] - same cancel() protocol
        heapq.heappush(self._timers, timer)
        self._arm_watchdog()
        return timer  # type: ignore[return-value]

    async def sleep(self, seconds: float) -> None:
        if seconds <= 0:
            await asyncio.sleep(0)
            return
        waiter: asyncio.Future[None] = self.loop.create_future()
        timer = self.call_later(seconds, _resolve, waiter)
        try:
            await waiter
        finally:
            timer.cancel()

    async def wait_for(self, awaitable: Awaitable[T], timeout: float | None) -> T:
        if timeout is None:
            return await awaitable
        task = asyncio.ensure_future(awaitable)
        expired = False

        def expire() -> None:
            nonlocal expired
            if not task.done():
                expired = True
                task.cancel()

        timer = self.call_later(timeout, expire)
        try:
            return await task
        except asyncio.CancelledError:
            if expired:
                raise asyncio.TimeoutError() from None
            raise
        finally:
            timer.cancel()

    def _fire(self, due: Callable[[_SourceTimer], bool]) -> None:
        while self._timers and (self._timers[0].cancelled or due(self._timers[0])):
            timer = heapq.heappop(self._timers)
            if not timer.cancelled:
                self.loop.call_soon(timer.callback, *timer.args)

    def _arm_watchdog(self) -> None:
        if self._watchdog is None:
            self._watchdog = self.loop.call_later(self.stall_timeout / 2, self._check_stall)

    def _check_stall(self) -> None:
        self._watchdog = None
        self._timers = [t for t in self._timers if not t.cancelled]
        heapq.heapify(self._timers)
        if not self._timers:
            return
        if self.loop.time() - self._last_tick_wall >= self.stall_timeout:
            self.stalls += 1
            if self.on_stall is not None:
                self.on_stall(f"no time from the clock source for {self.stall_timeout:g} s: pending waits end now")
            self._fire(lambda timer: True)
            return
        self._arm_watchdog()

    def __repr__(self) -> str:
        return f"FollowingClock(now={self.now():.3f}, x{self._rate:.3g})"


def _resolve(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


def real_clock() -> Clock:
    """Wall time, 1:1."""
    return Clock(1.0)


def scaled_clock(speed: float) -> Clock:
    """Wall time sped up (or slowed down) by ``speed``."""
    return Clock(speed)


def simulated_clock() -> Clock:
    """Virtual time that jumps over idle waits; must run on a :class:`VirtualTimeLoop`."""
    return Clock(1.0, simulated=True)


class _VirtualSelector(selectors.BaseSelector):
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
        self._real = selectors.DefaultSelector()
        self._loop = loop

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.modify(fileobj, events, data)

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

    def close(self) -> None:
        self._real.close()

    def get_key(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.get_key(fileobj)

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._real.get_map()


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio loop whose ``time()`` is virtual and jumps over idle waits."""

    def __init__(self) -> None:
        self._virtual_now = 0.0
        self.holds = 0  # Clock.held() depth: time stands still while positive
        super().__init__(_VirtualSelector(self))

    def time(self) -> float:
        return self._virtual_now

    def advance(self, seconds: float) -> None:
        """Move virtual time forward (never backward)."""
        if seconds > 0:
            self._virtual_now += seconds


def run_with_clock(main: Callable[[Clock], Coroutine[Any, Any, T]], clock: Clock) -> T:
    """Run ``main(clock)`` to completion on a fresh loop suited to ``clock``."""
    loop: asyncio.AbstractEventLoop = VirtualTimeLoop() if clock.simulated else asyncio.new_event_loop()
    try:
        asyncio.set_event_loop(loop)
        clock.bind(loop)
        return loop.run_until_complete(main(clock))
    finally:
        try:
            _cancel_pending(loop)
            loop.run_until_complete(loop.shutdown_asyncgens())
        finally:
            asyncio.set_event_loop(None)
            loop.close()


def _cancel_pending(loop: asyncio.AbstractEventLoop) -> None:
    pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
    for task in pending:
        task.cancel()
    if pending:
        loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
