"""The operator's speed override on a V+ controller: its monitor speed (``SPEED p MONITOR``), on a link of its own.

V+ scales every motion by the monitor speed, the one under way included, on its path -- what an operator
turns on the pendant.  The override goes to the controller as the ``monitor_speed`` skill over a second
connection: the first is busy with the motion's ``break`` until the arm arrives, and the monitor speed
must reach the controller while the arm moves (docs/vplus.md says what the controller's AdeptServer needs
for it).  While a motion is under way below 100 %, the calls waiting for its acks get the motion time the
override took from it (:meth:`VPlusClient.extend`), so a slowed or held motion is not taken for a
controller that stopped answering; the rest of the bounds stay as they were.

A value the controller did not take (no link, no ack) is kept as the problem of the next motion, which is
refused rather than run faster than the operator asked.
"""
from __future__ import annotations

import asyncio
import logging

from node_transport.clock import Clock
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import ConnectError, VPlusClient, VPlusError

log = logging.getLogger(__name__)

#: s between two extensions of the acks' deadline while a motion runs below 100 %.
STRETCH_PERIOD = 0.05


class MonitorSpeed:
    """Sends the monitor speed; stretches the deadline of the motion link's calls while it is below 100 %."""

    def __init__(self, clock: Clock, motion: VPlusClient, label: str) -> None:
        self.clock = clock
        self.motion = motion
        self.label = label
        self.link = VPlusClient(motion.host, motion.port, clock, timeout=motion.timeout, retries=motion.retries)
        self.rate = 1.0  # what the operator asked for
        self.sent = 1.0  # what the controller acknowledged
        self.problem: str | None = None  # why the last value did not reach the controller
        self._turn = asyncio.Lock()
        self._tasks: set[asyncio.Task[None]] = set()

    def set(self, rate: float) -> None:
        """Send ``rate`` (0..1) as the controller's monitor speed, after any value still on its way."""
        self.rate = rate
        task = asyncio.get_running_loop().create_task(self._send(rate), name=f"{self.label} monitor speed")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _send(self, rate: float) -> None:
        async with self._turn:
            if rate != self.rate:
                return  # a newer value follows
            try:
                if not self.link.connected:
                    await self.link.connect()
                await self.link.execute(codec.monitor_speed(round(rate * 100.0, 3)))
            except (ConnectError, VPlusError) as error:
                self.problem = f"{self.label}: the speed override {rate * 100.0:g} % did not reach the controller: {error}"
                log.error("%s", self.problem)
                return
            self.sent, self.problem = rate, None

    async def delivered(self) -> None:
        """Until every value asked for has reached the controller or failed (each send is bounded by the link's
        timeout): a motion goes out only once the controller has the operator's speed."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)

    async def stretching(self, work: asyncio.Future[object]) -> None:
        """While ``work`` (a motion's acks) is awaited: every period the controller spent below 100 %, its
        calls get the motion time it lost."""
        last = self.clock.now()
        while not work.done():
            try:
                await self.clock.wait_for(asyncio.shield(work), STRETCH_PERIOD)
            except asyncio.TimeoutError:
                pass
            except BaseException:  # noqa: BLE001 - the caller hears of the motion's failure itself
                return
            now = self.clock.now()
            lost = (now - last) * (1.0 - min(self.rate, self.sent))
            if lost > 0.0:
                self.motion.extend(lost)
            last = now

    async def close(self) -> None:
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self.link.close()
