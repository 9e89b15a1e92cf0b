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

from execution_engine.clock import Clock
from execution_engine.transport.wire import BridgeFeedback, SmRequest, SyncMessage

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
    where: str
    error: str


Event = Union[OperatorSignal, RequestEvent, FeedbackEvent, SyncEvent, FaultEvent]


class EventQueue:
    """A FIFO of events with a front slot for events a state hands back unconsumed."""

    def __init__(self, clock: Clock, maxsize: int = 10_000) -> None:
        self._clock = clock
        self._queue: asyncio.Queue[Event] = asyncio.Queue(maxsize)
        self._front: deque[Event] = deque()

    def put(self, event: Event) -> None:
        """Enqueue; a full queue means the machine is wedged, which must not pass silently."""
        try:
            self._queue.put_nowait(event)
        except asyncio.QueueFull:
            raise RuntimeError(f"event queue full ({self._queue.maxsize}); dropped {event!r}") from None

    def put_back(self, event: Event) -> None:
        """Return an event to the front so the next state sees it first."""
        self._front.appendleft(event)

    async def get(self, timeout: float | None = None) -> Event | None:
        """The next event, or None after ``timeout`` run seconds (None: wait without bound)."""
        if self._front:
            return self._front.popleft()
        if not self._queue.empty():  # the common case: no timer, no task, no wait
            return self._queue.get_nowait()
        try:
            return await self._clock.wait_for(self._queue.get(), timeout)
        except asyncio.TimeoutError:
            return None

    def __len__(self) -> int:
        return len(self._front) + self._queue.qsize()
