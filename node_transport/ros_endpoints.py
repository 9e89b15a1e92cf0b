"""The rclpy transport's endpoints: publisher, subscription, service server and client.

Each wraps one rclpy entity of a :class:`~node_transport.ros.RosNode` and crosses
between rclpy's executor thread and the asyncio loop the nodes run on: a subscription's
callback and a service's request are handed to the loop (``call_soon_threadsafe``), a client's
rclpy future is settled on the loop; a service answers from the loop through rclpy, and is
destroyed from the executor's side so no request is taken by a half-destroyed service.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from collections.abc import Awaitable, Callable
from contextlib import AbstractContextManager
from typing import Any, Generic, Protocol, TypeVar

from node_transport.clock import Clock
from node_transport.port import (
    Publisher,
    ServiceClient,
    ServiceServer,
    ServiceUnavailable,
    Subscription,
    TransportError,
    unwrap_reply,
)
from node_transport.qos import Durability, QoS
from node_transport.ros_convert import MessageConverter, failure_response

M = TypeVar("M")
log = logging.getLogger(__name__)

POLL = 0.05  # run seconds between checks while waiting for a service to be discovered


class EndpointTransport(Protocol):
    """What the endpoints use of the rclpy transport (ros.py's RosTransport): its loop and executor side."""

    api: Any  # the rclpy names the adapter imported
    loop: asyncio.AbstractEventLoop
    clock: Clock
    handler_timeout: float
    handlers: set[asyncio.Task[Any]]  # service handlers running on the loop
    stopping: bool

    @property
    def in_flight(self) -> AbstractContextManager[None]: ...  # held while an rclpy callback of the adapter runs
    @property
    def spinning(self) -> bool: ...

    def call_soon(self, callback: Callable[..., Any], *args: Any) -> bool: ...
    def settle_threadsafe(self, answer: asyncio.Future[Any], ros_future: Any) -> None: ...
    def profile(self, qos: QoS) -> Any: ...


class EndpointOwner(Protocol):
    """The node an endpoint belongs to (ros.py's RosNode): its rclpy node, converter, groups and faults."""

    converter: MessageConverter
    ros_node: Any
    subscription_group: Any
    service_group: Any
    clock: Clock

    @property
    def transport(self) -> EndpointTransport: ...
    @property
    def fully_qualified_name(self) -> str: ...

    def report_fault(self, where: str, error: BaseException) -> None: ...
    def report_fault_threadsafe(self, where: str, error: BaseException) -> None: ...
    def service_gone(self) -> None: ...


class TopicEndpoint(Generic[M]):
    """What a publisher and a subscription both hold; resolves the rosidl class up front."""

    def __init__(self, node: EndpointOwner, msg_type: type[M], topic: str, qos: QoS) -> None:
        self.node = node
        self.msg_type = msg_type
        self.topic = topic
        self.qos = qos
        self.alive = True
        self.ros_class = node.converter.ros_class(msg_type)
        self.profile = node.transport.profile(qos)


class RosPublisher(TopicEndpoint[M], Publisher[M]):
    def __init__(self, node: EndpointOwner, msg_type: type[M], topic: str, qos: QoS) -> None:
        super().__init__(node, msg_type, topic, qos)
        # No QoS event handlers: rclpy's executor rebuilds its wait set from every handler on each
        # callback, and with two per endpoint that tripled the latency of a message (see the module).
        events = node.transport.api.publisher_events(use_default_callbacks=False)
        self.handle = node.ros_node.create_publisher(self.ros_class, topic, self.profile, event_callbacks=events)

    def publish(self, msg: M) -> None:
        if not self.alive:
            raise TransportError(f"publisher on {self.topic} of {self.node.fully_qualified_name} was destroyed")
        self._check(msg)
        self.handle.publish(self.node.converter.to_ros(msg))

    def get_subscription_count(self) -> int:
        """Matched subscriptions: zero until DDS discovery has matched one."""
        return int(self.handle.get_subscription_count()) if self.alive else 0


class RosSubscription(TopicEndpoint[M], Subscription[M]):
    def __init__(self, node: EndpointOwner, msg_type: type[M], topic: str, callback: Callable[[M], None], qos: QoS) -> None:
        super().__init__(node, msg_type, topic, qos)
        self._callback = callback
        # rclpy's default handler warns of a publisher offering incompatible QoS; kept only where an
        # outside publisher is likely to get it wrong: a latched (transient-local) subscription.
        latched = qos.durability is Durability.TRANSIENT_LOCAL
        events = None if latched else node.transport.api.subscription_events(use_default_callbacks=False)
        self.handle = node.ros_node.create_subscription(
            self.ros_class, topic, self._on_ros_message, self.profile, callback_group=node.subscription_group, event_callbacks=events
        )

    def get_publisher_count(self) -> int:
        """Matched publishers: zero until DDS discovery has matched one."""
        return int(self.handle.get_publisher_count()) if self.alive else 0

    def _on_ros_message(self, ros_msg: Any) -> None:
        """Executor thread: convert, then queue the delivery on the loop. Never raises."""
        with self.node.transport.in_flight:
            try:
                if not self.alive:
                    return
                msg = self.node.converter.from_ros(self.msg_type, ros_msg)
                self.node.transport.call_soon(self._deliver, msg)
            except Exception as error:  # noqa: BLE001 - a bad message must not end the executor
                self.node.report_fault_threadsafe(f"subscription {self.topic}", error)

    def destroy(self) -> None:
        if not self.alive:
            return
        self.alive = False
        self.node.ros_node.destroy_subscription(self.handle)


class RosService(ServiceServer):
    def __init__(self, node: EndpointOwner, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]) -> None:
        self.node = node
        self.srv_type = srv_type
        self.name = name
        self.alive = True
        self.gone = False  # the rclpy service is destroyed
        self._handler = handler
        self._guard: Any = None
        self._follow_guard: Any = None  # fires once the responses before it are sent (Reply.then)
        self._follow_ups: list[Callable[[], None]] = []
        self._lock = threading.Lock()
        self.group = node.transport.api.exclusive_group()  # see the module docstring
        service_class, _, _ = node.converter.service_classes(srv_type)
        self.handle = node.ros_node.create_service(service_class, name, self._on_request, callback_group=self.group)

    def _on_request(self, ros_request: Any, ros_response: Any) -> Any:
        """Executor thread: run the handler on the loop and wait for it, bounded. Never raises."""
        with self.node.transport.in_flight:
            try:
                request = self.node.converter.from_ros(self.srv_type.Request, ros_request)
                response, then = unwrap_reply(self._run_handler(request))
                if then is not None:
                    self._after_answer(then)
            except Exception as error:  # noqa: BLE001 - the caller gets a failure answer, the node a fault
                self.node.report_fault_threadsafe(f"service {self.name}", error)
                response = failure_response(self.srv_type.Response, f"{self.name}: {type(error).__name__}: {error}")
            try:
                return self.node.converter.to_ros(response)
            except Exception as error:  # noqa: BLE001
                self.node.report_fault_threadsafe(f"service {self.name} response", error)
                return ros_response

    def _run_handler(self, request: Any) -> Any:
        if not self.alive:
            return failure_response(self.srv_type.Response, f"{self.name}: service was destroyed")
        transport = self.node.transport
        future = asyncio.run_coroutine_threadsafe(self._call(request), transport.loop)
        # a handler that waits for a long job on purpose (an action's get_result) holds this
        # executor thread until the job ends (or shutdown cancels it), unbounded
        long_running = getattr(self._handler, "long_running", False)
        wall = None if long_running else transport.clock.to_wall(transport.handler_timeout)
        try:
            return future.result(timeout=wall)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise TimeoutError(f"handler did not answer within {transport.handler_timeout:g} s") from None
        except concurrent.futures.CancelledError:
            raise TransportError("handler cancelled: the node is shutting down") from None

    async def _call(self, request: Any) -> Any:
        """Loop thread. Registered with the transport so shutdown can cancel it: both run on the
        loop, so a handler either is registered before shutdown looks or sees it has begun."""
        transport = self.node.transport
        if transport.stopping:
            raise TransportError("the node is shutting down")
        task = asyncio.current_task()
        assert task is not None
        transport.handlers.add(task)
        try:
            answer = await self._handler(request)
        finally:
            transport.handlers.discard(task)
        response, _ = unwrap_reply(answer)
        if type(response) is not self.srv_type.Response:
            raise TransportError(f"service {self.name} handler answered {type(response).__name__}, not {self.srv_type.Response.__name__}")
        return answer

    def _after_answer(self, then: Callable[[], None]) -> None:
        """Executor thread, inside the request's callback: run ``then`` on the loop once rclpy has
        sent the response.  rclpy sends it when the callback returns, still holding the service's
        mutually exclusive group; a guard condition of that group fires only after that."""
        with self._lock:
            self._follow_ups.append(then)
            if self._follow_guard is None:
                self._follow_guard = self.node.ros_node.create_guard_condition(self._answered, callback_group=self.group)
            guard = self._follow_guard
        guard.trigger()

    def _answered(self) -> None:
        """Executor thread, holding the service's group: the responses before this are sent."""
        with self.node.transport.in_flight:
            with self._lock:
                pending, self._follow_ups = self._follow_ups, []
            for then in pending:
                self.node.transport.call_soon(self._follow_up, then)

    def _follow_up(self, then: Callable[[], None]) -> None:
        try:
            then()
        except Exception as error:  # noqa: BLE001 - the serving node hears of it, like a handler's fault
            self.node.report_fault(f"service {self.name} (after its answer)", error)

    def destroy(self) -> None:
        """Stop answering now; leave the graph as soon as no request is being answered.

        While the executor spins, the rclpy service is destroyed from a guard condition in its
        own mutually exclusive group, so never between a request's callback and its response."""
        if not self.alive:
            return
        self.alive = False
        transport = self.node.transport
        if transport.stopping:
            return  # shutdown destroys it once the executor's callbacks are done
        if transport.spinning:
            self._guard = self.node.ros_node.create_guard_condition(self._destroy_in_group, callback_group=self.group)
            self._guard.trigger()
        else:
            self.destroy_now()

    def _destroy_in_group(self) -> None:
        """Executor thread, holding the service's group: no request of it is in flight."""
        with self.node.transport.in_flight:
            self.destroy_now()
            self.node.transport.call_soon(self.node.service_gone)

    def destroy_now(self) -> None:
        if self.gone:
            return
        self.gone = True
        try:
            self.node.ros_node.destroy_service(self.handle)
            for guard in (self._guard, self._follow_guard):
                if guard is not None:
                    self.node.ros_node.destroy_guard_condition(guard)
        except Exception:  # noqa: BLE001 - the node goes anyway; say what stayed behind
            log.exception("destroying service %s failed", self.name)


class RosClient(ServiceClient[Any, Any]):
    def __init__(self, node: EndpointOwner, srv_type: type, name: str) -> None:
        self.node = node
        self.srv_type = srv_type
        self.name = name
        self.alive = True
        self._pending: set[asyncio.Future[Any]] = set()
        service_class, _, _ = node.converter.service_classes(srv_type)
        self.handle = node.ros_node.create_client(service_class, name, callback_group=node.service_group)

    async def wait_for_service(self, timeout: float) -> bool:
        clock = self.node.clock
        deadline = clock.now() + timeout
        while not self.handle.service_is_ready():
            remaining = deadline - clock.now()
            if remaining <= 0:
                return False
            await clock.sleep(min(POLL, remaining))
        return True

    async def call(self, request: Any, timeout: float = 5.0) -> Any:
        if type(request) is not self.srv_type.Request:
            raise TransportError(f"service {self.name} takes {self.srv_type.Request.__name__}, got {type(request).__name__}")
        if not self.alive:
            raise TransportError(f"client of {self.name} on {self.node.fully_qualified_name} was destroyed")
        clock = self.node.clock
        deadline = clock.now() + timeout
        if not self.handle.service_is_ready() and not await self.wait_for_service(timeout):
            raise ServiceUnavailable(f"no server for service {self.name} within {timeout:g} s")
        transport = self.node.transport
        answer: asyncio.Future[Any] = transport.loop.create_future()
        ros_future = self.handle.call_async(self.node.converter.to_ros(request))
        ros_future.add_done_callback(lambda done: transport.settle_threadsafe(answer, done))
        self._pending.add(answer)
        try:
            ros_response = await clock.wait_for(answer, max(0.0, deadline - clock.now()))
        except asyncio.TimeoutError:
            self.handle.remove_pending_request(ros_future)
            raise TimeoutError(f"service {self.name} did not answer within {timeout:g} s") from None
        finally:
            self._pending.discard(answer)
        return self.node.converter.from_ros(self.srv_type.Response, ros_response)

    def abandon(self) -> None:
        """The node is going away: fail every call still waiting."""
        self.alive = False
        for answer in list(self._pending):
            if not answer.done():
                answer.set_exception(TransportError(f"client of {self.name} was destroyed during the call"))


def settle(answer: asyncio.Future[Any], ros_future: Any) -> None:
    """Loop thread: copy an rclpy future's outcome into the asyncio future (unless it gave up)."""
    if answer.done():
        return
    if ros_future.cancelled():
        answer.set_exception(TransportError("the service call was cancelled by rclpy"))
        return
    error = ros_future.exception()
    if error is not None:
        answer.set_exception(error)
    else:
        answer.set_result(ros_future.result())


# ======================================================================================= node
