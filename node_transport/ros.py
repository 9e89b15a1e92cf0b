"""The ``ros`` transport: the port of :mod:`node_transport.port` over rclpy (ROS 2 Jazzy).

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
transport.  Differences from :mod:`~node_transport.local` that a caller may notice:
a handler that raises or times out answers the caller with ``success=False`` and the error text
(rclpy must answer something); a call to a service that is not (yet) discovered waits for it up
to the call's timeout before raising :class:`ServiceUnavailable`, because discovery takes time;
nothing is delivered between endpoints before DDS discovery has matched them
(:func:`~node_transport.port.wait_until_matched`).  Parameters are read once at
start-up; ``ros2 param set`` on a declared parameter is refused rather than silently ignored.
Stamps come from the node's ROS clock; with ``use_sim_time`` the node's run clock follows
``/clock`` too (:class:`~node_transport.clock.FollowingClock`).  Logging goes to rcutils and
``/rosout`` (:mod:`~node_transport.ros_logging`).
"""
from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from node_transport import ros_logging, typed
from node_transport.clock import Clock, FollowingClock
from node_transport.msgs import CAMERA_TYPES, MESSAGE_TYPES, ClockMessage, Time
from node_transport.port import (
    EndpointNode,
    RosArgumentsError,
    ParameterValue,
    TopicInfo,
    Transport,
    TransportError,
    resolve_name,
    validate_node_name,
)
from node_transport.parameters import NumericRange, descriptor_range
from node_transport.qos import QoS
from node_transport.ros_args import raw_parameter_texts
from node_transport.ros_convert import (
    MessageConverter,
    offered_qos,
    parameter_type_code,
    qos_profile,
    user_overrides,
)
from node_transport.ros_endpoints import RosClient, RosPublisher, RosService, RosSubscription, settle
from node_transport.sim_time import follow_clock

M = TypeVar("M")
log = logging.getLogger(__name__)

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
    floating_point_range: Any
    integer_range: Any
    parameter_value: Any
    set_parameters_result: Any
    publisher_events: Any
    subscription_events: Any


def _import_rclpy() -> _Rclpy:
    try:  # optional: rclpy (a sourced ROS 2 environment), imported when the ros transport starts
        import rclpy
        import rclpy.qos
        from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterValue as ParameterValueMsg, SetParametersResult
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
        floating_point_range=FloatingPointRange,
        integer_range=IntegerRange,
        parameter_value=ParameterValueMsg,
        set_parameters_result=SetParametersResult,
        publisher_events=PublisherEventCallbacks,
        subscription_events=SubscriptionEventCallbacks,
    )


# =================================================================================== endpoints
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
        self.dying_services: list[RosService] = []  # destroyed by us, not yet by rclpy
        self.destroyed = False
        self.ros_node.add_pre_set_parameters_callback(self._widen_integers)
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
        return follow_clock(self, self.transport.loop, self.transport.clock_stall_timeout)

    def now_stamp(self) -> Time:
        """The node's ROS clock: wall time, or ``/clock`` with ``use_sim_time``."""
        sec, nanosec = self.ros_node.get_clock().now().seconds_nanoseconds()
        return Time(int(sec), int(nanosec))

    # ------------------------------------------------------------------------ parameters
    def declare_parameter(
        self, name: str, default: ParameterValue, description: str = "", numeric_range: NumericRange | None = None,
    ) -> ParameterValue:
        value = super().declare_parameter(name, default, description, numeric_range)
        api = self.transport.api
        code = parameter_type_code(default)
        descriptor = api.parameter_descriptor(description=description, type=code, **descriptor_range(self.ranges.get(name), api.floating_point_range, api.integer_range))
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

    def _widen_integers(self, parameters: list[Any]) -> list[Any]:
        """rclpy pre-set callback (any thread): an integer for a double parameter is that double, as on the
        command line -- ``ros2 param set /execution_engine speed_override 50`` sends the integer 50, which
        rclpy would refuse as the wrong type before its range or our check saw it."""
        api = self.transport.api
        return [
            api.parameter(p.name, value=float(p.value))
            if isinstance(self._parameters.get(p.name), float) and isinstance(p.value, int) and not isinstance(p.value, bool) else p
            for p in parameters
        ]

    def _on_set_parameters(self, parameters: list[Any]) -> Any:
        """rclpy callback (any thread): refuse changes to parameters our code has already read, and
        a changeable one's value its check refuses; a changeable one taken is applied on the loop."""
        frozen = [p.name for p in parameters if p.name in self._read_at_start and p.name not in self._changeable]
        result = self.transport.api.set_parameters_result
        if frozen:
            return result(
                successful=False,
                reason=f"{', '.join(frozen)} read at start-up; restart {self.fully_qualified_name} to change",
            )
        taken = []
        for parameter in (p for p in parameters if p.name in self._changeable):
            value, refusal = self.check_parameter(parameter.name, parameter.value)
            if value is None:
                return result(successful=False, reason=refusal)
            taken.append((parameter.name, value))
        for name, value in taken:
            self.transport.loop.call_soon_threadsafe(self._apply_reported, name, value)
        return result(successful=True)

    def show_parameter(self, name: str, value: ParameterValue) -> None:
        super().show_parameter(name, value)
        self.ros_node.set_parameters([self.transport.api.parameter(name, value=value)])  # its echo finds the value taken

    def _apply_reported(self, name: str, value: ParameterValue) -> None:
        try:
            self.apply_parameter(name, value)
        except Exception as error:  # noqa: BLE001 - a change that failed is a fault of the node, not a silent loss
            self.report_fault(f"parameter {name}", error)

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
        services = [e for e in self._endpoints if isinstance(e, RosService)]
        for endpoint in self._endpoints:
            if isinstance(endpoint, RosClient):
                endpoint.abandon()
                self.ros_node.destroy_client(endpoint.handle)
            elif isinstance(endpoint, RosSubscription):
                endpoint.destroy()
            elif isinstance(endpoint, RosPublisher):
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


RosNode.publisher_class, RosNode.subscription_class = RosPublisher, RosSubscription
RosNode.service_class, RosNode.client_class = RosService, RosClient


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
    :mod:`cell_runner.ros_main`).  ``handler_timeout`` bounds how long an executor thread
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
            self.call_soon(settle, answer, ros_future)

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
