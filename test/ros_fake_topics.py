"""Publishers and subscriptions of the fake rclpy: delivery as DDS does it once discovery has matched a pair.

What the ros transport depends on: nothing reaches a reader before its match (a volatile message published
earlier is lost and recorded in ``GRAPH.lost``); a TRANSIENT_LOCAL reader gets its writer's history at the match;
only compatible QoS match; a KEEP_LAST reader keeps its last ``depth`` messages; every reader gets its own copy;
``get_subscription_count`` / ``get_publisher_count`` count matches only.
"""
from __future__ import annotations

import copy
from collections import deque
from collections.abc import Callable
from typing import Any

from ros_fake_args import InvalidHandle
from ros_fake_callbacks import Entity, Owner
from ros_fake_graph import GRAPH
from ros_fake_msgs import INTERFACE_MODULES
from ros_fake_qos import DurabilityPolicy, HistoryPolicy, QoSProfile, compatible


def ros_type_name(msg_type: type) -> str:
    """``std_msgs/msg/String`` for the fake String class (what rclpy's graph calls reports)."""
    for module, classes in INTERFACE_MODULES.items():
        for name, cls in classes.items():
            if cls is msg_type:
                return module.replace(".", "/") + "/" + name
    return "unknown/msg/Unknown"


class PublisherEventCallbacks:
    """rclpy.event_handler: ``use_default_callbacks`` adds rclpy's warning handlers (one waitable each)."""

    def __init__(self, *, use_default_callbacks: bool = True, **callbacks: Any) -> None:
        self.use_default_callbacks = use_default_callbacks
        self.callbacks = callbacks


class SubscriptionEventCallbacks(PublisherEventCallbacks):
    pass


class FakePublisher:
    def __init__(self, node: Owner, msg_type: type, topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic, self.qos = node, msg_type, topic, qos
        self.history: deque[Any] = deque(maxlen=qos.depth if qos.durability is DurabilityPolicy.TRANSIENT_LOCAL else 0)
        self.published: list[Any] = []
        self.destroyed = False

    def _readers(self) -> list[FakeSubscription]:
        with GRAPH.lock:
            return [s for s in GRAPH.subscriptions.get(self.topic, []) if GRAPH.is_matched(self, s) and compatible(self.qos, s.qos)]

    def get_subscription_count(self) -> int:
        return len(self._readers())

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"publisher on {self.topic} expects {self.msg_type.__name__}")
        if self.destroyed:
            raise InvalidHandle("cannot use Destroyable because destruction was requested")
        self.published.append(msg)
        with GRAPH.lock:
            self.history.append(msg)
            readers = self._readers()
            if len(readers) < len(GRAPH.subscriptions.get(self.topic, [])):
                GRAPH.lost.append((self.topic, msg))
        for sub in readers:
            sub.receive(copy.deepcopy(msg))


class FakeSubscription(Entity):
    def __init__(self, node: Owner, msg_type: type, topic: str, callback: Callable[[Any], None], qos: QoSProfile, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.msg_type, self.topic, self.callback, self.qos = msg_type, topic, callback, qos
        self.event_callbacks: Any = None

    def get_publisher_count(self) -> int:
        with GRAPH.lock:
            return sum(1 for p in GRAPH.publishers.get(self.topic, []) if GRAPH.is_matched(p, self) and compatible(p.qos, self.qos))

    def receive(self, msg: Any) -> None:
        if self.destroyed:
            return
        self.push(msg)
        if self.qos.history is HistoryPolicy.KEEP_LAST:
            while len(self.queue) > self.qos.depth:
                self.queue.popleft()

    def run(self, item: Any) -> None:
        self.callback(item)


def replay(pub: FakePublisher, sub: FakeSubscription) -> None:
    """At the match: a TRANSIENT_LOCAL reader gets the writer's history, as DDS delivers it."""
    if sub.qos.durability is DurabilityPolicy.TRANSIENT_LOCAL and compatible(pub.qos, sub.qos):
        with GRAPH.lock:
            history = list(pub.history)
        for msg in history:
            sub.receive(copy.deepcopy(msg))
