"""The one injectable clock every duration in the project goes through.

Robot applications run for minutes of robot time, yet tests must run them in milliseconds and
deterministically, and an operator may want to watch a simulation at 10x.  So nothing in the
project calls ``time.sleep``, ``time.monotonic`` or ``asyncio.sleep`` directly: it asks a
:class:`Clock`.  Three kinds exist:

* :func:`real_clock` -- wall time, for real controllers;
* :func:`scaled_clock` -- a simulated robot's time at a speed factor (10x, 100x) of the wall
  clock, on a :class:`~node_transport.time_loops.PacedLoop`: only the loop's idle waits count,
  so rendering, detecting, recording or a busy computer never pass as robot time;
* :func:`simulated_clock` -- virtual time on a :class:`VirtualTimeLoop`: whenever every task is
  waiting for a timer, time jumps straight to the next timer.  Runs are deterministic and take
  no wall time for waiting.

All three are the same :class:`Clock` class; what differs is the event loop they run on and the
speed factor (:mod:`node_transport.time_loops` says why time is counted as it is).  A fourth,
:class:`FollowingClock`, takes its time from outside the process (a simulator's ``/clock`` on a
ROS node with ``use_sim_time``).  "Run time" is seconds since the clock was started, so traces of
real, scaled and simulated runs read the same.

Speed factors lie in [:data:`MIN_SPEED`, :data:`MAX_SPEED`]; faster than that is ``max``
(simulated time), slower is not a simulation anyone can wait for.
"""
from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import math
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine, Iterator
from typing import Any, TypeVar

from core_functions.option_ranges import bounds
from node_transport.time_loops import PacedLoop, VirtualTimeLoop, Wall

T = TypeVar("T")

__all__ = [
    "Clock",
    "FollowingClock",
    "MAX_SPEED",
    "MIN_SPEED",
    "PacedLoop",
    "VirtualTimeLoop",
    "real_clock",
    "run_with_clock",
    "scaled_clock",
    "simulated_clock",
]


#: The slowest and fastest speed factor of a scaled clock: a hundredth of real time (an 88 s cycle
#: in two and a half hours) to a thousand times (a 10 ms control period is 10 us of waiting).
MIN_SPEED, MAX_SPEED = bounds("speed").lower, bounds("speed").upper


#: How close to due asyncio runs a timer without waiting (its loops' ``_clock_resolution``).
_TIMER_RESOLUTION = time.get_clock_info("monotonic").resolution


class Clock:
    """Run time in seconds, sleeps and timeouts, all scaled by ``speed``.

    The clock binds to the event loop it is first used on; ``now()`` may be read from any thread
    (a logging thread, the rclpy executor) because it only reads the loop's time.  A ``paced``
    clock (a simulated robot at a speed factor) needs a :class:`PacedLoop` and paces it: from
    then on the loop's time, and so every clock on it, counts only its idle waits.
    """

    def __init__(self, speed: float = 1.0, *, simulated: bool = False, paced: bool = False, epoch: float | None = None) -> None:
        if not (speed > 0 and math.isfinite(speed)):
            raise ValueError(f"clock speed must be a positive finite factor, got {speed!r}")
        if simulated and paced:
            raise ValueError("a clock is either simulated (virtual time) or paced by the wall clock, not both")
        if epoch is not None and not (math.isfinite(epoch) and epoch >= 0):
            raise ValueError(f"clock epoch must be a finite time since 1970 in seconds, got {epoch!r}")
        self._speed = float(speed)
        self._simulated = simulated
        self._paced = paced
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

    @property
    def paced(self) -> bool:
        """True for a simulated robot's time paced by the wall clock: only idle waits count."""
        return self._paced

    def bind(self, loop: asyncio.AbstractEventLoop | None = None) -> Clock:
        """Tie the clock to ``loop`` (default: the running loop) and start run time at 0."""
        loop = loop or asyncio.get_running_loop()
        with self._lock:
            if self._loop is not None and self._loop is not loop:
                raise RuntimeError("a Clock serves one event loop; create another Clock for another loop")
            if self._loop is None:
                if self._simulated and not isinstance(loop, VirtualTimeLoop):
                    raise RuntimeError("a simulated clock needs a VirtualTimeLoop; use run_with_clock()")
                if self._paced:
                    if not isinstance(loop, PacedLoop):
                        raise RuntimeError("a scaled clock needs a PacedLoop (its time counts idle waits only); use run_with_clock()")
                    loop.pace()
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
        """Sleep ``seconds`` of run time (0 or less just yields to other tasks).

        A positive sleep always lets time move on.  asyncio runs a timer due within its clock's
        resolution (``time.get_clock_info("monotonic").resolution``, 1 ns) at once, without waiting,
        and a simulated or paced loop's time moves only while it waits; so a shorter sleep -- at x1000
        a microsecond of run time -- would end at the instant it began, and a loop waiting for time to
        pass a mark (a motion's end) would wait at that instant for ever.  Such a sleep lasts the
        shortest wait the loop can tell apart instead (the float's own step counts too: a paced loop's
        time is the computer's uptime)."""
        loop = self.loop
        delay = self.to_wall(seconds)
        if delay > 0:
            now = loop.time()
            shortest = 2.0 * max(_TIMER_RESOLUTION, math.ulp(now))
            delay = max(delay, shortest)
        await asyncio.sleep(delay)

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
        (a key, a service call, a wall-clock timer) and run time does not advance, on a simulated
        or a paced (scaled) loop; a real clock is not affected.  Use it only where nothing but the
        outside world can move the run on: a person, or work done outside the loop that the run
        waits for (a recording being finished in its writer threads).  Work in a worker thread
        (``run_in_executor``) holds time by itself.
        """
        loop = self._loop
        if not (isinstance(loop, VirtualTimeLoop) or (isinstance(loop, PacedLoop) and loop.paced)):
            yield
            return
        loop.holds += 1
        try:
            yield
        finally:
            loop.holds -= 1

    def __repr__(self) -> str:
        kind = "simulated" if self._simulated else f"x{self._speed:g}{' paced' if self._paced else ''}"
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
    While the source is silent, time stands still: a simulator that stalls (a busy computer, a
    bridge holding its time while a machine answers) never makes a timeout here fire early.

    Nothing may wait forever on a source that stopped: when no tick came for ``stall_timeout``
    wall seconds while something waits (``first_tick_timeout`` before its first tick: a simulator
    still starting -- importing its models, building its scene -- has not stopped), ``on_stall`` is told (once per silence) and every pending
    timer fires, so each wait ends in its own timeout and reports it.  From then until the source
    ticks again the clock runs on the wall clock at the source's last rate, so a loop that waits
    again (a poll until a deadline) gets to its deadline instead of waiting in steps of the stall
    bound for ever; when the source is back, run time goes on from where it is (never back).
    """

    def __init__(
        self, *, stall_timeout: float = 10.0, on_stall: Callable[[str], None] | None = None, first_tick_timeout: float | None = None,
    ) -> None:
        super().__init__(1.0)
        first_tick_timeout = stall_timeout if first_tick_timeout is None else first_tick_timeout
        for name, value in (("stall_timeout", stall_timeout), ("first_tick_timeout", first_tick_timeout)):
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
        self.stall_timeout = stall_timeout
        self.first_tick_timeout = first_tick_timeout
        self.on_stall = on_stall
        self._start: float | None = None  # source time at run time 0 (moved on when a silence ends)
        self._source = 0.0  # latest source time
        self._timers: list[_SourceTimer] = []
        self._order = itertools.count()
        self._last_tick_wall = 0.0
        self._rate = 1.0  # source seconds per wall second, measured between ticks
        self._watchdog: asyncio.TimerHandle | None = None
        self._free: tuple[float, float, float] | None = None  # silent past the bound: (loop time, run time, epoch) it began at
        self._free_timer: asyncio.TimerHandle | None = None
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

    @property
    def stalled(self) -> bool:
        """True while the source has been silent past the stall bound (the clock runs on the wall clock)."""
        return self._free is not None

    def now(self) -> float:
        if self._free is not None:
            since, base, _ = self._free
            return base + max(0.0, self.loop.time() - since) * self._rate
        return 0.0 if self._start is None else self._source - self._start

    def epoch_now(self) -> float:
        if self._free is not None:
            _, base, epoch = self._free
            return epoch + self.now() - base
        return self._source

    def to_wall(self, run_seconds: float) -> float:
        return max(0.0, run_seconds) / self._rate

    def advance_to(self, source_seconds: float) -> None:
        """Loop thread: the source's time is now ``source_seconds``; due timers fire.  A time
        earlier than the last one (a source restarted) is ignored: run time never goes back."""
        if not math.isfinite(source_seconds):
            return
        wall = self.loop.time()
        if self._free is not None:  # back after a silence: on from the run time reached meanwhile
            self._start = source_seconds - self.now()
            self._source = source_seconds
            self._free = None
            if self._free_timer is not None:
                self._free_timer.cancel()
                self._free_timer = None
        elif self._start is None:
            self._start = self._source = source_seconds
        elif source_seconds > self._source:
            elapsed = wall - self._last_tick_wall
            if elapsed > 1e-3:
                self._rate = max(1e-3, (source_seconds - self._source) / elapsed)
            self._source = source_seconds
        self._last_tick_wall = wall
        self._fire(lambda timer: timer.due <= self.now())
        if self._timers:
            self._arm_watchdog()

    def call_later(self, delay: float, callback: Callable[..., Any], *args: Any) -> asyncio.TimerHandle:
        """Run ``callback`` on the loop once the source has advanced ``delay`` run seconds."""
        timer = _SourceTimer(self.now() + max(0.0, delay), next(self._order), callback, args)
        if delay <= 0 and (self._start is not None or self._free is not None):
            self.loop.call_soon(callback, *args)
            return timer  # type: ignore[return-value] - same cancel() protocol
        heapq.heappush(self._timers, timer)
        if self._free is not None:
            self._arm_free_timer()
        else:
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
            self._watchdog = self.loop.call_later(self._bound() / 2, self._check_stall)

    def _check_stall(self) -> None:
        self._watchdog = None
        if self._free is not None:
            return
        self._timers = [t for t in self._timers if not t.cancelled]
        heapq.heapify(self._timers)
        if not self._timers:
            return
        if self.loop.time() - self._last_tick_wall >= self._bound():
            self.stalls += 1
            if self.on_stall is not None:
                never = "" if self._start is not None else " (it never ticked)"
                self.on_stall(
                    f"no time from the clock source for {self._bound():g} s{never}: pending waits end now, "
                    f"and time runs on the wall clock at x{self._rate:.3g} until it ticks again"
                )
            self._fire(lambda timer: True)
            self._free = (self.loop.time(), self.now(), self._source if self._start is not None else time.time())
            return
        self._arm_watchdog()

    def _bound(self) -> float:
        """Wall seconds of silence that make a stall: longer before the source's first tick."""
        return self.stall_timeout if self._start is not None else self.first_tick_timeout

    def _arm_free_timer(self) -> None:
        """While silent past the bound: wake for the next timer on the wall clock."""
        if self._free_timer is not None:
            self._free_timer.cancel()
        self._free_timer = None
        while self._timers and self._timers[0].cancelled:
            heapq.heappop(self._timers)
        if self._timers:
            self._free_timer = self.loop.call_later(max(0.0, self._timers[0].due - self.now()) / self._rate, self._free_tick)

    def _free_tick(self) -> None:
        self._free_timer = None
        if self._free is not None:
            self._fire(lambda timer: timer.due <= self.now() + 1e-9)
            self._arm_free_timer()

    def __repr__(self) -> str:
        return f"FollowingClock(now={self.now():.3f}, x{self._rate:.3g}{', stalled' if self._free else ''})"


def _resolve(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


def real_clock() -> Clock:
    """Wall time, 1:1."""
    return Clock(1.0)


def scaled_clock(speed: float) -> Clock:
    """A simulated robot's time at ``speed`` times the wall clock, counting only idle waits.

    ``speed`` 1 is real time, wall seconds as they pass: a real controller can be driven on it.
    Any other factor is a simulation, paced by the wall clock (:class:`PacedLoop`): work the
    computer does (rendering, detection, recording, another program) is not robot time.
    """
    if not (MIN_SPEED <= speed <= MAX_SPEED):
        raise ValueError(f"speed must be in [{MIN_SPEED:g}, {MAX_SPEED:g}] (or simulated time: max), got {speed!r}")
    return Clock(speed) if speed == 1.0 else Clock(speed, paced=True)


def simulated_clock() -> Clock:
    """Virtual time that jumps over idle waits; must run on a :class:`VirtualTimeLoop`."""
    return Clock(1.0, simulated=True)


def run_with_clock(main: Callable[[Clock], Coroutine[Any, Any, T]], clock: Clock, *, wall: Wall = time.monotonic) -> T:
    """Run ``main(clock)`` to completion on a fresh loop suited to ``clock``.

    Every loop but a simulated clock's is a :class:`PacedLoop` on ``wall``: plain wall time until a
    scaled clock binds to it (a bridge node's simulator, say), paced from then on.
    """
    loop: asyncio.AbstractEventLoop = VirtualTimeLoop() if clock.simulated else PacedLoop(wall)
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
