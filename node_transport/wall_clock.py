"""An operator's clock: wall time for the waits that are a person's, not the robot's.

Every robot duration goes through the run :class:`~node_transport.clock.Clock`, which may run
ten times faster than real time or, on a ``VirtualTimeLoop`` (``--speed max``), jump over every
idle wait.  An alarm waits for a person: ``alarm_timeout="300"`` means five minutes of the
operator's time whatever the robot's clock does.  A Clock of speed 1 on the same loop would not
do -- under a VirtualTimeLoop its timers jump too -- so the deadline lives outside the loop: a
thread sleeps on the real monotonic clock and wakes the loop through ``call_soon_threadsafe``
(the loop's self-pipe, which also wakes a virtual-time loop blocked in ``select``).

Tests inject :class:`ManualWallClock` and move it by hand, so nothing sleeps for real.
"""
from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from typing import Protocol


class WallTimer(Protocol):
    def cancel(self) -> None: ...


class WallClock(Protocol):
    """Monotonic wall seconds, and a callback at a wall deadline (from any thread)."""

    def now(self) -> float: ...

    def call_later(self, seconds: float, callback: Callable[[], None]) -> WallTimer: ...


class RealWallClock:
    """``time.monotonic`` and a daemon timer thread per deadline (alarms are rare and few)."""

    def now(self) -> float:
        return time.monotonic()

    def call_later(self, seconds: float, callback: Callable[[], None]) -> WallTimer:
        timer = threading.Timer(max(0.0, seconds), callback)
        timer.daemon = True  # an alarm left waiting must not keep the process alive
        timer.name = "alarm wall-clock deadline"
        timer.start()
        return timer


class ManualWallClock:
    """A wall clock a test moves by hand; due callbacks run in the caller's thread, in order."""

    def __init__(self) -> None:
        self._now = 0.0
        self._timers: list[_ManualTimer] = []

    def now(self) -> float:
        return self._now

    def call_later(self, seconds: float, callback: Callable[[], None]) -> WallTimer:
        timer = _ManualTimer(self._now + max(0.0, seconds), callback)
        self._timers.append(timer)
        return timer

    def advance(self, seconds: float) -> None:
        self._now += seconds
        due = sorted((t for t in self._timers if t.due <= self._now and not t.cancelled), key=lambda t: t.due)
        self._timers = [t for t in self._timers if t not in due and not t.cancelled]
        for timer in due:
            timer.callback()


class _ManualTimer:
    def __init__(self, due: float, callback: Callable[[], None]) -> None:
        self.due = due
        self.callback = callback
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


def wake_loop(loop: asyncio.AbstractEventLoop, callback: Callable[[], None]) -> Callable[[], None]:
    """A callback for :meth:`WallClock.call_later` that runs ``callback`` on ``loop``, from any thread.

    A loop closed in the meantime has ended the wait with it, so there is nothing to wake.
    """

    def wake() -> None:
        try:
            loop.call_soon_threadsafe(callback)
        except RuntimeError:  # the loop is closed: the run (and its alarm) is over
            pass

    return wake
