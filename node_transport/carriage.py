"""Typed topics as the nodes use them: publish a wire dataclass, receive a validated one.

Over rclpy and DDS a wire dataclass (:mod:`node_transport.wire`) travels as its typed message
(:func:`typed.to_msg`) and the receiver checks it back into the dataclass (:func:`typed.from_msg`).
In one process that was four conversions per hop for nothing, so on the local transport a message
crosses once: the publisher checks at publish that the object is exactly what the receiver would
decode from its message -- every field of the type decoding gives (:mod:`node_transport.exact`),
within the decoder's limits, and a fixed point of the typed mapping (an optional text is never
``""``, an index never ``-1``: the message says those for None) -- and then hands the object itself
to each receiver that takes objects, a copy of its dicts and lists for each (the dataclasses are
frozen, so nothing else can change under a receiver).  Receivers thus get the same types, values
and guarantees as off the wire (run times exactly, where the wire rounds them to a nanosecond).
An object the check cannot vouch for, and any typed message from a publisher of another kind (a
recorder's replay, a test, another transport), takes the usual way and is validated, or refused
naming the topic, type and field, by the receiver as before.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar

from node_transport import codec, typed
from node_transport.exact import Walk, copier, exact
from node_transport.local import LocalNode, LocalPublisher
from node_transport.port import Node, Publisher, Subscription, TransportError
from node_transport.qos import COMMANDS, QoS
from node_transport.wire import (
    PROTOCOL_VERSION,
    BridgeCommand,
    BridgeFeedback,
    EngineEvent,
    EngineStatus,
    SmRequest,
    SmResult,
    SmStatus,
    SmStructure,
    SyncMessage,
)

W = TypeVar("W")


def _texts(*values: str | None) -> bool:
    """Each optional text None or not empty: the message says ``""`` for None, so ``""`` comes back None."""
    return "" not in values


def _sequences(*values: Any) -> bool:
    return all(len(v) <= typed.MAX_SEQUENCE_ITEMS for v in values)


def _event(e: EngineEvent) -> bool:
    accepted = type(e.accepted) is bool if e.event == "operator" else e.accepted is None  # the message's bool means it only then
    return accepted and _texts(e.operation, e.from_state, e.command, e.source, e.answer)


def _engine_status(s: EngineStatus) -> bool:
    return _texts(s.operation_id) and _sequences(s.groups) and all(_texts(p.operation, p.function) for p in s.groups.values())


#: the typed mapping's fixed points, per wire class carried as an object (run after the exact check,
#: so every field has its type); the cell model and the located frames, latched and rare, travel as messages
RULES: dict[type, Callable[[Any], bool]] = {
    SmRequest: lambda r: _sequences(r.params, r.partners),
    SmResult: lambda r: _texts(r.error),
    SmStatus: lambda s: s.index != -1 and s.count != -1 and _texts(
        s.from_state, s.to_state, s.signal, s.operation, s.function, s.request_id, s.primitive, s.outcome, s.error
    ),
    SmStructure: lambda s: _sequences(s.states, s.transitions),
    BridgeCommand: lambda c: True,
    BridgeFeedback: lambda f: _texts(f.error),
    SyncMessage: lambda s: _texts(s.error),
    EngineStatus: _engine_status,
    EngineEvent: _event,
}


def carriable(obj: Any) -> Walk | None:
    """The exact check's walk when ``obj`` may cross in process as itself, else None."""
    rule = RULES.get(type(obj))
    if rule is None:
        return None
    walk = exact(type(obj), obj)
    if walk is None or obj.v != PROTOCOL_VERSION or not rule(obj):  # v does not travel: it arrives as 1
        return None
    return walk


class TypedPublisher(Publisher[W], Generic[W]):
    """Publishes the wire dataclass ``wire_cls`` on its typed message's topic (see the module's doc)."""

    def __init__(self, node: Node, wire_cls: type[W], topic: str, qos: QoS = COMMANDS) -> None:
        self.wire_cls = wire_cls
        self.port: Publisher[Any] = node.create_publisher(typed.msg_type(wire_cls), topic, qos)
        self.topic = self.port.topic
        self.msg_type = self.port.msg_type
        self.clock = node.clock
        self._local = self.port if isinstance(self.port, LocalPublisher) and wire_cls in RULES else None
        self._copy = copier(wire_cls)

    def publish(self, obj: W) -> None:
        if type(obj) is not self.wire_cls:
            raise TransportError(f"publisher on {self.topic} carries {self.wire_cls.__name__}, got {type(obj).__name__}")
        local = self._local
        if local is not None:
            walk = carriable(obj)
            if walk is not None:
                local.publish_object(obj, self._to_msg, self._copy if walk.mutable else None)
                return
        self.port.publish(typed.to_msg(obj, self.clock))

    def _to_msg(self, obj: W) -> Any:
        return typed.to_msg(obj, self.clock)

    def get_subscription_count(self) -> int:
        return self.port.get_subscription_count()


def subscribe(
    node: Node,
    wire_cls: type[W],
    topic: str,
    take: Callable[[W], None],
    refuse: Callable[[codec.WireError], None],
    qos: QoS = COMMANDS,
    *,
    hand_over: bool = False,
) -> Subscription[Any]:
    """Receive ``wire_cls`` on ``topic``: ``take`` gets each valid one, ``refuse`` the error of each
    message out of contract (naming the topic, the ROS type and the field).  ``hand_over``: ``take``
    and ``refuse`` only hand on to the node's own queue or futures, so on the local transport they
    may run inside the sender's publish (:mod:`node_transport.local`); other transports ignore it."""
    source = node.resolve(topic)
    clock = node.clock
    msg_type = typed.msg_type(wire_cls)

    def receive(item: Any) -> None:
        if type(item) is wire_cls:  # carried in process: checked exact when it was published
            take(item)
            return
        try:
            obj = typed.from_msg(wire_cls, item, clock, source=source)
        except codec.WireError as error:
            refuse(error)
            return
        take(obj)

    if isinstance(node, LocalNode):
        return node.create_subscription(msg_type, topic, receive, qos, objects=wire_cls if wire_cls in RULES else None, hand_over=hand_over)
    return node.create_subscription(msg_type, topic, receive, qos)
