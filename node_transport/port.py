"""The transport port: the only way nodes of this project talk to each other.

The engine, every group machine and every bridge is a :class:`Node`; they share nothing but
topics and services, even when they run in one process.  That keeps the in-process deployment
(the embedded default, used by the tests) and a ROS 2 deployment (each node its own process,
rclpy underneath) the same program.  The API follows rclpy's shape -- ``create_publisher``,
``create_subscription``, ``create_service``, ``create_client``, ``declare_parameter`` -- with
two deliberate differences: callbacks run on the node's asyncio loop, and service handlers and
client calls are coroutines.

Faults inside callbacks never vanish: a transport catches them and hands them to the node's
fault handler (by default: log at ERROR), which a group machine turns into ErrorHandling.
"""
from __future__ import annotations

import logging
import re
from abc import ABC, abstractmethod
from dataclasses import dataclass
from collections.abc import Awaitable, Callable, Iterable, Mapping
from typing import Any, Generic, TypeVar

from node_transport.clock import Clock
from node_transport.msgs import Time
from node_transport.parameters import NumericRange, ParameterTypeError, ParameterValue, coerce_parameter
from node_transport.qos import COMMANDS, QoS

M = TypeVar("M")
Req = TypeVar("Req")
Resp = TypeVar("Resp")

FaultHandler = Callable[[str, BaseException], None]


@dataclass(frozen=True)
class ParameterChange:
    """How a parameter that may change while the node runs takes a new value: ``check`` says why a
    value is refused ("" when it is not; any thread, no side effect), ``apply`` takes it (on the node's loop)."""

    check: Callable[[ParameterValue], str]
    apply: Callable[[ParameterValue], None]

_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_ABSOLUTE_NAME = re.compile(rf"^(/{_TOKEN})+$")
_NODE_NAME = re.compile(rf"^{_TOKEN}$")
_NAMESPACE = re.compile(rf"^(/|(/{_TOKEN})+)$")


class TransportError(RuntimeError):
    """A name, type or service problem on the transport, naming the endpoint concerned."""


class RosArgumentsError(TransportError):
    """rcl refused the command line's ROS arguments (``-p speed`` without ``:=``, an unknown flag,
    a params file it cannot parse): the user's to fix, so the process exits with the usage code."""


class ServiceUnavailable(TransportError):
    """No server answered on a service name within the timeout."""


def validate_node_name(name: str) -> str:
    if not _NODE_NAME.match(name):
        raise TransportError(f"invalid node name {name!r}: use letters, digits and '_', not starting with a digit")
    return name


def resolve_name(name: str, namespace: str = "/", node_name: str = "") -> str:
    """Resolve a topic or service name as ROS 2 does: absolute, relative to the namespace, or private (~)."""
    if not _NAMESPACE.match(namespace):
        raise TransportError(f"invalid namespace {namespace!r}")
    base = namespace.rstrip("/")
    if name.startswith("~"):
        if not node_name:
            raise TransportError(f"private name {name!r} needs a node")
        rest = name[1:].lstrip("/")
        resolved = f"{base}/{node_name}" + (f"/{rest}" if rest else "")
    elif name.startswith("/"):
        resolved = name
    else:
        resolved = f"{base}/{name}"
    if not _ABSOLUTE_NAME.match(resolved):
        raise TransportError(
            f"invalid topic or service name {name!r} (resolved {resolved!r}): tokens are letters, digits "
            "and '_', separated by single '/', not starting with a digit, no trailing '/'"
        )
    return resolved


class Publisher(ABC, Generic[M]):
    topic: str
    msg_type: type[M]

    @abstractmethod
    def publish(self, msg: M) -> None:
        """Send ``msg`` to every matching subscription; raises TransportError on a wrong type."""

    @abstractmethod
    def get_subscription_count(self) -> int:
        """How many subscriptions match (rclpy's Publisher.get_subscription_count): lets a node skip
        building messages nobody reads."""

    def _check(self, msg: object) -> None:
        if type(msg) is not self.msg_type:
            raise TransportError(
                f"publisher on {self.topic} carries {self.msg_type.__name__}, got {type(msg).__name__}"
            )


class Subscription(ABC, Generic[M]):
    topic: str
    msg_type: type[M]
    node: Node
    alive: bool
    _callback: Callable[[M], None]

    def _deliver(self, msg: M) -> None:
        """Loop thread: one message to the callback; a fault goes to the node, never up the loop."""
        if not self.alive:
            return
        try:
            self._callback(msg)
        except Exception as error:  # noqa: BLE001 - reported, never swallowed
            self.node.report_fault(f"subscription {self.topic}", error)

    @abstractmethod
    def destroy(self) -> None:
        """Stop receiving."""

    @abstractmethod
    def get_publisher_count(self) -> int:
        """How many publishers match (rclpy's Subscription.get_publisher_count)."""

    def publisher_nodes(self) -> list[str]:
        """Fully qualified names of the nodes whose publishers this subscription matches now, as
        far as the transport can tell (``[]`` when it cannot): lets a watcher name a lost peer."""
        return []


async def wait_until_matched(
    clock: Clock, endpoints: Iterable[Publisher[Any] | Subscription[Any]], timeout: float, poll: float = 0.01
) -> bool:
    """True once every endpoint has matched a peer; False after ``timeout`` run seconds.

    Over DDS, a message published before discovery has matched the reader is lost for a
    volatile topic, and a transient-local one reaches only readers matched in time.  A node
    therefore waits here before the first message of a conversation (a command and the topic
    its answer comes back on), bounded by the same timeout it gives the answer.
    """
    pending = list(endpoints)

    def all_matched() -> bool:
        pending[:] = [e for e in pending if _matched(e) == 0]
        return not pending

    return await poll_until(clock, all_matched, timeout, poll)


async def poll_until(clock: Clock, condition: Callable[[], bool], timeout: float, poll: float = 0.01) -> bool:
    """True once ``condition()`` holds; False after ``timeout`` run seconds (checked every ``poll``)."""
    deadline = clock.now() + timeout
    while not condition():
        remaining = deadline - clock.now()
        if remaining <= 0:
            return False
        await clock.sleep(min(poll, remaining))
    return True


def _matched(endpoint: Publisher[Any] | Subscription[Any]) -> int:
    if isinstance(endpoint, Publisher):
        return endpoint.get_subscription_count()
    return endpoint.get_publisher_count()


@dataclass(frozen=True)
class TopicInfo:
    """One topic of the graph as a recorder sees it (rclpy's ``get_topic_names_and_types`` plus
    ``get_publishers_info_by_topic``): its type and the QoS each publisher offers, so a recorder
    can ask for what every publisher gives (a best-effort publisher only matches a best-effort reader)."""

    name: str
    msg_type: type
    offered: tuple[QoS, ...]


@dataclass(frozen=True)
class Reply:
    """A service handler's answer with work that must wait until the answer is on its way.

    A handler returns it instead of a bare response when something it does next must reach the
    caller *after* the response: an action server publishes a goal's status only once the goal
    response is sent, as rcl_action does, because rclpy's ActionClient learns of a goal from that
    response and drops status entries of goals it does not know.  Every transport writes the
    response, then runs ``then`` on the node's loop (also when the caller stopped waiting).
    """

    response: Any
    then: Callable[[], None]


def unwrap_reply(answer: Any) -> tuple[Any, Callable[[], None] | None]:
    """A handler's answer as (response, follow-up or None)."""
    if isinstance(answer, Reply):
        return answer.response, answer.then
    return answer, None


class ServiceServer(ABC):
    name: str

    @abstractmethod
    def destroy(self) -> None:
        """Stop serving."""


class ServiceClient(ABC, Generic[Req, Resp]):
    name: str

    @abstractmethod
    async def wait_for_service(self, timeout: float) -> bool:
        """True once a server exists; False after ``timeout`` run seconds."""

    @abstractmethod
    async def call(self, request: Req, timeout: float = 5.0) -> Resp:
        """Call the service; raises ServiceUnavailable or TimeoutError after ``timeout`` run seconds."""


class Node(ABC):
    """One participant on the transport, with its own name, parameters and fault handler."""

    transport: Transport  # the transport the node belongs to (set by each adapter)

    def __init__(
        self,
        name: str,
        namespace: str,
        clock: Clock,
        parameter_overrides: Mapping[str, ParameterValue] | None = None,
        override_texts: Mapping[str, str] | None = None,
    ) -> None:
        self.name = validate_node_name(name)
        resolve_name("x", namespace)  # validates the namespace
        self.namespace = namespace
        self.clock = clock
        self.logger = logging.getLogger(f"{namespace.strip('/').replace('/', '.') or 'root'}.{name}")
        self._overrides: dict[str, ParameterValue] = dict(parameter_overrides or {})
        self._override_texts: dict[str, str] = dict(override_texts or {})  # as the user wrote them
        self._parameters: dict[str, ParameterValue] = {}
        self._changeable: dict[str, ParameterChange] = {}  # parameters that may change while the node runs
        self.descriptions: dict[str, str] = {}  # what each declared parameter is (ros2 param describe)
        self.ranges: dict[str, NumericRange] = {}  # the ROS range of each numeric parameter declared with one
        self.fault_handler: FaultHandler = self._log_fault

    @property
    def fully_qualified_name(self) -> str:
        return f"{self.namespace.rstrip('/')}/{self.name}"

    def resolve(self, name: str) -> str:
        return resolve_name(name, self.namespace, self.name)

    def now_stamp(self) -> Time:
        """The node's ROS time for message stamps (``header.stamp``), seconds since 1970.

        The embedded transports derive it from the run clock (:meth:`Clock.epoch_now`); the rclpy
        transport asks the node's ROS clock, which follows ``/clock`` when ``use_sim_time`` is set.
        Run time (``clock.now()``) stays what every duration is measured in.
        """
        return Time.from_seconds(self.clock.epoch_now())

    # ------------------------------------------------------------------------- parameters
    def initial_parameter(self, name: str, default: ParameterValue) -> ParameterValue:
        """The value :meth:`declare_parameter` would give ``name``: its override in the default's type
        (:func:`coerce_parameter`), else the default; TransportError saying how to write it."""
        try:
            return coerce_parameter(self.fully_qualified_name, name, default, self._overrides.get(name, default), self._override_texts.get(name))
        except ParameterTypeError as error:
            raise TransportError(str(error)) from None

    def declare_parameter(
        self, name: str, default: ParameterValue, description: str = "", numeric_range: NumericRange | None = None,
    ) -> ParameterValue:
        """Declare a parameter with a default; an override is converted to its type (:func:`coerce_parameter`).

        ``numeric_range``: the range a numeric parameter carries the ROS way (in the type of ``default``: an
        IntegerRange for an integer, a FloatingPointRange for a double); the value declared -- the override,
        else the default -- must lie in it, as rclpy requires, or the declaration is a TransportError with
        rclpy's reason, and a later change outside it is refused (:meth:`check_parameter`)."""
        if name in self._parameters:
            raise TransportError(f"{self.fully_qualified_name}: parameter {name!r} declared twice")
        value = self.initial_parameter(name, default)
        if numeric_range is not None:
            try:
                numeric_range = numeric_range.for_type(default)
            except ValueError as error:
                raise TransportError(f"{self.fully_qualified_name}: parameter {name!r}: {error}") from None
            refusal = numeric_range.refusal(name, value)
            if refusal:
                raise TransportError(f"{self.fully_qualified_name}: {refusal}")
            self.ranges[name] = numeric_range
        self._parameters[name] = value
        self.descriptions[name] = description
        return value

    def changeable(self, name: str) -> bool:
        """Whether ``name`` may change while the node runs (:meth:`changeable_parameter`)."""
        return name in self._changeable

    def get_parameter(self, name: str) -> ParameterValue:
        try:
            return self._parameters[name]
        except KeyError:
            raise TransportError(f"{self.fully_qualified_name}: parameter {name!r} was never declared") from None

    def changeable_parameter(self, name: str, change: ParameterChange) -> None:
        """Let the declared parameter ``name`` change while the node runs (``ros2 param set``; in
        process :meth:`set_parameter`); every other parameter is read once, at start-up."""
        self.get_parameter(name)
        self._changeable[name] = change

    def check_parameter(self, name: str, value: ParameterValue) -> tuple[ParameterValue | None, str]:
        """A changeable parameter's new value in its declared type, or (None, why it is refused): the type, whether
        it may change, its own check, then its ROS range (rclpy's reason), which rclpy itself checks first."""
        if name not in self._parameters:
            return None, f"parameter {name!r} is not declared by {self.fully_qualified_name}"
        change = self._changeable.get(name)
        if change is None:
            return None, f"{name} read at start-up; restart {self.fully_qualified_name} to change"
        try:
            value = coerce_parameter(self.fully_qualified_name, name, self._parameters[name], value)
        except ParameterTypeError as error:
            return None, str(error)
        numeric_range = self.ranges.get(name)
        refusal = change.check(value) or (numeric_range.refusal(name, value) if numeric_range is not None else "")
        return (None, refusal) if refusal else (value, "")

    def apply_parameter(self, name: str, value: ParameterValue) -> None:
        """Take a value :meth:`check_parameter` accepted (on the node's loop)."""
        self._parameters[name] = value
        self._changeable[name].apply(value)

    def show_parameter(self, name: str, value: ParameterValue) -> None:
        """A changeable parameter's value changed another way (an operator's command): show it (``ros2 param get``)."""
        self._parameters[name] = value

    def set_parameter(self, name: str, value: ParameterValue) -> str:
        """Change a changeable parameter from this process: "" when taken, else why not (nothing changes)."""
        checked, refusal = self.check_parameter(name, value)
        if checked is None:
            return refusal
        self.apply_parameter(name, checked)
        return ""

    def declared_parameters(self) -> dict[str, ParameterValue]:
        """Every declared parameter with its value, as ``ros2 param dump`` shows them."""
        return dict(self._parameters)

    def undeclared_overrides(self) -> list[str]:
        """Overrides nobody declared: almost always a typo in a launch file."""
        return sorted(set(self._overrides) - set(self._parameters))

    # --------------------------------------------------------------------------- endpoints
    @abstractmethod
    def create_publisher(self, msg_type: type[M], topic: str, qos: QoS = COMMANDS) -> Publisher[M]: ...

    @abstractmethod
    def create_subscription(
        self, msg_type: type[M], topic: str, callback: Callable[[M], None], qos: QoS = COMMANDS
    ) -> Subscription[M]: ...

    @abstractmethod
    def create_service(
        self, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]
    ) -> ServiceServer: ...

    @abstractmethod
    def create_client(self, srv_type: type, name: str) -> ServiceClient[Any, Any]: ...

    @abstractmethod
    def destroy(self) -> None:
        """Remove every endpoint of this node."""

    def topic_names_and_types(self) -> list[TopicInfo]:
        """Every topic with a publisher whose type is one of ours (a recorder's discovery);
        TransportError on a transport that cannot list its graph."""
        raise TransportError(f"{type(self).__name__} cannot list the topics of its graph")

    # ------------------------------------------------------------------------------ faults
    def report_fault(self, where: str, error: BaseException) -> None:
        """Hand a fault from a callback to the node's fault handler; never lets it escape silently."""
        try:
            self.fault_handler(where, error)
        except Exception:  # the handler itself failed: the log is the last resort
            self.logger.exception("fault handler failed while handling %s: %r", where, error)

    def _log_fault(self, where: str, error: BaseException) -> None:
        self.logger.error("%s: fault in %s: %s: %s", self.fully_qualified_name, where, type(error).__name__, error)


class EndpointNode(Node):
    """A node whose endpoint classes are built as ``cls(node, type, resolved name, ...)``: the
    middleware adapters (rclpy, DDS) name their four classes and share the rest."""

    publisher_class: type
    subscription_class: type
    service_class: type
    client_class: type
    _endpoints: list[Any]
    destroyed: bool

    def _add(self, endpoint: Any) -> Any:
        if self.destroyed:
            raise TransportError(f"{self.fully_qualified_name} was destroyed")
        self._endpoints.append(endpoint)
        return endpoint

    def create_publisher(self, msg_type: type[M], topic: str, qos: QoS = COMMANDS) -> Publisher[M]:
        publisher = self._add(self.publisher_class(self, msg_type, self.resolve(topic), qos))
        self.transport.publisher_created(TopicInfo(publisher.topic, msg_type, (qos,)))
        return publisher  # type: ignore[no-any-return]

    def create_subscription(
        self, msg_type: type[M], topic: str, callback: Callable[[M], None], qos: QoS = COMMANDS
    ) -> Subscription[M]:
        return self._add(self.subscription_class(self, msg_type, self.resolve(topic), callback, qos))  # type: ignore[no-any-return]

    def create_service(self, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]) -> ServiceServer:
        return self._add(self.service_class(self, srv_type, self.resolve(name), handler))  # type: ignore[no-any-return]

    def create_client(self, srv_type: type, name: str) -> ServiceClient[Any, Any]:
        return self._add(self.client_class(self, srv_type, self.resolve(name)))  # type: ignore[no-any-return]


class Transport(ABC):
    """A family of nodes that can reach each other."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        #: told of each publisher a node of this process creates, before it can publish anything: a
        #: recorder subscribes to a new topic then, so not even its first message is missed
        self.publisher_listeners: list[Callable[[TopicInfo], None]] = []

    def publisher_created(self, info: TopicInfo) -> None:
        for listener in list(self.publisher_listeners):
            listener(info)

    @abstractmethod
    def create_node(
        self,
        name: str,
        namespace: str = "/",
        parameters: Mapping[str, ParameterValue] | None = None,
    ) -> Node: ...

    @abstractmethod
    async def shutdown(self) -> None:
        """Destroy every node and release the middleware."""
