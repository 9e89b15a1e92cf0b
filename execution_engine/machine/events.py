"""Everything that can happen to a group machine, as one ordered stream of events.

A state waits for "whatever comes next" -- the bridge finishing, an operator pausing, the
partner arm arriving at a barrier -- so all sources feed one queue and each state decides
what an event means *in that state*.  That keeps the order of events the order they arrived in,
makes unexpected events explicit (each state names what it ignores), and gives tests one place
to inject anything.
"""
from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass
from typing import Literal, Union

from node_transport.clock import Clock
from node_transport.wire import BridgeFeedback, FaultKind, SmRequest, SyncMessage

OperatorCommand = Literal["pause", "resume", "stop", "reset"]


@dataclass(frozen=True)
class OperatorSignal:
    command: OperatorCommand
    source: str  # the service or node that asked


@dataclass(frozen=True)
class RequestEvent:
    request: SmRequest


@dataclass(frozen=True)
class FeedbackEvent:
    feedback: BridgeFeedback


@dataclass(frozen=True)
class SyncEvent:
    message: SyncMessage


@dataclass(frozen=True)
class FaultEvent:
    """Something outside a state went wrong (garbage feedback, a defect in a callback)."""

    where: str
    error: str
    kind: FaultKind = FaultKind.INTERNAL


Event = Union[OperatorSignal, RequestEvent, FeedbackEvent, SyncEvent, FaultEvent]


class EventQueue:
    """A FIFO of events with a front slot for events a state hands back unconsumed.

    Built on a deque and one waiter future rather than ``asyncio.Queue`` + ``wait_for``: a
    machine waits on this queue several times per primitive, and a bounded wait here costs one
    timer instead of a task and a timer.
    """

    def __init__(self, clock: Clock, maxsize: int = 10_000) -> None:
        self._clock = clock
        self._maxsize = maxsize
        self._events: deque[Event] = deque()
        self._waiter: asyncio.Future[None] | None = None

    def put(self, event: Event) -> None:
        """Enqueue; a full queue means the machine is wedged, which must not pass silently."""
        if len(self._events) >= self._maxsize:
            raise RuntimeError(f"event queue full ({self._maxsize}); dropped {event!r}")
        self._events.append(event)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def put_back(self, event: Event) -> None:
        """Return an event to the front so the next state sees it first."""
        self._events.appendleft(event)

    def take_signal(self, command: OperatorCommand) -> OperatorSignal | None:
        """Remove and return the first queued operator ``command``, if any: a stop that came while a
        state waited for something else must still win over a primitive not sent yet."""
        for event in self._events:
            if isinstance(event, OperatorSignal) and event.command == command:
                self._events.remove(event)
                return event
        return None

    def pop(self) -> Event | None:
        """The next event if one is queued, else None (without waiting)."""
        return self._events.popleft() if self._events else None

    async def get(self, timeout: float | None = None) -> Event | None:
        """The next event, or None after ``timeout`` run seconds (None: wait without bound)."""
        if self._events:
            return self._events.popleft()
        if self._waiter is not None and not self._waiter.done():
            raise RuntimeError("two states wait on one machine's events at once")
        waiter = self._waiter = self._clock.loop.create_future()
        timer = None if timeout is None else self._clock.call_later(timeout, _expire, waiter)
        try:
            await waiter  # cancellation of the caller propagates; the timer resolves, never cancels
        finally:
            if timer is not None:
                timer.cancel()
            self._waiter = None
        return self._events.popleft() if self._events else None

    def __len__(self) -> int:
        return len(self._events)


def _expire(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)  # woken with nothing queued: the caller sees the timeout
