"""What the cell's operators did without this station's page, in the station's audit log.

A cell is commanded from more places than the page: the terminal of ``run --interactive``, the engine's ROS
services and its ``speed_override`` parameter, another station on the graph, an action client's cancel, a light
curtain on ``cell/safety_stop``.  Whoever asks "who paused the cell at 10:42?" must find the answer in one log,
so every operator record of the run the station watches (its own run or a cell it is attached to) whose source
is not this page is appended here under that source as recorded -- ``who`` is ``terminal console (key 'p')``,
``service /execution_engine/pause``, ``parameter /execution_engine/speed_override`` -- with the engine's answer
and the run time.  The page's own commands are already audited by their routes, with the user, so they are left
out here once each: in the station's own run they carry the source ``studio``; on a ROS graph (where a Trigger
carries no caller) the route says beforehand which service it is about to call (:meth:`CellAudit.expect`) and the
record that call makes is taken as the page's.

The safety stop: the engine records the pause it makes when ``cell/safety_stop`` rises, whoever raised it
(``safety event`` of the ``cell``); a raise or a clear of the input itself -- the clear is no engine record -- is
seen on the topic (:func:`watch_safety`) and audited under the topic's name unless this station published it.
A paused run's remainder swapped by someone else (``edit paused run``, both digests) is audited too, and, for a
cell the station only watches, the run's end as the engine's state says it (the station's own run's end is
audited under whoever started it, :mod:`operator_station.run_audit`).

Everything arrives through the feed's taps, on the thread that appended the record, in the order the station
received the records; :class:`~operator_station.audit.AuditLog` is thread-safe.
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from execution_engine.engine.breakpoints import BREAKPOINT_SERVICE, RUN_TO_SERVICE
from node_transport.msgs import Bool
from node_transport.port import Node
from node_transport.qos import LATCHED
from node_transport.wire import SAFETY_STOP, engine_service
from operator_station.access import Who
from operator_station.audit import AuditLog, hex_digest
from operator_station.feed import Feed

log = logging.getLogger(__name__)

#: The engine's states a run ends in.
ENDED = ("finished", "failed", "stopped")
#: Who the audit names for what the cell itself did (the pause the engine makes when the safety stop rises).
CELL = Who("engine", "", "the cell", "cell", "")
#: Who an entry names for a record that names no source (an engine of another version, say).
UNNAMED = "an unnamed source"
#: The pseudo-record a tap gets for each message on ``cell/safety_stop`` (never stored in the feed).
SAFETY_INPUT = "safety_stop_input"
#: Wall seconds a command the page is about to give through a service is waited for in the records: the
#: service's answer bound (operator_station.attach.SERVICE_TIMEOUT, 10 s) and some.
EXPECT_FOR = 15.0
#: The audit's name for an operator record's command, where it differs (the page's routes use these).
WHAT = {"start": "run start", "speed_override": "speed override", "break": "breakpoint set", "unbreak": "breakpoint clear",
        "unbreak_all": "breakpoint clear_all", "run_to": "run to"}
#: The service that carries each command of the page on a ROS graph (the base of the source the engine records).
SERVICE = {"breakpoint": BREAKPOINT_SERVICE, "run_to": RUN_TO_SERVICE}


def service_of(command: str) -> str:
    """The last part of the service name the engine records for the page's ``command`` on a graph."""
    return SERVICE.get(command, engine_service(command)).rsplit("/", 1)[-1]


@dataclass
class CellAudit:
    """Tapped into a station's feed: audits each outside operator command and safety stop change once."""

    audit: Callable[[], AuditLog]  # the station's log, looked up at each entry (a test may replace it)
    own: str  # the source the station's own run records the page's commands under (operator_station.session.SOURCE)
    wall: Callable[[], float] = time.time
    ends: bool = False  # audit a run's end from the engine's state (a cell the station only watches: nobody else does)
    _expected: list[tuple[str, float]] = field(default_factory=list)  # (service, wall deadline) the page is calling
    _published: list[tuple[str, float]] = field(default_factory=list)  # (safety stop value, deadline) published, not yet heard
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def attach(self, feed: Feed) -> None:
        feed.taps.append(self.see)

    # ------------------------------------------------------------------ the page's own, said beforehand
    def expect(self, command: str) -> None:
        """The page is about to give ``command`` through the engine's service (a call that never reaches the engine
        is forgotten after :data:`EXPECT_FOR` s, so it cannot hide someone else's call for long)."""
        with self._lock:
            self._expected.append((service_of(command), self.wall() + EXPECT_FOR))

    def publishing(self, active: bool) -> Callable[[], None]:
        """This station is about to publish ``active`` on ``cell/safety_stop``; the undo (it did not)."""
        entry = (str(active), self.wall() + EXPECT_FOR)
        with self._lock:
            self._published.append(entry)

        def undo() -> None:
            with self._lock:
                if entry in self._published:
                    self._published.remove(entry)

        return undo

    def _take(self, said: list[tuple[str, float]], key: str) -> bool:
        """Whether ``key`` was said beforehand (and not too long ago): the first such is taken."""
        now = self.wall()
        with self._lock:
            said[:] = [(k, due) for k, due in said if due >= now]
            for entry in said:
                if entry[0] == key:
                    said.remove(entry)
                    return True
        return False

    # ------------------------------------------------------------------ the records
    def see(self, record: dict[str, Any]) -> None:
        """A record of the run as the feed gets it (or a safety stop input message)."""
        try:
            if record.get("event") == SAFETY_INPUT:
                self._safety_input(record)
            elif record.get("event") == "operator":
                self._operator(record)
            elif record.get("event") == "swap" and not self.mine(str(record.get("source", ""))):
                self._swap(record)
            elif self.ends and record.get("event") == "engine_state" and record.get("to") in ENDED:
                self.audit().append(CELL, "run end", ok=record.get("to") == "finished", answer=str(record.get("to")),
                                    details={"t": record.get("t"), "message": record.get("message", "")})
        except Exception:  # noqa: BLE001 - the run's thread must go on; the failure is said
            log.exception("studio: a record could not be audited")

    def _operator(self, record: dict[str, Any]) -> None:
        source, command = str(record.get("source", "")), str(record.get("command", ""))
        accepted, answer = bool(record.get("accepted", True)), str(record.get("answer", ""))
        details = {"t": record.get("t"), "source": source, "command": command}
        if record.get("operation"):
            details["operation"] = record["operation"]
        for key in ("target", "percent"):  # the operation a breakpoint or run-to names; a speed override's new value
            if record.get(key) is not None:
                details[key] = record[key]
        if source.startswith("safety stop"):  # the engine obeying the cell's safety stop, whoever raised it
            self.audit().append(CELL, "safety event", ok=accepted, answer=f"{command} by {source}", details={"t": record.get("t")})
            return
        if self.mine(source) or (source.startswith("service ") and self._take(self._expected, source.rsplit("/", 1)[-1])):
            return  # the page's: its route audits it, with the user
        who = Who("cell", "", "", source or UNNAMED, "")
        self.audit().append(who, WHAT.get(command, command) or "operator command", ok=accepted, answer=answer, details=details)

    def _swap(self, record: dict[str, Any]) -> None:
        """A paused run's remainder edited by someone else than this page (whose route audits its own)."""
        source = str(record.get("source", ""))
        before, after = (hex_digest(str(record[k])) if record.get(k) else None for k in ("from_digest", "to_digest"))
        self.audit().append(Who("cell", "", "", source or UNNAMED, ""), "edit paused run", answer=str(record.get("message", "")), before=before, after=after,
                            details={"t": record.get("t"), "source": source, "file": record.get("file"), "from_operation": record.get("from_operation")})

    def mine(self, source: str) -> bool:
        """Whether the station's own run recorded ``source`` for the page: ``studio``, or ``studio (anna)`` (an edit)."""
        return source == self.own or source.startswith(f"{self.own} (")

    def _safety_input(self, record: dict[str, Any]) -> None:
        active, topic = bool(record.get("active")), str(record.get("topic", SAFETY_STOP))
        if self._take(self._published, str(active)):
            return  # this station's own: its route audited it, with the user
        if record.get("changed") is False:
            return  # the same value again: nothing happened
        what = "safety stop raised" if active else "safety stop cleared"
        answer = ("seen on joining: the safety stop is active" if record.get("first") else f"{topic} went {'true' if active else 'false'}")
        self.audit().append(Who("cell", "", "", topic, ""), what, answer=answer, details={"source": topic})


def tell(feed: Feed, record: dict[str, Any]) -> None:
    """Give ``record`` to the feed's taps only (the pages and the trace never see it)."""
    for tap in list(feed.taps):
        tap(record)


def watch_safety(node: Node, feed: Feed) -> None:
    """Subscribe ``node`` to ``cell/safety_stop``: each message goes to the feed's taps, with whether it changed
    the value (the first one seen is a change only when it is a raise: the stop was active when the station came)."""
    last: list[bool] = []
    topic = node.resolve(SAFETY_STOP)

    def heard(msg: Bool) -> None:
        active = bool(msg.data)
        changed = (not last and active) or (bool(last) and last[0] != active)
        first = not last
        last[:] = [active]
        tell(feed, {"event": SAFETY_INPUT, "active": active, "changed": changed, "first": first, "topic": topic})

    node.create_subscription(Bool, SAFETY_STOP, heard, LATCHED)
