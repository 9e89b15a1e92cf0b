"""The ``ros`` transport: the port of :mod:`execution_engine.transport.port` over rclpy (ROS 2 Jazzy).

Imported only when a ROS deployment is chosen; rclpy itself is imported inside
:class:`RosTransport`, so this module can be read (and its fakes tested) without ROS 2.  Two
worlds meet here and each keeps its own thread:

* rclpy's executor spins in a background thread.  Every rclpy callback is a small bridge that
  never raises (an exception out of an rclpy callback would end ``spin``):

  - a subscription converts the rosidl message to our mirror and hands it to the asyncio loop
    with ``loop.call_soon_threadsafe``; subscriptions share one mutually exclusive callback
    group per node, so a topic's messages reach the loop in the order they arrived;
  - a service runs our coroutine handler on the loop with ``run_coroutine_threadsafe`` and
    waits (bounded) for its answer.  Each service has its own mutually exclusive callback group:
    rclpy takes a request, runs the callback and sends the response while holding the group, so
    a guard condition in the same group is the one moment the service can be destroyed without
    a response meeting a destroyed handle (which would end ``spin``);
  - clients use a reentrant group, so a handler that itself calls a service does not block the
    client response it waits for -- which is why the executor is a MultiThreadedExecutor;
  - a client call is ``call_async``; the rclpy future's done-callback settles an asyncio future.

  Publishers and subscriptions carry no QoS event handlers (but latched subscriptions, where an
  outside publisher offering volatile QoS would silently not connect): rclpy 7.1's executor
  rebuilds its wait set from every handler on each callback, which made a message between two
  of our processes three times slower.

  Every callback is counted while it runs: rclpy 7.1.11 and older return from
  ``Executor.shutdown(timeout_sec)`` at once, so shutdown waits for that count, bounded.

* the asyncio loop runs the node's code: callbacks, handlers, publishing.

Faults in any callback go to ``node.report_fault`` on the loop, exactly as on the local
transport.  Differences from :mod:`~execution_engine.transport.local` that a caller may notice:
a handler that raises or times out answers the caller with ``success=False`` and the error text
(rclpy must answer something); a call to a service that is not (yet) discovered waits for it up
to the call's timeout before raising :class:`ServiceUnavailable`, because discovery takes time;
nothing is delivered between endpoints before DDS discovery has matched them
(:func:`~execution_engine.transport.port.wait_until_matched`).  Parameters are read once at
start-up; ``ros2 param set`` on a declared parameter is refused rather than silently ignored.
Stamps come from the node's ROS clock; with ``use_sim_time`` the node's run clock follows
``/clock`` too (:class:`~execution_engine.clock.FollowingClock`).  Logging goes to rcutils and
``/rosout`` (:mod:`~execution_engine.transport.ros_logging`).
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from execution_engine.clock import Clock, FollowingClock
from execution_engine.transport import ros_logging, typed
from execution_engine.transport.msgs import CAMERA_TYPES, MESSAGE_TYPES, ClockMessage, Time
from execution_engine.transport.port import (
    EndpointNode,
    RosArgumentsError,
    ParameterValue,
    Publisher,
    ServiceClient,
    ServiceServer,
    ServiceUnavailable,
    Subscription,
    TopicInfo,
    Transport,
    TransportError,
    resolve_name,
    validate_node_name,
)
from execution_engine.transport.qos import CLOCK, Durability, QoS
from execution_engine.transport.ros_args import raw_parameter_texts
from execution_engine.transport.wire import CLOCK_TOPIC
from execution_engine.transport.ros_convert import (
    MessageConverter,
    failure_response,
    offered_qos,
    parameter_type_code,
    qos_profile,
    user_overrides,
)

M = TypeVar("M")
log = logging.getLogger(__name__)

_POLL = 0.05  # run seconds between checks while waiting for a service to be discovered


def _rcl_message(error: BaseException) -> str:
    """One line of what rcl said: without its source location and its generic prefix."""
    text = " ".join(str(error).split())
    text = text.split(", at ./")[0].split(", at /")[0]
    for prefix in ("failed to initialize rcl: ", "Failed to initialize rcl: "):
        if text.startswith(prefix):
            text = text[len(prefix):]
    if type(error).__name__ == "UnknownROSArgsError":
        text = f"unknown ROS argument(s) {text}"
    return text


class _InFlight:
    """Counts rclpy callbacks of the adapter while they run, so shutdown can wait for them."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._count = 0

    def __enter__(self) -> None:
        with self._cond:
            self._count += 1

    def __exit__(self, *exc: object) -> None:
        with self._cond:
            self._count -= 1
            if self._count == 0:
                self._cond.notify_all()

    @property
    def count(self) -> int:
        return self._count

    def wait_idle(self, timeout: float) -> bool:
        """True once no callback runs; False after ``timeout`` wall seconds."""
        with self._cond:
            return self._cond.wait_for(lambda: self._count == 0, timeout=timeout)


@dataclass(frozen=True)
class _Rclpy:
    """The rclpy names the adapter uses, imported once, in one place."""

    rclpy: Any
    node_class: Any
    executor_class: Any
    external_shutdown: type[BaseException]
    exclusive_group: Any
    reentrant_group: Any
    parameter: Any
    qos: Any
    no_signal_handlers: Any
    remove_ros_args: Any
    parameter_descriptor: Any
    parameter_value: Any
    set_parameters_result: Any
    publisher_events: Any
    subscription_events: Any


def _import_rclpy() -> _Rclpy:
    try:
        import rclpy
        import rclpy.qos
        from rcl_interfaces.msg import ParameterDescriptor, ParameterValue as ParameterValueMsg, SetParametersResult
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
        from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
        from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
        from rclpy.node import Node as RclpyNode
        from rclpy.parameter import Parameter
        from rclpy.signals import SignalHandlerOptions
        from rclpy.utilities import remove_ros_args
    except ImportError as error:
        raise TransportError(
            f"the ros transport needs rclpy ({error}); source a ROS 2 Jazzy environment "
            "(source /opt/ros/jazzy/setup.bash) or use the local transport"
        ) from None
    return _Rclpy(
        rclpy=rclpy,
        node_class=RclpyNode,
        executor_class=MultiThreadedExecutor,
        external_shutdown=ExternalShutdownException,
        exclusive_group=MutuallyExclusiveCallbackGroup,
        reentrant_group=ReentrantCallbackGroup,
        parameter=Parameter,
        qos=rclpy.qos,
        no_signal_handlers=SignalHandlerOptions.NO,
        remove_ros_args=remove_ros_args,
        parameter_descriptor=ParameterDescriptor,
        parameter_value=ParameterValueMsg,
        set_parameters_result=SetParametersResult,
        publisher_events=PublisherEventCallbacks,
        subscription_events=SubscriptionEventCallbacks,
    )


# =================================================================================== endpoints
class _TopicEndpoint(Generic[M]):
    """What a publisher and a subscription both hold; resolves the rosidl class up front."""

    def __init__(self, node: RosNode, msg_type: type[M], topic: str, qos: QoS) -> None:
        self.node = node
        self.msg_type = msg_type
        self.topic = topic
        self.qos = qos
        self.alive = True
        self.ros_class = node.converter.ros_class(msg_type)
        self.profile = node.transport.profile(qos)


class _RosPublisher(_TopicEndpoint[M], Publisher[M]):
    def __init__(self, node: RosNode, msg_type: type[M], topic: str, qos: QoS) -> None:
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


class _RosSubscription(_TopicEndpoint[M], Subscription[M]):
    def __init__(self, node: RosNode, msg_type: type[M], topic: str, callback: Callable[[M], None], qos: QoS) -> None:
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


class _RosService(ServiceServer):
    def __init__(self, node: RosNode, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]) -> None:
        self.node = node
        self.srv_type = srv_type
        self.name = name
        self.alive = True
        self.gone = False  # the rclpy service is destroyed
        self._handler = handler
        self._guard: Any = None
        self.group = node.transport.api.exclusive_group()  # see the module docstring
        service_class, _, _ = node.converter.service_classes(srv_type)
        self.handle = node.ros_node.create_service(service_class, name, self._on_request, callback_group=self.group)

    def _on_request(self, ros_request: Any, ros_response: Any) -> Any:
        """Executor thread: run the handler on the loop and wait for it, bounded. Never raises."""
        with self.node.transport.in_flight:
            try:
                request = self.node.converter.from_ros(self.srv_type.Request, ros_request)
                response = self._run_handler(request)
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
            response = await self._handler(request)
        finally:
            transport.handlers.discard(task)
        if type(response) is not self.srv_type.Response:
            raise TransportError(f"service {self.name} handler answered {type(response).__name__}, not {self.srv_type.Response.__name__}")
        return response

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
            if self._guard is not None:
                self.node.ros_node.destroy_guard_condition(self._guard)
        except Exception:  # noqa: BLE001 - the node goes anyway; say what stayed behind
            log.exception("destroying service %s failed", self.name)


class _RosClient(ServiceClient[Any, Any]):
    def __init__(self, node: RosNode, srv_type: type, name: str) -> None:
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
            await clock.sleep(min(_POLL, remaining))
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


def _settle(answer: asyncio.Future[Any], ros_future: Any) -> None:
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
class RosNode(EndpointNode):
    """One rclpy node behind the port; its callbacks run on the transport's asyncio loop."""

    def __init__(
        self,
        transport: RosTransport,
        name: str,
        namespace: str,
        parameters: Mapping[str, ParameterValue] | None,
    ) -> None:
        validate_node_name(name)
        resolve_name("x", namespace)  # validates the namespace before rclpy sees it
        api = transport.api
        self.transport = transport
        self.converter = transport.converter
        overrides = [api.parameter(key, value=value) for key, value in (parameters or {}).items()]
        # Overrides from the command line / launch file are declared by rclpy itself, so we can
        # read them back (and report the ones no code declares: typos in a launch file).
        self.ros_node = api.node_class(
            name,
            namespace=namespace,
            parameter_overrides=overrides,
            automatically_declare_parameters_from_overrides=True,
        )
        # A launch file may rename the node (__node:=, __ns:=): the port sees the real name.
        real_namespace = self.ros_node.get_namespace() or "/"
        real_name = self.ros_node.get_name()
        given = self.ros_node.get_parameters_by_prefix("")
        fqn = f"{real_namespace.rstrip('/')}/{real_name}"
        super().__init__(
            real_name,
            real_namespace,
            transport.clock,
            user_overrides((key, self.ros_node.get_parameter(key).value) for key in given),
            override_texts=raw_parameter_texts(transport.argv, fqn),
        )
        self.subscription_group = api.exclusive_group()
        self.service_group = api.reentrant_group()
        self._read_at_start: set[str] = set()
        self._endpoints: list[Any] = []
        self.dying_services: list[_RosService] = []  # destroyed by us, not yet by rclpy
        self.destroyed = False
        self.ros_node.add_on_set_parameters_callback(self._on_set_parameters)
        ros_logging.install(self.logger.name, self.ros_node.get_logger())
        if self._use_sim_time():
            self.clock = self._follow_sim_time()

    # ------------------------------------------------------------------------------ time
    def _use_sim_time(self) -> bool:
        """rclpy's own parameter; read once, like every parameter of ours."""
        self._read_at_start.add("use_sim_time")
        try:
            return self.ros_node.get_parameter("use_sim_time").value is True
        except Exception:  # noqa: BLE001 - an rclpy without it has no simulated time
            return False

    def _follow_sim_time(self) -> FollowingClock:
        """The node's run clock follows ``/clock``; a silent source is a fault, not a hang."""
        clock = FollowingClock(
            stall_timeout=self.transport.clock_stall_timeout,
            on_stall=lambda text: self.report_fault(CLOCK_TOPIC, TimeoutError(text)),
        )
        clock.bind(self.transport.loop)
        self.create_subscription(ClockMessage, CLOCK_TOPIC, lambda msg: clock.advance_to(msg.clock.to_seconds()), CLOCK)
        return clock

    def now_stamp(self) -> Time:
        """The node's ROS clock: wall time, or ``/clock`` with ``use_sim_time``."""
        sec, nanosec = self.ros_node.get_clock().now().seconds_nanoseconds()
        return Time(int(sec), int(nanosec))

    # ------------------------------------------------------------------------ parameters
    def declare_parameter(self, name: str, default: ParameterValue, description: str = "") -> ParameterValue:
        value = super().declare_parameter(name, default, description)
        api = self.transport.api
        code = parameter_type_code(default)
        descriptor = api.parameter_descriptor(description=description, type=code)
        try:
            if self.ros_node.has_parameter(name):
                # rclpy declared the override with a bare descriptor and the override's own type:
                # give it ours, so `ros2 param describe` is right and `-p speed:=2` is a double.
                self.ros_node.set_descriptor(name, descriptor, _parameter_value(api, code, value))
            else:
                self.ros_node.declare_parameter(name, value, descriptor)
        except Exception as error:  # noqa: BLE001 - rclpy's parameter exceptions have no common base
            del self._parameters[name]
            raise TransportError(f"{self.fully_qualified_name}: rclpy refused parameter {name!r}: {error}") from None
        self._read_at_start.add(name)
        return value

    def _on_set_parameters(self, parameters: list[Any]) -> Any:
        """rclpy callback (any thread): refuse changes to parameters our code has already read."""
        frozen = [p.name for p in parameters if p.name in self._read_at_start]
        result = self.transport.api.set_parameters_result
        if frozen:
            return result(
                successful=False,
                reason=f"{', '.join(frozen)} read at start-up; restart {self.fully_qualified_name} to change",
            )
        return result(successful=True)

    def topic_names_and_types(self) -> list[TopicInfo]:
        """The graph's topics of our types, with each publisher's offered QoS (``ros2 bag record -a``'s discovery)."""
        known = {t.ROS_TYPE: t for t in (*MESSAGE_TYPES, *typed.MESSAGE_TYPES, *CAMERA_TYPES, ClockMessage)}
        found = []
        for name, types in self.ros_node.get_topic_names_and_types():
            mirror = next((known[t] for t in types if t in known), None)
            if mirror is None:
                continue
            offered = tuple(offered_qos(info.qos_profile) for info in self.ros_node.get_publishers_info_by_topic(name))
            if offered:
                found.append(TopicInfo(name, mirror, offered))
        return found

    def destroy(self) -> None:
        """Leave the graph: every endpoint stops now; the services go as soon as none of them is
        answering a request, and the rclpy node with the last of them."""
        if self.destroyed:
            return
        self.destroyed = True
        services = [e for e in self._endpoints if isinstance(e, _RosService)]
        for endpoint in self._endpoints:
            if isinstance(endpoint, _RosClient):
                endpoint.abandon()
                self.ros_node.destroy_client(endpoint.handle)
            elif isinstance(endpoint, _RosSubscription):
                endpoint.destroy()
            elif isinstance(endpoint, _RosPublisher):
                endpoint.alive = False
                self.ros_node.destroy_publisher(endpoint.handle)
        self._endpoints.clear()
        ros_logging.uninstall(self.logger.name)
        for service in services:
            service.destroy()
        self.dying_services = [s for s in services if not s.gone]
        if not self.dying_services and not self.transport.stopping:
            self.transport.retire(self)

    def service_gone(self) -> None:
        """Loop thread: one more service of this destroyed node left the graph."""
        self.dying_services = [s for s in self.dying_services if not s.gone]
        if not self.dying_services and not self.transport.stopping:
            self.transport.retire(self)

    # ---------------------------------------------------------------------------- faults
    def report_fault_threadsafe(self, where: str, error: BaseException) -> None:
        """From the executor thread: report on the loop, where the fault handler lives."""
        if not self.transport.call_soon(self.report_fault, where, error):
            self.logger.error("%s: fault in %s after the loop closed: %r", self.fully_qualified_name, where, error)


RosNode.publisher_class, RosNode.subscription_class = _RosPublisher, _RosSubscription
RosNode.service_class, RosNode.client_class = _RosService, _RosClient


def _parameter_value(api: _Rclpy, code: int, value: ParameterValue) -> Any:
    """An rcl_interfaces/ParameterValue message of type ``code`` holding ``value``."""
    field = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
             6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value", 9: "string_array_value"}[code]
    return api.parameter_value(type=code, **{field: value})


# ================================================================================== transport
class RosTransport(Transport):
    """Nodes of one process on rclpy, with one executor thread for all of them.

    Create it inside the running loop its clock is bound to.  ``args`` is the process's argv
    (ROS arguments such as ``--ros-args -p name:=value`` are parsed by rclpy; ones rcl refuses
    raise :class:`RosArgumentsError`).  rclpy's own SIGINT/SIGTERM handlers are not installed:
    the process's asyncio loop handles signals and shuts the transport down in order (see
    :mod:`execution_engine.ros_main`).  ``handler_timeout`` bounds how long an executor thread
    waits for a service handler and ``shutdown_timeout`` how long shutdown waits for callbacks in
    flight, both in run seconds; ``clock_stall_timeout`` how long a node with ``use_sim_time``
    waits for ``/clock`` before its waits end (wall seconds).
    """

    def __init__(
        self,
        clock: Clock,
        args: Sequence[str] | None = None,
        *,
        threads: int = 4,
        handler_timeout: float = 30.0,
        shutdown_timeout: float = 5.0,
        clock_stall_timeout: float = 10.0,
    ) -> None:
        super().__init__(clock)
        if clock.simulated:
            raise ValueError(
                "the ros transport runs in wall time: a simulated clock would jump over every wait for the executor thread"
            )
        if threads < 2:
            raise ValueError("the ros transport needs at least 2 executor threads (a service handler may wait for a client response)")
        self.api = _import_rclpy()
        self.loop = clock.loop
        self.argv = list(args or [])
        self.handler_timeout = handler_timeout
        self.shutdown_timeout = shutdown_timeout
        self.clock_stall_timeout = clock_stall_timeout
        self.converter = MessageConverter()
        self.in_flight = _InFlight()
        self._owns_context = False
        if not self.api.rclpy.ok():
            try:
                self.api.rclpy.init(args=None if args is None else list(args), signal_handler_options=self.api.no_signal_handlers)
            except RuntimeError as error:  # rcl's RCLError / UnknownROSArgsError: the arguments are wrong
                raise RosArgumentsError(_rcl_message(error)) from None
            self._owns_context = True
        self._nodes: dict[str, RosNode] = {}
        self.stopping = False
        self.spin_error: BaseException | None = None
        self._closed = asyncio.Event()
        self.handlers: set[asyncio.Task[Any]] = set()  # service handlers running on the loop
        self._executor = self.api.executor_class(num_threads=threads)
        self._thread = threading.Thread(target=self._spin, name="rclpy executor", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------------- executor side
    @property
    def spinning(self) -> bool:
        return self._thread.is_alive() and not self.stopping

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except self.api.external_shutdown:  # rclpy.shutdown() elsewhere: an orderly end
            log.info("rclpy was shut down; the executor stopped")
        except BaseException as error:  # noqa: BLE001 - the loop must learn that ROS is gone
            if not self.stopping:
                self.spin_error = error
                log.error("rclpy executor stopped: %s: %s", type(error).__name__, error)
        finally:
            self.call_soon(self._closed.set)

    def call_soon(self, callback: Callable[..., Any], *args: Any) -> bool:
        """Schedule ``callback`` on the loop from any thread; False once the loop is closed."""
        try:
            self.loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:  # loop closed: nothing left to deliver to
            return False
        return True

    def settle_threadsafe(self, answer: asyncio.Future[Any], ros_future: Any) -> None:
        """An rclpy future's done-callback (executor thread): settle ``answer`` on the loop."""
        with self.in_flight:
            self.call_soon(_settle, answer, ros_future)

    def profile(self, qos: QoS) -> Any:
        return qos_profile(qos, self.api.qos)

    # ------------------------------------------------------------------------------- nodes
    def create_node(
        self, name: str, namespace: str = "/", parameters: Mapping[str, ParameterValue] | None = None
    ) -> RosNode:
        if self.stopping:
            raise TransportError("the ros transport is shut down")
        node = RosNode(self, name, namespace, parameters)
        if node.fully_qualified_name in self._nodes:
            node.destroy()
            raise TransportError(f"a node named {node.fully_qualified_name} already exists")
        self._nodes[node.fully_qualified_name] = node
        self._executor.add_node(node.ros_node)
        return node

    def retire(self, node: RosNode) -> None:
        """Take ``node`` off the executor and destroy its rclpy node (its services are gone)."""
        if self._nodes.get(node.fully_qualified_name) is node:
            del self._nodes[node.fully_qualified_name]
        self._executor.remove_node(node.ros_node)
        _destroy_ros_node(node.ros_node)

    def node_names(self) -> list[str]:
        return sorted(self._nodes)

    def user_args(self, argv: Sequence[str]) -> list[str]:
        """``argv`` without the program name and without ROS arguments (``--ros-args ... --``)."""
        return list(self.api.remove_ros_args(args=list(argv)))[1:]

    async def wait_closed(self) -> None:
        """Returns once the executor has stopped: after shutdown, or when rclpy went away by itself."""
        await self._closed.wait()

    async def shutdown(self) -> None:
        """Destroy every node, stop the executor and wait for callbacks in flight (bounded), then
        shut rclpy down if we started it."""
        if self.stopping:
            return
        self.stopping = True
        for node in list(self._nodes.values()):
            node.destroy()
        for task in list(self.handlers):  # their executor threads answer "cancelled" at once
            task.cancel()
        wall = self.clock.to_wall(self.shutdown_timeout)
        deadline = self.loop.time() + wall
        try:
            # Blocking calls go to a worker thread: in-flight service callbacks need this loop.
            await asyncio.to_thread(self._executor.shutdown, timeout_sec=wall)
        except Exception:  # noqa: BLE001 - shutdown goes on regardless
            log.exception("rclpy executor shutdown failed")
        # rclpy <= 7.1.11 returned at once: wait for our callbacks ourselves, within the same bound.
        if not await asyncio.to_thread(self.in_flight.wait_idle, max(0.0, deadline - self.loop.time())):
            log.warning("rclpy executor: %d callback(s) still running after %g s at shutdown", self.in_flight.count, self.shutdown_timeout)
        await asyncio.to_thread(self._thread.join, max(0.0, deadline - self.loop.time()))
        if self._thread.is_alive():
            log.error("rclpy executor thread did not stop within %g s", self.shutdown_timeout)
        for node in list(self._nodes.values()):  # the executor is idle: services go directly
            for service in node.dying_services:
                service.destroy_now()
            _destroy_ros_node(node.ros_node)
        self._nodes.clear()
        if self._owns_context and self.api.rclpy.ok():
            self.api.rclpy.shutdown()
        self._closed.set()


def _destroy_ros_node(ros_node: Any) -> None:
    try:
        ros_node.destroy_node()
    except Exception:  # noqa: BLE001 - one node failing to go must not keep the others
        log.exception("destroying rclpy node failed")
