"""The in-process transport: the embedded default and the deterministic test bed.

It keeps the semantics a ROS 2 deployment relies on, so nothing works here that would break
over DDS: delivery is asynchronous (never inside ``publish``; but see hand-over below), each subscription has its own
KEEP_LAST queue of ``depth`` that drops the oldest message, TRANSIENT_LOCAL publishers replay
their last ``depth`` messages to late subscribers, incompatible QoS pairs do not connect, and a
service call fails when nobody serves the name.  Message objects are frozen dataclasses, so they
are shared, not copied.

A message crosses once: a typed topic's wire dataclass (:mod:`node_transport.carriage`) is
handed over as the object itself (:meth:`LocalPublisher.publish_object`) to the subscriptions
that take objects (``create_subscription(..., objects=cls)``), with a copy of its dicts and lists
for each, as a receiver off the wire has its own; only subscriptions that want the typed message
(a recorder, a test, a latecomer on a latched topic) have it built, once per publish.

Hand-over subscriptions (``create_subscription(..., hand_over=True)``): a receiver whose callback
only hands the message on to its own node -- puts it on the node's event queue, resolves a
future its node awaits -- is called inside ``publish`` instead of a turn of the loop later, when
nothing is queued for it and it is not in its own callback (else the message queues behind the
others, as usual).  What the receiving node does with the message still happens in that node's
own task, so no node runs inside another's code; each subscription still receives in publish
order; and the order across topics is publish order, which is one of the orders DDS allows (it
orders nothing across topics; the engine, the machines and the bridges are written for any).
Per primitive that is six turns of the loop fewer.  A callback whose effect others can observe
at another moment (the engine's view of a machine's state, which its status reports at its own
events) stays a plain subscription: there the turn keeps the order each topic's observers see.  A replay to a late subscriber is always
queued, and hand-overs nest at most :data:`HAND_OVER_DEPTH` deep.
"""
from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Generic, TypeVar

from node_transport.clock import Clock
from node_transport.port import (
    Node,
    ParameterValue,
    Publisher,
    ServiceClient,
    ServiceServer,
    ServiceUnavailable,
    Subscription,
    TopicInfo,
    Transport,
    TransportError,
    unwrap_reply,
)
from node_transport.qos import COMMANDS, Durability, History, QoS

M = TypeVar("M")

#: hand-overs inside hand-overs (a bridge answering inside the machine's publish): past this depth messages queue
HAND_OVER_DEPTH = 4


class Carried:
    """One :meth:`LocalPublisher.publish_object`: the object, how a receiver gets its own copy of
    the object's dicts and lists (None: nothing in it can change), and its message, built from the
    object the first time a subscription wants it (a latched topic's latecomer, perhaps never)."""

    __slots__ = ("obj", "copy", "msg", "message", "publisher")

    def __init__(self, obj: Any, copy: Callable[[Any], Any] | None, message: Callable[[Any], Any], publisher: LocalPublisher[Any]) -> None:
        self.obj, self.copy, self.message, self.publisher = obj, copy, message, publisher
        self.msg: Any = None

    def item_for(self, objects: type | None) -> Any:
        """What a subscription that takes objects of class ``objects`` (None: messages) receives."""
        if objects is type(self.obj):
            return self.obj if self.copy is None else self.copy(self.obj)
        if self.msg is None:
            msg = self.message(self.obj)
            self.publisher.check_message(msg)
            self.msg = msg
        return self.msg


class LocalSubscription(Subscription[M], Generic[M]):
    def __init__(
        self,
        node: LocalNode,
        msg_type: type[M],
        topic: str,
        callback: Callable[[M], None],
        qos: QoS,
        objects: type | None = None,
        hand_over: bool = False,
    ) -> None:
        self.node = node
        self.msg_type = msg_type
        self.topic = topic
        self.qos = qos
        self.objects = objects  # the wire class it takes as objects; messages otherwise
        self.hand_over = hand_over  # called inside publish when nothing is queued (see the module's doc)
        self._callback = callback
        maxlen = None if qos.history is History.KEEP_ALL else qos.depth
        self._queue: deque[M] = deque(maxlen=maxlen)
        self._scheduled = False
        self._busy = False  # in its callback now
        self.alive = True

    def deliver(self, msg: M) -> None:
        """Queue ``msg``; the callback gets it on a later turn of the loop."""
        if not self.alive:
            return
        self._queue.append(msg)
        if not self._scheduled:
            self._scheduled = True
            self.node.bus.loop.call_soon(self._drain)

    def offer(self, msg: M) -> None:
        """A publish's delivery: handed over at once when this subscription takes hand-overs and
        nothing is queued for it or running in it, else queued (:meth:`deliver`)."""
        bus = self.node.bus
        if not self.hand_over or self._queue or self._busy or not self.alive or bus.hand_over_depth >= HAND_OVER_DEPTH or not bus.hand_overs:
            self.deliver(msg)
            return
        bus.hand_over_depth += 1
        self._busy = True
        try:
            self._callback(msg)
        except Exception as error:  # noqa: BLE001 - reported, never swallowed, as in a drain
            self.node.report_fault(f"subscription {self.topic}", error)
        finally:
            self._busy = False
            bus.hand_over_depth -= 1

    def _drain(self) -> None:
        self._scheduled = False
        self._busy = True
        try:
            while self._queue and self.alive:
                msg = self._queue.popleft()
                try:
                    self._callback(msg)
                except Exception as error:  # noqa: BLE001 - reported, never swallowed
                    self.node.report_fault(f"subscription {self.topic}", error)
        finally:
            self._busy = False

    def destroy(self) -> None:
        self.alive = False
        self._queue.clear()
        self.node.bus.remove_subscription(self)

    def get_publisher_count(self) -> int:
        return len(self.node.bus.matching_publishers(self)) if self.alive else 0

    def publisher_nodes(self) -> list[str]:
        return sorted({p.node.fully_qualified_name for p in self.node.bus.matching_publishers(self)}) if self.alive else []


class LocalPublisher(Publisher[M], Generic[M]):
    def __init__(self, node: LocalNode, msg_type: type[M], topic: str, qos: QoS):
        self.node = node
        self.msg_type = msg_type
        self.topic = topic
        self.qos = qos
        self.history: deque[M | Carried] = deque(maxlen=qos.depth if qos.durability is Durability.TRANSIENT_LOCAL else 0)
        self.alive = True

    def publish(self, msg: M) -> None:
        if not self.alive:
            raise TransportError(f"publisher on {self.topic} of {self.node.fully_qualified_name} was destroyed")
        self._check(msg)
        if self.qos.durability is Durability.TRANSIENT_LOCAL:
            self.history.append(msg)
        for sub in self.node.bus.matching_subscriptions(self):
            sub.offer(msg)

    def publish_object(self, obj: Any, message: Callable[[Any], M], copy: Callable[[Any], Any] | None) -> None:
        """Hand ``obj`` (checked by the caller: exactly what decoding its ``message(obj)`` would give)
        to the subscriptions that take its class, and its message -- built once, and only when a
        subscription wants it -- to the others.  The latched history keeps the object (its own copy
        when it holds dicts or lists the sender may change later): a latecomer that takes messages
        has the message built then, from what was published."""
        if not self.alive:
            raise TransportError(f"publisher on {self.topic} of {self.node.fully_qualified_name} was destroyed")
        subs = self.node.bus.matching_subscriptions(self)
        latched = self.qos.durability is Durability.TRANSIENT_LOCAL
        carried = Carried(obj if copy is None or not latched else copy(obj), copy, message, self)
        if latched:
            self.history.append(carried)
        for sub in subs:
            sub.offer(carried.item_for(sub.objects))

    def check_message(self, msg: M) -> None:
        """That ``msg`` is of this publisher's type (a carried object's message, once built)."""
        self._check(msg)

    def get_subscription_count(self) -> int:
        return len(self.node.bus.matching_subscriptions(self))


class _LocalService(ServiceServer):
    def __init__(self, node: LocalNode, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]):
        self.node = node
        self.srv_type = srv_type
        self.name = name
        self.handler = handler

    def destroy(self) -> None:
        self.node.bus.remove_service(self)


class _LocalClient(ServiceClient[Any, Any]):
    def __init__(self, node: LocalNode, srv_type: type, name: str):
        self.node = node
        self.srv_type = srv_type
        self.name = name

    async def wait_for_service(self, timeout: float) -> bool:
        deadline = self.node.clock.now() + timeout
        while self.node.bus.service(self.name) is None:
            if self.node.clock.now() >= deadline:
                return False
            await self.node.clock.sleep(min(0.05, max(0.0, deadline - self.node.clock.now())))
        return True

    async def call(self, request: Any, timeout: float = 5.0) -> Any:
        if type(request) is not self.srv_type.Request:
            raise TransportError(f"service {self.name} takes {self.srv_type.Request.__name__}, got {type(request).__name__}")
        server = self.node.bus.service(self.name)
        if server is None:
            raise ServiceUnavailable(f"no server for service {self.name}")
        if server.srv_type is not self.srv_type:
            raise TransportError(f"service {self.name} is {server.srv_type.__name__}, client expects {self.srv_type.__name__}")
        # The handler runs as its own task, like a server in another process: cancelling the
        # caller's wait (timeout) must not cancel the server's work half-way.
        task = self.node.bus.loop.create_task(server.handler(request), name=f"service {self.name}")
        try:
            answer = await self.node.clock.wait_for(asyncio.shield(task), timeout)
        except BaseException:  # the caller gave up; whatever the handler does after its answer still happens
            task.add_done_callback(lambda done: _follow_up_later(server, done))
            raise
        response, then = unwrap_reply(answer)
        if then is not None:  # after the caller has the response in hand, as the other transports do it
            self.node.bus.loop.call_soon(_follow_up, server, then)
        if type(response) is not self.srv_type.Response:
            raise TransportError(f"service {self.name} answered {type(response).__name__}")
        return response


def _follow_up(server: _LocalService, then: Callable[[], None]) -> None:
    try:
        then()
    except Exception as error:  # noqa: BLE001 - the serving node hears of it, like a handler's fault
        server.node.report_fault(f"service {server.name} (after its answer)", error)


def _follow_up_later(server: _LocalService, done: asyncio.Task[Any]) -> None:
    if done.cancelled() or done.exception() is not None:
        return
    _, then = unwrap_reply(done.result())
    if then is not None:
        _follow_up(server, then)


class LocalNode(Node):
    def __init__(
        self,
        bus: LocalTransport,
        name: str,
        namespace: str,
        parameters: Mapping[str, ParameterValue] | None,
    ) -> None:
        super().__init__(name, namespace, bus.clock, parameters)
        self.bus = self.transport = bus
        self._endpoints: list[Any] = []

    def create_publisher(self, msg_type: type[M], topic: str, qos: QoS = COMMANDS) -> LocalPublisher[M]:
        pub = LocalPublisher(self, msg_type, self.resolve(topic), qos)
        self.bus.add_publisher(pub)
        self._endpoints.append(pub)
        self.bus.publisher_created(TopicInfo(pub.topic, msg_type, (qos,)))
        return pub

    def create_subscription(
        self,
        msg_type: type[M],
        topic: str,
        callback: Callable[[M], None],
        qos: QoS = COMMANDS,
        *,
        objects: type | None = None,
        hand_over: bool = False,
    ) -> LocalSubscription[M]:
        """As every transport's; ``objects``: the callback also takes that wire class's objects as
        published by :meth:`LocalPublisher.publish_object` (:mod:`node_transport.carriage`);
        ``hand_over``: the callback only hands the message on to its node's own queue or futures,
        and may be called inside ``publish`` (see the module's doc)."""
        sub = LocalSubscription(self, msg_type, self.resolve(topic), callback, qos, objects, hand_over)
        self.bus.add_subscription(sub)
        self._endpoints.append(sub)
        return sub

    def create_service(self, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]) -> ServiceServer:
        server = _LocalService(self, srv_type, self.resolve(name), handler)
        self.bus.add_service(server)
        self._endpoints.append(server)
        return server

    def create_client(self, srv_type: type, name: str) -> ServiceClient[Any, Any]:
        return _LocalClient(self, srv_type, self.resolve(name))

    def topic_names_and_types(self) -> list[TopicInfo]:
        return self.bus.topics()

    def destroy(self) -> None:
        for endpoint in self._endpoints:
            if isinstance(endpoint, LocalPublisher):
                endpoint.alive = False
                self.bus.remove_publisher(endpoint)
            else:
                endpoint.destroy()
        self._endpoints.clear()
        self.bus.remove_node(self)


class LocalTransport(Transport):
    """All nodes of one process, on one asyncio loop."""

    def __init__(self, clock: Clock, *, hand_over: bool = True) -> None:
        """``hand_over`` False: every delivery takes its turn of the loop (as a comparison for tests)."""
        super().__init__(clock)
        self.hand_overs = hand_over
        self._publishers: dict[str, list[LocalPublisher[Any]]] = {}
        self._subscriptions: dict[str, list[LocalSubscription[Any]]] = {}
        # publisher -> the subscriptions it reaches: worked out once, not on every publish (a
        # running cell publishes thousands of messages a second and rarely changes its graph)
        self._matches: dict[LocalPublisher[Any], tuple[LocalSubscription[Any], ...]] = {}
        self._sources: dict[LocalSubscription[Any], tuple[LocalPublisher[Any], ...]] = {}  # the other way (a watch asks it per wait)
        self._services: dict[str, _LocalService] = {}
        self._types: dict[str, type] = {}
        self._nodes: dict[str, LocalNode] = {}
        self.hand_over_depth = 0  # hand-overs running now, one inside another

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        return self.clock.loop

    def create_node(
        self, name: str, namespace: str = "/", parameters: Mapping[str, ParameterValue] | None = None
    ) -> LocalNode:
        node = LocalNode(self, name, namespace, parameters)
        if node.fully_qualified_name in self._nodes:
            raise TransportError(f"a node named {node.fully_qualified_name} already exists")
        self._nodes[node.fully_qualified_name] = node
        return node

    def remove_node(self, node: LocalNode) -> None:
        self._nodes.pop(node.fully_qualified_name, None)

    def node_names(self) -> list[str]:
        return sorted(self._nodes)

    async def shutdown(self) -> None:
        for node in list(self._nodes.values()):
            node.destroy()

    # ------------------------------------------------------------------------------ wiring
    def _claim_type(self, topic: str, msg_type: type) -> None:
        known = self._types.setdefault(topic, msg_type)
        if known is not msg_type:
            raise TransportError(f"topic {topic} carries {known.__name__}; cannot use it for {msg_type.__name__}")

    def add_publisher(self, pub: LocalPublisher[Any]) -> None:
        self._claim_type(pub.topic, pub.msg_type)
        self._publishers.setdefault(pub.topic, []).append(pub)
        self._sources.clear()

    def remove_publisher(self, pub: LocalPublisher[Any]) -> None:
        pubs = self._publishers.get(pub.topic, [])
        if pub in pubs:
            pubs.remove(pub)
        self._matches.pop(pub, None)
        self._sources.clear()

    def add_subscription(self, sub: LocalSubscription[Any]) -> None:
        self._claim_type(sub.topic, sub.msg_type)
        self._subscriptions.setdefault(sub.topic, []).append(sub)
        self._matches.clear()
        for pub in self._publishers.get(sub.topic, []):
            if sub.qos.compatible_with(pub.qos) and sub.qos.durability is Durability.TRANSIENT_LOCAL:
                for msg in pub.history:
                    sub.deliver(msg.item_for(sub.objects) if type(msg) is Carried else msg)

    def remove_subscription(self, sub: LocalSubscription[Any]) -> None:
        subs = self._subscriptions.get(sub.topic, [])
        if sub in subs:
            subs.remove(sub)
        self._matches.clear()
        self._sources.pop(sub, None)

    def matching_publishers(self, sub: LocalSubscription[Any]) -> tuple[LocalPublisher[Any], ...]:
        found = self._sources.get(sub)
        if found is None:
            found = self._sources[sub] = tuple(p for p in self._publishers.get(sub.topic, []) if sub.qos.compatible_with(p.qos))
        return found

    def matching_subscriptions(self, pub: LocalPublisher[Any]) -> tuple[LocalSubscription[Any], ...]:
        found = self._matches.get(pub)
        if found is None:
            found = self._matches[pub] = tuple(s for s in self._subscriptions.get(pub.topic, []) if s.qos.compatible_with(pub.qos))
        return found

    def add_service(self, server: _LocalService) -> None:
        if server.name in self._services:
            raise TransportError(f"service {server.name} is already served by {self._services[server.name].node.fully_qualified_name}")
        self._services[server.name] = server

    def remove_service(self, server: _LocalService) -> None:
        if self._services.get(server.name) is server:
            del self._services[server.name]

    def service(self, name: str) -> _LocalService | None:
        return self._services.get(name)

    def topics(self) -> list[TopicInfo]:
        """Every topic that has a live publisher, with the QoS each offers."""
        return [
            TopicInfo(topic, self._types[topic], tuple(p.qos for p in pubs))
            for topic, pubs in sorted(self._publishers.items())
            if pubs
        ]
