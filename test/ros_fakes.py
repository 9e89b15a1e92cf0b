"""A stand-in for rclpy (7.1, ROS 2 Jazzy), for testing the ros transport without ROS 2.

It models what rclpy and the middleware really do where the adapter depends on it -- including
the parts that bit us on a real Jazzy -- not rclpy's internals:

* ``rclpy.init`` parses ``--ros-args`` as rcl does and refuses what rcl refuses, with rcl's
  exception types (``test/ros_fake_args.py``): parameter values typed by rcl's YAML rules
  (``off`` is a bool, ``0x10`` an int), ``--params-file`` sections matched to node names,
  ``--log-level``, ``-r __node:=``/``__ns:=`` renames;
* DDS discovery takes time: every publisher/subscription and client/service pair matches only
  ``GRAPH.match_delay`` wall seconds after both exist, and only when their QoS are compatible;
  nothing is delivered before the match (a volatile message published earlier is lost; a
  TRANSIENT_LOCAL history reaches the reader at the match); ``get_subscription_count`` /
  ``get_publisher_count`` / ``service_is_ready`` count matches only;
* ``Node`` with parameter overrides (and automatic declaration with a bare descriptor, the
  override's own type), ``declare_parameter``, ``set_descriptor`` (type checks, alternative
  value), ``describe_parameter``, on-set callbacks; ``use_sim_time`` makes ``get_clock()``
  follow ``/clock``; ``get_logger()`` writes to a ``/rosout`` record filtered by ``--log-level``;
  guard conditions; ``destroy_service`` after which a response still to be sent raises
  ``InvalidHandle`` (as rclpy's ``send_response`` does);
* executors whose ``spin`` runs callbacks on threads, honouring mutually exclusive groups over
  take + callback + response; an exception out of a callback ends ``spin``; and, like rclpy
  up to 7.1.11, ``shutdown(timeout_sec)`` returns at once without waiting for callbacks;
* messages are delivered as copies (as DDS would); ``call_async`` futures' done-callbacks run
  on an executor thread;
* ``rclpy.action.ActionClient`` (``test/ros_fake_action.py``): a goal is known from its goal
  response on, status entries of unknown goals are dropped, as rclpy's client does.

``install(monkeypatch)`` puts the fake modules in ``sys.modules`` and returns the fake ``rclpy``.
"""
from __future__ import annotations

import copy
import enum
import sys
import threading
import time
import types
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace
from typing import Any

import pytest

from ros_fake_args import InvalidHandle, RCLError, RosArguments, UnknownROSArgsError
from ros_fake_msgs import *  # noqa: F403 - the fake interface packages, re-exported for the tests
from ros_fake_msgs import (  # noqa: F401
    INTERFACE_MODULES,
    ClockMessage,
    ParameterDescriptor,
    ParameterValue,
    SetParametersResult,
    Time,
    message_class,
    resolve,
)

# ====================================================================================== QoS
class ReliabilityPolicy(enum.Enum):
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.Enum):
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.Enum):
    KEEP_LAST = 1
    KEEP_ALL = 2


class QoSProfile:
    def __init__(self, **kwargs: Any) -> None:
        if "history" not in kwargs and "depth" not in kwargs:
            raise TypeError("A QoSProfile must either have a history or depth setting")
        self.history = kwargs.pop("history", HistoryPolicy.KEEP_LAST)
        self.depth = kwargs.pop("depth", 10)
        self.reliability = kwargs.pop("reliability", ReliabilityPolicy.RELIABLE)
        self.durability = kwargs.pop("durability", DurabilityPolicy.VOLATILE)
        if kwargs:
            raise TypeError(f"unknown QoS settings {sorted(kwargs)}")


# =============================================================================== parameters
class ParameterAlreadyDeclaredException(Exception):
    pass


class InvalidParameterValueException(Exception):
    pass


class ExternalShutdownException(Exception):
    """Raised out of ``spin`` when the context is shut down while spinning (as rclpy does)."""


class Parameter:
    def __init__(self, name: str, type_: Any = None, value: Any = None) -> None:
        self.name = name
        self.type_ = type_
        self.value = value


class SignalHandlerOptions(enum.Enum):
    NO = 0
    SIGINT = 1
    SIGTERM = 2
    ALL = 3




# ================================================================================== futures
class Future:
    """rclpy.task.Future: done-callbacks run when the result is set (on the setting thread here)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._done = False
        self._cancelled = False
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[[Future], None]] = []

    def done(self) -> bool:
        return self._done

    def cancelled(self) -> bool:
        return self._cancelled

    def result(self) -> Any:
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception

    def set_result(self, result: Any) -> None:
        self._finish(result=result)

    def set_exception(self, error: BaseException) -> None:
        self._finish(exception=error)

    def cancel(self) -> None:
        self._finish(cancelled=True)

    def _finish(self, result: Any = None, exception: BaseException | None = None, cancelled: bool = False) -> None:
        with self._lock:
            if self._done:
                return
            self._result, self._exception, self._cancelled, self._done = result, exception, cancelled, True
            callbacks, self._callbacks = self._callbacks, []
        for callback in callbacks:
            callback(self)

    def add_done_callback(self, callback: Callable[[Future], None]) -> None:
        with self._lock:
            if not self._done:
                self._callbacks.append(callback)
                return
        callback(self)


# ============================================================================ the ROS graph
def compatible(offered: QoSProfile, requested: QoSProfile) -> bool:
    """DDS request/offer: a reader may not ask more reliability or durability than the writer gives."""
    if requested.reliability is ReliabilityPolicy.RELIABLE and offered.reliability is ReliabilityPolicy.BEST_EFFORT:
        return False
    if requested.durability is DurabilityPolicy.TRANSIENT_LOCAL and offered.durability is DurabilityPolicy.VOLATILE:
        return False
    return True


class Graph:
    """Everything the middleware would do between nodes of all fake processes, discovery included."""

    def __init__(self, match_delay: float = 0.02) -> None:
        self.lock = threading.RLock()
        self.match_delay = match_delay  # wall seconds from both endpoints existing to their match
        self.subscriptions: dict[str, list[FakeSubscription]] = {}
        self.publishers: dict[str, list[FakePublisher]] = {}
        self.services: dict[str, list[FakeService]] = {}
        self.clients: list[FakeClient] = []
        self.matched: set[tuple[int, int]] = set()
        self.timers: list[threading.Timer] = []
        self.lost: list[tuple[str, Any]] = []  # (topic, message) published to a reader not matched yet

    def discover(self, writer: Any, reader: Any, on_match: Callable[[], None] | None = None) -> None:
        """Match ``writer`` and ``reader`` after the discovery delay (at once with a delay of 0)."""

        def match() -> None:
            with self.lock:
                if writer.destroyed or reader.destroyed:
                    return
                self.matched.add((id(writer), id(reader)))
            if on_match is not None:
                on_match()

        if self.match_delay <= 0:
            match()
            return
        timer = threading.Timer(self.match_delay, match)
        timer.daemon = True
        with self.lock:
            self.timers.append(timer)
        timer.start()

    def is_matched(self, writer: Any, reader: Any) -> bool:
        with self.lock:
            return (id(writer), id(reader)) in self.matched

    def close(self) -> None:
        with self.lock:
            for timer in self.timers:
                timer.cancel()
            self.timers.clear()


GRAPH = Graph()


class _Context:
    def __init__(self) -> None:
        self.initialised = False
        self.args: list[str] = []
        self.ros_args = RosArguments([])
        self.init_kwargs: dict[str, Any] = {}
        self.on_shutdown_callbacks: list[Callable[[], None]] = []
        self.init_count = 0
        self.shutdown_count = 0

    def ok(self) -> bool:
        return self.initialised

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self.on_shutdown_callbacks.append(callback)


CONTEXT = _Context()
ROSOUT: list[tuple[str, int, str]] = []  # (logger name, severity, message) of every log that passed its level


def init(*, args: list[str] | None = None, context: Any = None, domain_id: int | None = None, signal_handler_options: Any = None) -> None:
    if CONTEXT.initialised:
        raise RuntimeError("rcl_init called while already initialized")
    argv = list(args if args is not None else sys.argv)
    ros_args = RosArguments(argv)  # raises RCLError / UnknownROSArgsError as rcl_init does
    CONTEXT.initialised = True
    CONTEXT.args = argv
    CONTEXT.ros_args = ros_args
    CONTEXT.init_kwargs = {"args": args, "signal_handler_options": signal_handler_options}
    CONTEXT.init_count += 1


def ok(context: Any = None) -> bool:
    return CONTEXT.ok()


def shutdown(context: Any = None) -> None:
    if not CONTEXT.initialised:
        raise RuntimeError("rcl_shutdown already called on the given context")
    CONTEXT.initialised = False
    CONTEXT.shutdown_count += 1
    for callback in list(CONTEXT.on_shutdown_callbacks):
        callback()


def remove_ros_args(args: list[str] | None = None) -> list[str]:
    out: list[str] = []
    in_ros = False
    for arg in args if args is not None else sys.argv:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--" and in_ros:
            in_ros = False
        elif not in_ros:
            out.append(arg)
    return out


# ================================================================================ callbacks
class MutuallyExclusiveCallbackGroup:
    exclusive = True


class ReentrantCallbackGroup:
    exclusive = False


class _Entity:
    """Something with an rmw queue the executor takes work from, one item at a time."""

    def __init__(self, node: FakeNode, callback_group: Any) -> None:
        self.node = node
        self.callback_group = callback_group or node.default_callback_group
        self.queue: deque[Any] = deque()
        self.destroyed = False

    def push(self, item: Any) -> None:
        executor = self.node.executor
        if executor is None:
            with GRAPH.lock:
                self.queue.append(item)
            return
        with executor.cond:
            self.queue.append(item)
            executor.cond.notify_all()

    def run(self, item: Any) -> None:
        raise NotImplementedError


def ros_type_name(msg_type: type) -> str:
    """``std_msgs/msg/String`` for the fake String class (what rclpy's graph calls reports)."""
    for module, classes in INTERFACE_MODULES.items():
        for name, cls in classes.items():
            if cls is msg_type:
                return module.replace(".", "/") + "/" + name
    return "unknown/msg/Unknown"


class FakePublisher:
    def __init__(self, node: FakeNode, msg_type: type, topic: str, qos: QoSProfile) -> None:
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


class FakeSubscription(_Entity):
    def __init__(self, node: FakeNode, msg_type: type, topic: str, callback: Callable[[Any], None], qos: QoSProfile, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.msg_type, self.topic, self.callback, self.qos = msg_type, topic, callback, qos

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


class FakeService(_Entity):
    def __init__(self, node: FakeNode, srv_type: Any, name: str, callback: Callable[[Any, Any], Any], callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.srv_type, self.name, self.callback = srv_type, name, callback

    def run(self, item: Any) -> None:
        request, client, sequence = item
        response = self.callback(request, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):  # rclpy's send_response does the same
            raise TypeError(f"service {self.name} callback returned {type(response).__name__}")
        if self.destroyed:  # rclpy: `with self.handle:` in send_response on a destroyed service
            raise InvalidHandle(f"cannot use Destroyable because destruction was requested (service {self.name})")
        if not client.destroyed:
            client.push((sequence, copy.deepcopy(response)))


class FakeGuardCondition(_Entity):
    def __init__(self, node: FakeNode, callback: Callable[[], Any], callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.callback = callback

    def trigger(self) -> None:
        if self.destroyed:
            raise InvalidHandle("cannot use Destroyable because destruction was requested (guard condition)")
        self.push(None)

    def run(self, item: Any) -> None:
        self.callback()


class FakeClient(_Entity):
    def __init__(self, node: FakeNode, srv_type: Any, name: str, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.srv_type, self.name = srv_type, name
        self.pending: dict[int, Future] = {}
        self.removed: list[Future] = []
        self._sequence = 0

    def _servers(self) -> list[FakeService]:
        with GRAPH.lock:
            return [s for s in GRAPH.services.get(self.name, []) if not s.destroyed and GRAPH.is_matched(self, s)]

    def service_is_ready(self) -> bool:
        return bool(self._servers())

    def call_async(self, request: Any) -> Future:
        if not isinstance(request, self.srv_type.Request):
            raise TypeError()
        future = Future()
        with GRAPH.lock:
            self._sequence += 1
            self.pending[self._sequence] = future
            servers = self._servers()
        for server in servers[:1]:  # a request written before the match is lost, as over DDS
            server.push((copy.deepcopy(request), self, self._sequence))
        return future

    def remove_pending_request(self, future: Future) -> None:
        with GRAPH.lock:
            for sequence, pending in list(self.pending.items()):
                if pending is future:
                    del self.pending[sequence]
                    self.removed.append(future)

    def run(self, item: Any) -> None:
        sequence, response = item
        with GRAPH.lock:
            future = self.pending.pop(sequence, None)
        if future is not None:
            future.set_result(response)


# ============================================================================= time, logging
class FakeTime:
    """rclpy.time.Time, as far as the adapter reads it."""

    def __init__(self, nanoseconds: int) -> None:
        self.nanoseconds = nanoseconds

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return divmod(self.nanoseconds, 1_000_000_000)


class FakeClock:
    """A node's ROS clock: system time, or the last ``/clock`` (0 before one) with use_sim_time."""

    def __init__(self) -> None:
        self.ros_time_is_active = False
        self.sim_nanoseconds = 0

    def now(self) -> FakeTime:
        return FakeTime(self.sim_nanoseconds if self.ros_time_is_active else time.time_ns())


class FakeLogger:
    """rclpy's RcutilsLogger: severities as ints, a level from ``--log-level``, records on /rosout.

    As in rclpy, each call site (the first frame outside rclpy: file, function, line, bytecode
    offset) keeps the severity of its first call; logging at another severity from the same
    site raises ValueError."""

    def __init__(self, name: str, level: int) -> None:
        self.name = name
        self.level = level
        self.contexts: dict[tuple[str, str, int, int], int] = {}

    def get_effective_level(self) -> int:
        return self.level

    def is_enabled_for(self, severity: int) -> bool:
        return severity >= self.level

    def log(self, message: str, severity: int, **kwargs: Any) -> bool:
        if severity not in (10, 20, 30, 40, 50):
            raise ValueError(f"{severity} is not a valid LoggingSeverity")
        if not isinstance(message, str):
            raise TypeError("message must be a string")
        if not self.is_enabled_for(severity):
            return False
        frame = sys._getframe(1)
        while frame.f_code.co_filename == __file__:  # rclpy's _find_caller: skip the logger itself
            frame = frame.f_back  # type: ignore[assignment]
        caller = (frame.f_code.co_filename, frame.f_code.co_name, frame.f_lineno, frame.f_lasti)
        if self.contexts.setdefault(caller, severity) != severity:
            raise ValueError("Logger severity cannot be changed between calls.")
        ROSOUT.append((self.name, severity, message))
        return True

    def debug(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 10, **kwargs)

    def info(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 20, **kwargs)

    def warning(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 30, **kwargs)

    def error(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 40, **kwargs)

    def fatal(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 50, **kwargs)


# ===================================================================================== nodes
_TYPE_CODES = {bool: 1, int: 2, float: 3, str: 4}
_VALUE_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
                 6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value", 9: "string_array_value"}


def type_code(value: Any) -> int:
    """rcl_interfaces/ParameterType of a Python value, as rclpy's Parameter.Type.from_parameter_value."""
    if value is None:
        return 0
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        return {bool: 6, int: 7, float: 8, str: 9}.get(next(iter(kinds)), 9) if len(kinds) == 1 else 9
    return _TYPE_CODES[type(value)]


class PublisherEventCallbacks:
    """rclpy.event_handler: ``use_default_callbacks`` adds rclpy's warning handlers (one waitable each)."""

    def __init__(self, *, use_default_callbacks: bool = True, **callbacks: Any) -> None:
        self.use_default_callbacks = use_default_callbacks
        self.callbacks = callbacks


class SubscriptionEventCallbacks(PublisherEventCallbacks):
    pass


class ParameterNotDeclaredException(Exception):
    pass


class FakeNode:
    def __init__(
        self,
        node_name: str,
        *,
        context: Any = None,
        cli_args: list[str] | None = None,
        namespace: str | None = None,
        use_global_arguments: bool = True,
        enable_rosout: bool = True,
        start_parameter_services: bool = True,
        parameter_overrides: list[Parameter] | None = None,
        allow_undeclared_parameters: bool = False,
        automatically_declare_parameters_from_overrides: bool = False,
        enable_logger_service: bool = False,
    ) -> None:
        if not CONTEXT.ok():
            raise RuntimeError("NotInitializedException: cannot create node")
        ros_args = CONTEXT.ros_args
        self._name = ros_args.remaps.get("__node", node_name)
        self._namespace = ros_args.remaps.get("__ns", namespace or "/")
        fqn = f"{self._namespace.rstrip('/')}/{self._name}"
        self.default_callback_group = MutuallyExclusiveCallbackGroup()
        self.executor: FakeExecutor | None = None
        self._parameters: dict[str, Parameter] = {}
        self._descriptors: dict[str, Any] = {}
        self._callbacks: list[Callable[[list[Parameter]], Any]] = []
        self.publishers: list[FakePublisher] = []
        self.entities: list[_Entity] = []
        self.destroyed = False
        self._overrides = {k: Parameter(k, value=v) for k, v in ros_args.parameters_for(fqn).items()}
        self._overrides.update({p.name: p for p in parameter_overrides or []})
        if automatically_declare_parameters_from_overrides:
            for name, param in self._overrides.items():
                self.declare_parameter(name, param.value, ParameterDescriptor())
        for name, default in (("use_sim_time", False), ("start_type_description_service", True)):
            if name not in self._parameters:
                self.declare_parameter(name, default)
        self._clock = FakeClock()
        if self._parameters["use_sim_time"].value is True:  # rclpy's TimeSource
            self._clock.ros_time_is_active = True
            self.create_subscription(ClockMessage, "/clock", self._on_clock, QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        logger_name = fqn.strip("/").replace("/", ".")
        self._logger = FakeLogger(logger_name, CONTEXT.ros_args.log_level or 20)

    def _on_clock(self, msg: Any) -> None:
        self._clock.sim_nanoseconds = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

    def get_name(self) -> str:
        return self._name

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic with a publisher or a subscription, with its ROS type names (as rclpy)."""
        with GRAPH.lock:
            endpoints = [(t, e.msg_type) for table in (GRAPH.publishers, GRAPH.subscriptions) for t, es in table.items() for e in es]
        found: dict[str, set[str]] = {}
        for topic, msg_type in endpoints:
            found.setdefault(topic, set()).add(ros_type_name(msg_type))
        return sorted((topic, sorted(types)) for topic, types in found.items())

    def get_publishers_info_by_topic(self, topic_name: str) -> list[Any]:
        """rclpy's TopicEndpointInfo, as far as a recorder reads it: the offered QoS."""
        with GRAPH.lock:
            return [SimpleNamespace(qos_profile=p.qos, node_name=p.node._name) for p in GRAPH.publishers.get(topic_name, []) if not p.destroyed]

    def get_namespace(self) -> str:
        return self._namespace

    def get_clock(self) -> FakeClock:
        return self._clock

    def get_logger(self) -> FakeLogger:
        return self._logger

    # parameters
    def _set(self, name: str, value: Any) -> None:
        for callback in self._callbacks:
            result = callback([Parameter(name, value=value)])
            if not result.successful:
                raise InvalidParameterValueException(f"{name}: {result.reason}")
        self._parameters[name] = Parameter(name, value=value)

    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None, ignore_override: bool = False) -> Parameter:
        if name in self._parameters:
            raise ParameterAlreadyDeclaredException(name)
        if not ignore_override and name in self._overrides:
            value = self._overrides[name].value
        descriptor = descriptor if descriptor is not None else ParameterDescriptor()
        if descriptor.type not in (0, type_code(value)) and not descriptor.dynamic_typing:
            raise InvalidParameterValueException(f"{name}: Wrong parameter type, expected '{descriptor.type}' got '{type_code(value)}'")
        descriptor.type = type_code(value)
        descriptor.name = name
        self._set(name, value)
        self._descriptors[name] = descriptor
        return self._parameters[name]

    def set_descriptor(self, name: str, descriptor: Any, alternative_value: Any = None) -> Any:
        """rclpy: keep the value if it has the descriptor's type, else take the alternative; no callbacks."""
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        descriptor.name = name
        candidates = [self._parameters[name].value]
        if alternative_value is not None:
            field = _VALUE_FIELDS.get(alternative_value.type)
            candidates.append(None if field is None else getattr(alternative_value, field))
        for value in candidates:
            if descriptor.dynamic_typing or type_code(value) == descriptor.type:
                self._parameters[name] = Parameter(name, value=list(value) if isinstance(value, (list, tuple)) or hasattr(value, "typecode") else value)
                self._descriptors[name] = descriptor
                return alternative_value
        raise InvalidParameterValueException(f"{name}: Wrong parameter type, expected '{descriptor.type}'")

    def describe_parameter(self, name: str) -> Any:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        return self._parameters[name]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        return {n: p for n, p in self._parameters.items() if n.startswith(prefix)}

    def add_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        self._callbacks.append(callback)

    def set_parameters(self, parameters: list[Parameter]) -> list[Any]:
        results = []
        for param in parameters:
            result = SetParametersResult(successful=True)
            for callback in self._callbacks:
                result = callback([param])
                if not result.successful:
                    break
            if result.successful:
                self._parameters[param.name] = param
            results.append(result)
        return results

    # endpoints
    def create_publisher(
        self, msg_type: type, topic: str, qos_profile: QoSProfile, *, callback_group: Any = None, event_callbacks: Any = None
    ) -> FakePublisher:
        pub = FakePublisher(self, msg_type, topic, qos_profile)
        with GRAPH.lock:
            GRAPH.publishers.setdefault(topic, []).append(pub)
            readers = list(GRAPH.subscriptions.get(topic, []))
        self.publishers.append(pub)
        for sub in readers:
            GRAPH.discover(pub, sub, lambda s=sub: _replay(pub, s))
        return pub

    def create_subscription(
        self, msg_type: type, topic: str, callback: Callable[[Any], None], qos_profile: QoSProfile, *, callback_group: Any = None, event_callbacks: Any = None
    ) -> FakeSubscription:
        sub = FakeSubscription(self, msg_type, topic, callback, qos_profile, callback_group)
        sub.event_callbacks = event_callbacks
        with GRAPH.lock:
            GRAPH.subscriptions.setdefault(topic, []).append(sub)
            writers = list(GRAPH.publishers.get(topic, []))
        self.entities.append(sub)
        for pub in writers:
            GRAPH.discover(pub, sub, lambda p=pub: _replay(p, sub))
        return sub

    def create_service(self, srv_type: Any, srv_name: str, callback: Callable[[Any, Any], Any], *, qos_profile: Any = None, callback_group: Any = None) -> FakeService:
        srv = FakeService(self, srv_type, srv_name, callback, callback_group)
        with GRAPH.lock:
            GRAPH.services.setdefault(srv_name, []).append(srv)
            clients = [c for c in GRAPH.clients if c.name == srv_name]
        self.entities.append(srv)
        for client in clients:
            GRAPH.discover(client, srv)
        return srv

    def create_client(self, srv_type: Any, srv_name: str, *, qos_profile: Any = None, callback_group: Any = None) -> FakeClient:
        client = FakeClient(self, srv_type, srv_name, callback_group)
        with GRAPH.lock:
            GRAPH.clients.append(client)
            servers = list(GRAPH.services.get(srv_name, []))
        self.entities.append(client)
        for srv in servers:
            GRAPH.discover(client, srv)
        return client

    def create_guard_condition(self, callback: Callable[[], Any], callback_group: Any = None) -> FakeGuardCondition:
        guard = FakeGuardCondition(self, callback, callback_group)
        self.entities.append(guard)
        return guard

    def destroy_guard_condition(self, guard: FakeGuardCondition) -> bool:
        guard.destroyed = True
        return True

    def destroy_subscription(self, sub: FakeSubscription) -> bool:
        sub.destroyed = True
        with GRAPH.lock:
            if sub in GRAPH.subscriptions.get(sub.topic, []):
                GRAPH.subscriptions[sub.topic].remove(sub)
        return True

    def destroy_publisher(self, pub: FakePublisher) -> bool:
        pub.destroyed = True
        with GRAPH.lock:
            if pub in GRAPH.publishers.get(pub.topic, []):
                GRAPH.publishers[pub.topic].remove(pub)
        return True

    def destroy_service(self, srv: FakeService) -> bool:
        srv.destroyed = True
        with GRAPH.lock:
            if srv in GRAPH.services.get(srv.name, []):
                GRAPH.services[srv.name].remove(srv)
        return True

    def destroy_client(self, client: FakeClient) -> bool:
        client.destroyed = True
        with GRAPH.lock:
            if client in GRAPH.clients:
                GRAPH.clients.remove(client)
        return True

    def destroy_node(self) -> None:
        self.destroyed = True
        for pub in self.publishers:
            self.destroy_publisher(pub)
        for entity in self.entities:
            if isinstance(entity, FakeSubscription):
                self.destroy_subscription(entity)
            elif isinstance(entity, FakeService):
                self.destroy_service(entity)
            elif isinstance(entity, FakeClient):
                self.destroy_client(entity)
            entity.destroyed = True


def _replay(pub: FakePublisher, sub: FakeSubscription) -> None:
    """At the match: a TRANSIENT_LOCAL reader gets the writer's history, as DDS delivers it."""
    if sub.qos.durability is DurabilityPolicy.TRANSIENT_LOCAL and compatible(pub.qos, sub.qos):
        with GRAPH.lock:
            history = list(pub.history)
        for msg in history:
            sub.receive(copy.deepcopy(msg))


# ================================================================================= executors
class FakeExecutor:
    """Runs callbacks of its nodes on threads; ``spin`` ends on shutdown or on a callback's exception."""

    def __init__(self, num_threads: int | None = None, *, context: Any = None) -> None:
        self.num_threads = num_threads or 2
        self.cond = threading.Condition()
        self.nodes: list[FakeNode] = []
        self._is_shutdown = False
        self._groups_running: set[int] = set()
        self._in_flight = 0
        self._error: BaseException | None = None
        self.spin_threads: set[int] = set()
        self.callback_threads: set[int] = set()
        CONTEXT.on_shutdown(self.wake)

    @property
    def in_flight(self) -> int:
        return self._in_flight

    def wake(self) -> None:
        with self.cond:
            self.cond.notify_all()

    def add_node(self, node: FakeNode) -> bool:
        with self.cond:
            if node in self.nodes:
                return False
            self.nodes.append(node)
            node.executor = self
            self.cond.notify_all()
        return True

    def remove_node(self, node: FakeNode) -> None:
        with self.cond:
            if node in self.nodes:
                self.nodes.remove(node)
            self.cond.notify_all()

    def _next(self) -> tuple[_Entity, Any] | None:
        for node in self.nodes:
            for entity in node.entities:
                group = entity.callback_group
                if not entity.queue or entity.destroyed:
                    continue
                if group.exclusive and id(group) in self._groups_running:
                    continue
                # As in rclpy, only a mutually exclusive group serialises callbacks: a reentrant
                # entity is taken again while its previous callback still runs.
                if group.exclusive:
                    self._groups_running.add(id(group))
                self._in_flight += 1
                return entity, entity.queue.popleft()
        return None

    def _run(self, entity: _Entity, item: Any) -> None:
        self.callback_threads.add(threading.get_ident())
        try:
            entity.run(item)
        except BaseException as error:  # rclpy re-raises it out of spin
            with self.cond:
                self._error = self._error or error
        finally:
            with self.cond:
                self._groups_running.discard(id(entity.callback_group))
                self._in_flight -= 1
                self.cond.notify_all()

    def spin(self) -> None:
        self.spin_threads.add(threading.get_ident())
        pool = ThreadPoolExecutor(max_workers=self.num_threads, thread_name_prefix="fake executor")
        try:
            with self.cond:
                while not self._is_shutdown:
                    if not CONTEXT.ok():
                        raise ExternalShutdownException()
                    if self._error is not None:
                        error, self._error = self._error, None
                        raise error
                    work = self._next()
                    if work is None:
                        self.cond.wait()
                        continue
                    pool.submit(self._run, *work)
        finally:
            pool.shutdown(wait=False)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """rclpy <= 7.1.11: stops spinning and returns True at once, whatever is still running
        (the wait it documents is skipped by a bug fixed in 7.1.12)."""
        with self.cond:
            self._is_shutdown = True
            self.nodes = []
            self.cond.notify_all()
        return True


MultiThreadedExecutor = FakeExecutor


# ================================================================================ installing
def _module(name: str, **attributes: Any) -> types.ModuleType:
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    return module


def install(monkeypatch: Any) -> types.ModuleType:
    """Put the fake rclpy and interface packages in ``sys.modules``; a fresh graph and context."""
    global GRAPH, CONTEXT
    GRAPH.close()
    GRAPH = Graph()
    CONTEXT = _Context()
    ROSOUT.clear()
    rclpy = _module("rclpy", init=init, ok=ok, shutdown=shutdown, graph=lambda: GRAPH, context=lambda: CONTEXT)
    submodules = {
        "rclpy.node": _module("rclpy.node", Node=FakeNode),
        "rclpy.executors": _module(
            "rclpy.executors", MultiThreadedExecutor=MultiThreadedExecutor, ExternalShutdownException=ExternalShutdownException
        ),
        "rclpy.callback_groups": _module(
            "rclpy.callback_groups", MutuallyExclusiveCallbackGroup=MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup=ReentrantCallbackGroup
        ),
        "rclpy.parameter": _module("rclpy.parameter", Parameter=Parameter),
        "rclpy.qos": _module(
            "rclpy.qos", QoSProfile=QoSProfile, ReliabilityPolicy=ReliabilityPolicy, DurabilityPolicy=DurabilityPolicy, HistoryPolicy=HistoryPolicy
        ),
        "rclpy.signals": _module("rclpy.signals", SignalHandlerOptions=SignalHandlerOptions),
        "rclpy.utilities": _module("rclpy.utilities", remove_ros_args=remove_ros_args),
        "rclpy.task": _module("rclpy.task", Future=Future),
        "rclpy.event_handler": _module(
            "rclpy.event_handler", PublisherEventCallbacks=PublisherEventCallbacks, SubscriptionEventCallbacks=SubscriptionEventCallbacks
        ),
    }
    import ros_fake_action  # it builds on this module: imported once the module is complete

    submodules["rclpy.action"] = _module("rclpy.action", ActionClient=ros_fake_action.ActionClient)
    for name, module in submodules.items():
        setattr(rclpy, name.split(".", 1)[1], module)
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setitem(sys.modules, "rclpy", rclpy)
    for module_name, classes in INTERFACE_MODULES.items():
        package = module_name.split(".")[0]
        monkeypatch.setitem(sys.modules, package, _module(package))
        monkeypatch.setitem(sys.modules, module_name, _module(module_name, **classes))
    return rclpy


@pytest.fixture
def fake_rclpy(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    """The fake rclpy installed for one test (import this fixture into a test module)."""
    yield install(monkeypatch)
    GRAPH.close()
