"""A small stand-in for rclpy and the interface packages, for testing the ros transport without ROS 2.

It models the documented behaviour the adapter relies on, not rclpy's internals:

* message classes shaped like rosidl's: ``__slots__``, keyword constructors that refuse unknown
  fields, setters that refuse a wrong Python type (an ``int`` for a ``float64``), numeric
  sequences stored as ``array.array``, ``get_fields_and_field_types()``; services expose
  ``Request`` / ``Response`` on the service class only;
* ``rclpy.init(*, args, signal_handler_options)``, ``ok``, ``shutdown`` (which raises when not
  initialised), ``utilities.remove_ros_args``; ``-p name:=value`` and ``-r __node:=name`` in the
  init args become parameter overrides and a node rename;
* ``Node`` with parameter overrides (and automatic declaration), ``declare_parameter`` (raising
  when declared twice), on-set callbacks, publishers, subscriptions, services, clients;
* executors whose ``spin`` runs callbacks on threads; a MultiThreadedExecutor honours
  mutually-exclusive and reentrant callback groups; an exception out of a callback ends ``spin``
  (as in rclpy); ``shutdown(timeout_sec)`` waits for callbacks in flight;
* a process-wide graph that delivers a *copy* of each message (as DDS would), replays
  TRANSIENT_LOCAL history to late subscribers, and routes service requests and responses;
  ``call_async`` returns a future whose done-callbacks run on an executor thread.

``install(monkeypatch)`` puts the fake modules in ``sys.modules`` and returns the fake ``rclpy``.
"""
from __future__ import annotations

import array
import copy
import enum
import sys
import threading
import types
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

from ros_fake_msgs import *  # noqa: F403 - the fake interface packages, re-exported for the tests
from ros_fake_msgs import INTERFACE_MODULES, SetParametersResult, message_class, resolve  # noqa: F401


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


def _parse_value(text: str) -> Any:
    if text in ("true", "false"):
        return text == "true"
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


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
class Graph:
    """Everything the middleware would do between nodes of all fake processes."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.subscriptions: dict[str, list[FakeSubscription]] = {}
        self.publishers: dict[str, list[FakePublisher]] = {}
        self.services: dict[str, FakeService] = {}
        self.clients: list[FakeClient] = []


GRAPH = Graph()


class _Context:
    def __init__(self) -> None:
        self.initialised = False
        self.args: list[str] = []
        self.init_kwargs: dict[str, Any] = {}
        self.on_shutdown_callbacks: list[Callable[[], None]] = []
        self.init_count = 0
        self.shutdown_count = 0

    def ok(self) -> bool:
        return self.initialised

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self.on_shutdown_callbacks.append(callback)


CONTEXT = _Context()


def init(*, args: list[str] | None = None, context: Any = None, domain_id: int | None = None, signal_handler_options: Any = None) -> None:
    if CONTEXT.initialised:
        raise RuntimeError("rcl_init called while already initialized")
    CONTEXT.initialised = True
    CONTEXT.args = list(args if args is not None else sys.argv)
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


def _ros_args(args: list[str]) -> tuple[dict[str, Any], dict[str, str]]:
    """``-p name:=value`` parameters and ``-r from:=to`` remaps of the ROS part of ``args``."""
    params: dict[str, Any] = {}
    remaps: dict[str, str] = {}
    in_ros = False
    it = iter(args)
    for arg in it:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and arg in ("-p", "-r"):
            key, _, value = next(it).partition(":=")
            if arg == "-p":
                params[key] = _parse_value(value)
            else:
                remaps[key] = value
    return params, remaps


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


class FakePublisher:
    def __init__(self, node: FakeNode, msg_type: type, topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic, self.qos = node, msg_type, topic, qos
        self.history: deque[Any] = deque(maxlen=qos.depth if qos.durability is DurabilityPolicy.TRANSIENT_LOCAL else 0)
        self.published: list[Any] = []

    def get_subscription_count(self) -> int:
        with GRAPH.lock:
            return len(GRAPH.subscriptions.get(self.topic, []))

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"publisher on {self.topic} expects {self.msg_type.__name__}")
        self.published.append(msg)
        with GRAPH.lock:
            self.history.append(msg)
            subscriptions = list(GRAPH.subscriptions.get(self.topic, []))
        for sub in subscriptions:
            sub.receive(copy.deepcopy(msg))


class FakeSubscription(_Entity):
    def __init__(self, node: FakeNode, msg_type: type, topic: str, callback: Callable[[Any], None], qos: QoSProfile, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.msg_type, self.topic, self.callback, self.qos = msg_type, topic, callback, qos

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
        client.push((sequence, copy.deepcopy(response)))


class FakeClient(_Entity):
    def __init__(self, node: FakeNode, srv_type: Any, name: str, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.srv_type, self.name = srv_type, name
        self.pending: dict[int, Future] = {}
        self.removed: list[Future] = []
        self._sequence = 0

    def service_is_ready(self) -> bool:
        with GRAPH.lock:
            return self.name in GRAPH.services

    def call_async(self, request: Any) -> Future:
        if not isinstance(request, self.srv_type.Request):
            raise TypeError()
        future = Future()
        with GRAPH.lock:
            self._sequence += 1
            self.pending[self._sequence] = future
            server = GRAPH.services.get(self.name)
        if server is not None:
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


# ===================================================================================== nodes
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
        params, remaps = _ros_args(CONTEXT.args)
        self._name = remaps.get("__node", node_name)
        self._namespace = remaps.get("__ns", namespace or "/")
        self.default_callback_group = MutuallyExclusiveCallbackGroup()
        self.executor: FakeExecutor | None = None
        self._parameters: dict[str, Parameter] = {}
        self._callbacks: list[Callable[[list[Parameter]], Any]] = []
        self.publishers: list[FakePublisher] = []
        self.entities: list[_Entity] = []
        self.destroyed = False
        self.descriptions: dict[str, str] = {}
        self._overrides = {k: Parameter(k, value=v) for k, v in params.items()}
        self._overrides.update({p.name: p for p in parameter_overrides or []})
        if automatically_declare_parameters_from_overrides:
            for name, param in self._overrides.items():
                self._set(name, param.value)
        for name, default in (("use_sim_time", False), ("start_type_description_service", True)):
            if name not in self._parameters:
                self.declare_parameter(name, default)

    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

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
        self._set(name, value)
        if descriptor is not None:
            self.descriptions[name] = descriptor.description
        return self._parameters[name]

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
    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile, *, callback_group: Any = None) -> FakePublisher:
        pub = FakePublisher(self, msg_type, topic, qos_profile)
        with GRAPH.lock:
            GRAPH.publishers.setdefault(topic, []).append(pub)
        self.publishers.append(pub)
        return pub

    def create_subscription(self, msg_type: type, topic: str, callback: Callable[[Any], None], qos_profile: QoSProfile, *, callback_group: Any = None) -> FakeSubscription:
        sub = FakeSubscription(self, msg_type, topic, callback, qos_profile, callback_group)
        with GRAPH.lock:
            GRAPH.subscriptions.setdefault(topic, []).append(sub)
            latched = [
                m for pub in GRAPH.publishers.get(topic, [])
                if qos_profile.durability is DurabilityPolicy.TRANSIENT_LOCAL for m in pub.history
            ]
        for msg in latched:
            sub.receive(copy.deepcopy(msg))
        self.entities.append(sub)
        return sub

    def create_service(self, srv_type: Any, srv_name: str, callback: Callable[[Any, Any], Any], *, qos_profile: Any = None, callback_group: Any = None) -> FakeService:
        srv = FakeService(self, srv_type, srv_name, callback, callback_group)
        with GRAPH.lock:
            GRAPH.services[srv_name] = srv
        self.entities.append(srv)
        return srv

    def create_client(self, srv_type: Any, srv_name: str, *, qos_profile: Any = None, callback_group: Any = None) -> FakeClient:
        client = FakeClient(self, srv_type, srv_name, callback_group)
        with GRAPH.lock:
            GRAPH.clients.append(client)
        self.entities.append(client)
        return client

    def destroy_subscription(self, sub: FakeSubscription) -> bool:
        sub.destroyed = True
        with GRAPH.lock:
            if sub in GRAPH.subscriptions.get(sub.topic, []):
                GRAPH.subscriptions[sub.topic].remove(sub)
        return True

    def destroy_publisher(self, pub: FakePublisher) -> bool:
        with GRAPH.lock:
            if pub in GRAPH.publishers.get(pub.topic, []):
                GRAPH.publishers[pub.topic].remove(pub)
        return True

    def destroy_client(self, client: FakeClient) -> bool:
        client.destroyed = True
        with GRAPH.lock:
            if client in GRAPH.clients:
                GRAPH.clients.remove(client)
        return True

    def destroy_node(self) -> None:
        self.destroyed = True
        with GRAPH.lock:
            for pub in self.publishers:
                if pub in GRAPH.publishers.get(pub.topic, []):
                    GRAPH.publishers[pub.topic].remove(pub)
            for entity in self.entities:
                entity.destroyed = True
                if isinstance(entity, FakeSubscription) and entity in GRAPH.subscriptions.get(entity.topic, []):
                    GRAPH.subscriptions[entity.topic].remove(entity)
                if isinstance(entity, FakeService) and GRAPH.services.get(entity.name) is entity:
                    del GRAPH.services[entity.name]
                if isinstance(entity, FakeClient) and entity in GRAPH.clients:
                    GRAPH.clients.remove(entity)


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
        with self.cond:
            self._is_shutdown = True
            self.cond.notify_all()
            done = self.cond.wait_for(lambda: self._in_flight == 0, timeout=timeout_sec)
            if done:
                self.nodes = []
        return bool(done)


MultiThreadedExecutor = FakeExecutor


# ================================================================================ installing
def _module(name: str, **attributes: Any) -> types.ModuleType:
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    return module


def install(monkeypatch: Any) -> types.ModuleType:
    """Put the fake rclpy and interface packages in ``sys.modules``; a fresh graph and context."""
    global GRAPH, CONTEXT
    GRAPH = Graph()
    CONTEXT = _Context()
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
    }
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
def fake_rclpy(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """The fake rclpy installed for one test (import this fixture into a test module)."""
    return install(monkeypatch)
