"""``rclpy.node.Node`` of the fake rclpy: the endpoints a node creates and destroys, its graph queries, clock and logger.

A node takes its name, namespace, parameters and log level from the context's ``--ros-args`` (renames with
``__node``/``__ns``, parameters of its own section), declares ``use_sim_time`` (and then follows ``/clock``), and
announces every endpoint to the graph so that discovery can match it (``ros_fake_graph``).  The parameter API is
:class:`~ros_fake_parameters.NodeParameters`; delivery is ``ros_fake_topics`` and ``ros_fake_services``.
"""
from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

from ros_fake_callbacks import Entity, FakeGuardCondition, MutuallyExclusiveCallbackGroup, Waker
from ros_fake_context import CONTEXT
from ros_fake_graph import GRAPH
from ros_fake_logging import FakeLogger
from ros_fake_msgs import ClockMessage, ParameterDescriptor
from ros_fake_parameters import NodeParameters, Parameter
from ros_fake_qos import QoSProfile, ReliabilityPolicy
from ros_fake_services import FakeClient, FakeService
from ros_fake_time import FakeClock
from ros_fake_topics import FakePublisher, FakeSubscription, replay, ros_type_name


class FakeNode(NodeParameters):
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
        self.executor: Waker | None = None
        overrides = {k: Parameter(k, value=v) for k, v in ros_args.parameters_for(fqn).items()}
        overrides.update({p.name: p for p in parameter_overrides or []})
        super().__init__(overrides)
        self.publishers: list[FakePublisher] = []
        self.entities: list[Entity] = []
        self.destroyed = False
        if automatically_declare_parameters_from_overrides:
            for name, param in overrides.items():
                self.declare_parameter(name, param.value, ParameterDescriptor())
        for name, default in (("use_sim_time", False), ("start_type_description_service", True)):
            if not self.has_parameter(name):
                self.declare_parameter(name, default)
        self._clock = FakeClock()
        if self.get_parameter("use_sim_time").value is True:  # rclpy's TimeSource
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
            return [SimpleNamespace(qos_profile=p.qos, node_name=p.node.get_name()) for p in GRAPH.publishers.get(topic_name, []) if not p.destroyed]

    def get_namespace(self) -> str:
        return self._namespace

    def get_clock(self) -> FakeClock:
        return self._clock

    def get_logger(self) -> FakeLogger:
        return self._logger

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
            GRAPH.discover(pub, sub, lambda s=sub: replay(pub, s))
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
            GRAPH.discover(pub, sub, lambda p=pub: replay(p, sub))
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
