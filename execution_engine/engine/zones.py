"""Interference zones at run time, both modes: one group at a time in a zone, in application order.

The engine is the zones' arbiter; the group machines ask it (execution_engine/machine/zone_gate.py).
Before a motion that ends inside a zone's box, a machine announces itself on the coordination
topic (a :class:`SyncMessage` ``arrived`` with key ``zone:<zone>:<request id>``) and waits; the
engine answers ``done`` (granted, from group :data:`ENGINE`) once no other group is inside and
every earlier call in that zone -- earlier in application order: by operation, then the robot's
group order -- has left it or ended, so the order is the same in every run and ``validate`` can
prove it free of deadlocks together with the flags and the operations (app_model/flag_check.py).
The machine says ``left`` when a motion of it ends outside the box again; its call's successful
result ends its turn too (a lost ``left`` costs time, never safety).  A failed call keeps the
zone: its arm may still be inside, and a retry of the call is let in again at once.  Motions
that are not the application's (the stages of a safe pose) are let in at once.

A call that names no frame in the zone but moves into it anyway has no place in the order: it
is let in whenever nobody is inside.  Calls of synchronised functions are not gated: both arms
move as one.  Waits are kept and published like flag waits (kind ``zone``), and so is each
entering (``passed``) and leaving (``left``).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Application
from execution_engine.app_model.zones import ENGINE, call_zones, parse_key
from node_transport.clock import Clock
from execution_engine.engine.waits import FlagWait
from node_transport import codec, typed
from node_transport.port import Node
from node_transport.qos import COMMANDS
from node_transport.wire import SYNC_TOPIC, SyncMessage

Publish = Callable[..., None]  # (group, zone, state, operation, kind)
CallKey = tuple[str, str]  # (operation id, group)


@dataclass
class _Asking:
    """A group waiting to enter a zone."""

    zone: str
    call: CallKey
    key: str
    since: float


def zone_order(app: Application, catalog: Catalog) -> dict[str, list[CallKey]]:
    """Each zone's calls in application order (synchronised and engine functions have no place)."""
    order: dict[str, list[CallKey]] = {}
    if app.cell is None or not getattr(app.cell, "zones", None):
        return order
    for operation in app.operations:
        for group in app.robot.group_names:
            call = operation.calls.get(group)
            spec = catalog.get(call.function) if call is not None else None
            if call is None or call.implicit or (spec is not None and spec.sync):
                continue
            for zone in call_zones(app.cell, call.params):
                order.setdefault(zone, []).append((operation.id, group))
    return order


class ZoneBoard:
    """The zones of the engine's runs: the order, who is inside, who waits; grants on the coordination topic."""

    def __init__(self, node: Node, catalog: Catalog, publish: Publish) -> None:
        self.clock: Clock = node.clock
        self.catalog = catalog
        self.publish = publish
        self._pub = node.create_publisher(typed.SyncMsg, SYNC_TOPIC, COMMANDS)
        node.create_subscription(typed.SyncMsg, SYNC_TOPIC, self._on_sync, COMMANDS)
        self.order: dict[str, list[CallKey]] = {}
        self.waits: list[FlagWait] = []
        self.waiting: dict[str, str] = {}  # group -> "zone Z" it waits for now
        self.inside: dict[str, CallKey] = {}  # zone -> the call inside it
        self._done: dict[str, set[CallKey]] = {}  # zone -> calls that left it or ended
        self._calls: dict[str, CallKey] = {}  # request id -> its call
        self._asking: dict[str, _Asking] = {}  # key -> a request not granted yet
        self._granted: set[str] = set()
        self._operations: set[str] = set()

    def start(self, app: Application, waits: list[FlagWait], done_before: int = 0) -> None:
        """A new run: its order; calls before operation ``done_before`` ran in an earlier run."""
        self.order = zone_order(app, self.catalog)
        self.waits = waits
        self.waiting.clear()
        self.inside.clear()
        self._calls.clear()
        self._asking.clear()
        self._granted.clear()
        self._operations = {op.id for op in app.operations}
        earlier = {op.id for op in app.operations[:done_before]}
        self._done = {zone: {c for c in calls if c[0] in earlier} for zone, calls in self.order.items()}

    def swap(self, app: Application) -> None:
        """A paused run's remainder was edited (engine/remainder_swap.py): the new order, the calls done and held kept."""
        self.order = zone_order(app, self.catalog)
        self._operations = {op.id for op in app.operations}
        for zone in self.order:
            self._done.setdefault(zone, set())

    def register(self, request_id: str, operation: str, group: str) -> None:
        """The engine sent request ``request_id`` for call (``operation``, ``group``) of the application
        (the safe pose's stages are not: their motions are let in at once)."""
        if operation in self._operations:
            self._calls[request_id] = (operation, group)

    def ended(self, operation: str, group: str) -> None:
        """Call (``operation``, ``group``) succeeded: whatever it held, it left."""
        call = (operation, group)
        for zone, calls in self.order.items():
            if call in calls:
                self._done[zone].add(call)
        for zone in [z for z, c in self.inside.items() if c == call]:
            self._leave(zone, call)
        self._grant_waiting()

    def waited(self) -> dict[str, float]:
        """Seconds each group waited for zones in this run: inside its functions, so idle, not busy."""
        out: dict[str, float] = {}
        for wait in self.waits:
            if wait.kind == "zone":
                out[wait.group] = out.get(wait.group, 0.0) + wait.duration
        return out

    def close(self) -> None:
        """The run ended: waits still open end as stopped."""
        for asking in list(self._asking.values()):
            self._record(asking, "stopped")
        self._asking.clear()
        self.waiting.clear()

    # ------------------------------------------------------------------------ messages
    def _on_sync(self, msg: Any) -> None:
        try:
            message = typed.from_msg(SyncMessage, msg, self.clock, source="coordination")
        except codec.WireError:
            return  # the machines log what they cannot read; the engine only answers zone requests
        parsed = parse_key(message.key)
        if parsed is None or message.group == ENGINE:
            return
        zone, request_id = parsed
        call = self._calls.get(request_id)
        if call is None:  # not a call of the application (a safe-pose retreat, an earlier run's): not gated
            if message.event == "arrived":
                self._send(message.key)
            return
        if call[1] != message.group:
            return
        if message.event == "arrived":
            self._ask(zone, call, message.key)
        elif message.event == "left" and self.inside.get(zone) == call:
            self._granted.discard(message.key)  # coming back in is asked for again, behind whoever is inside then
            self._leave(zone, call)
            self._done.setdefault(zone, set()).add(call)
            self._grant_waiting()

    def _ask(self, zone: str, call: CallKey, key: str) -> None:
        if key in self._granted:
            self._send(key)  # the answer was lost: again
            return
        if self._free(zone, call):
            self._enter(zone, call, key)
            return
        if key not in self._asking:
            self._asking[key] = _Asking(zone, call, key, self.clock.now())
            self.waiting[call[1]] = f"zone {zone}"
            self.publish(call[1], zone, "waiting", call[0], "zone")

    def _free(self, zone: str, call: CallKey) -> bool:
        holder = self.inside.get(zone)
        if holder is not None and holder != call:
            return False
        order = self.order.get(zone, [])
        if call not in order:
            return True
        done = self._done.get(zone, set())
        return all(c in done for c in order[: order.index(call)])

    def _enter(self, zone: str, call: CallKey, key: str) -> None:
        fresh = self.inside.get(zone) != call
        self.inside[zone] = call
        self._granted.add(key)
        self._send(key)
        if fresh:
            self.publish(call[1], zone, "passed", call[0], "zone")

    def _leave(self, zone: str, call: CallKey) -> None:
        del self.inside[zone]
        self.publish(call[1], zone, "left", call[0], "zone")

    def _grant_waiting(self) -> None:
        for key, asking in sorted(self._asking.items(), key=lambda kv: self._rank(kv[1])):
            if self._free(asking.zone, asking.call):
                del self._asking[key]
                self._record(asking, "passed")
                self._enter(asking.zone, asking.call, key)

    def _rank(self, asking: _Asking) -> int:
        order = self.order.get(asking.zone, [])
        return order.index(asking.call) if asking.call in order else len(order)

    def _record(self, asking: _Asking, outcome: str) -> None:
        group = asking.call[1]
        self.waiting.pop(group, None)
        self.waits.append(FlagWait(group, asking.call[0], asking.zone, asking.since, self.clock.now(), outcome, kind="zone"))
        if outcome != "passed":
            self.publish(group, asking.zone, outcome, asking.call[0], "zone")

    def _send(self, key: str) -> None:
        message = SyncMessage(group=ENGINE, key=key, event="done", state="granted", t=self.clock.now())
        self._pub.publish(typed.to_msg(message, self.clock))
