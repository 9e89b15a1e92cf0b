"""The primitive a V+ back end has under way, and what the operator asked of it meanwhile.

AdeptServer cannot hold or abort a motion, so pause and stop are flags the back end reads when
the motion ends (pause: hold the result) or at once (stop: abandon the wait); ``changed`` wakes
whoever waits on them, ``finished`` tells ``stop`` and ``close`` that the primitive is over.
"""
from __future__ import annotations

import asyncio


class Job:
    """One primitive's pause/stop flags and the events around them."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.paused = False
        self.stopped = False
        self.changed = asyncio.Event()
        self.finished: asyncio.Future[None] = loop.create_future()

    def signal(self) -> None:
        self.changed.set()

    async def next_change(self) -> None:
        await self.changed.wait()
        self.changed.clear()
