"""Interference zones at run time (``sync="flags"``): one group at a time in a zone, in application order.

Every call that works in a zone (a frame it names lies in the zone's box: app_model/zones.py) gets
its turn in the order the application lists the calls -- by operation, then by the robot's group
order within one -- so the order is the same in every run and ``validate`` can prove it free of
deadlocks together with the flags (app_model/flag_check.py).  A call waits before it is sent until
every earlier call in that zone has ended; it leaves the zone when it ends (a function working in
a zone leaves it before it ends, as the rivet skills do by moving aside; the dry run's collision
sweep checks that it really does).  Waits are kept and published like flag waits (kind ``zone``).
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from execution_engine.app_model.model import Application
from execution_engine.app_model.zones import call_zones
from execution_engine.clock import Clock
from execution_engine.engine.flags import FlagWait, until


class ZoneBoard:
    """The zones of one run: which calls work in each, in application order, and which have ended."""

    def __init__(
        self, app: Application, clock: Clock, publish: Callable[[str, str, str, str | None, str], None], waits: list[FlagWait],
        stopped: Callable[[], bool] = lambda: False,
    ) -> None:
        self.clock = clock
        self.stopped = stopped  # an operator stopped the run: the waits end
        self.publish = publish  # (group, zone, state, operation, kind)
        self.waits = waits
        self.order: dict[str, list[tuple[int, str]]] = {}
        self.calls: dict[tuple[int, str], tuple[str, ...]] = {}
        for index, operation in enumerate(app.operations):
            for group, call in operation.calls.items():
                zones = call_zones(app.cell, call.params) if app.cell is not None and not call.implicit else ()
                self.calls[(index, group)] = zones
                for zone in zones:
                    self.order.setdefault(zone, []).append((index, group))
        self.ended: set[tuple[int, str]] = set()
        self.waiting: dict[str, str] = {}
        self._changed = asyncio.Event()

    def _free(self, zone: str, key: tuple[int, str]) -> bool:
        earlier = self.order[zone][: self.order[zone].index(key)]
        return all(k in self.ended for k in earlier)

    async def enter(self, index: int, group: str, operation: str) -> None:
        """Wait until every earlier call in each zone of this call has ended (ApplicationAborted on a stop)."""
        from execution_engine.engine.engine import ApplicationAborted  # the engine imports the flags module
        key = (index, group)
        for zone in self.calls.get(key, ()):
            if self._free(zone, key):
                continue
            start = self.clock.now()
            self.waiting[group] = f"zone {zone}"
            self.publish(group, zone, "waiting", operation, "zone")
            outcome = "stopped"
            try:
                while not self._free(zone, key):
                    if self.stopped():
                        raise ApplicationAborted(f"{group} was stopped while waiting for zone {zone!r}")
                    self._changed.clear()
                    await until(self.clock, self._changed, math.inf, self.stopped)
                outcome = "passed"
            finally:
                self.waiting.pop(group, None)
                self.waits.append(FlagWait(group, operation, zone, start, self.clock.now(), outcome, kind="zone"))
                self.publish(group, zone, outcome, operation, "zone")

    def leave(self, index: int, group: str) -> None:
        self.ended.add((index, group))
        self._changed.set()
