"""The ``dds`` transport: the port over Eclipse Cyclone DDS from PyPI, a ROS 2 graph without ROS.

``pip install '.[dds]'`` is all a machine needs: no ROS install, no ``ROS_DISTRO``.  What goes on
the wire is what ``rmw_cyclonedds_cpp`` of ROS 2 Jazzy puts there, so ``ros2 node list``,
``ros2 topic echo``, ``ros2 service call``, RViz and Foxglove see these nodes like any other:

* types built from the ``.msg``/``.srv`` files (:mod:`~node_transport.idl`), plain CDR, encoded and
  decoded by code compiled once per type (:mod:`~node_transport.dds_cdr`: cyclonedds-python's bytes);
* names, QoS, domain and discovery configuration, ``ros_discovery_info``:
  :mod:`~node_transport.dds_graph`;
* services carry rmw_cyclonedds_cpp's request header (the client's 64-bit id and a sequence
  number); a server answers only once its reply writer has matched the client's reply reader
  (the ``clientid=`` user data, as rmw does; for a client without it, such as ros2-client on
  RustDDS, a reply reader of the caller's participant), so a first answer is not lost;
* every writer asserts automatic liveliness with a lease of ``lease`` seconds (1 s by default),
  and every transport pulses four times per lease (:mod:`~node_transport.dds_pulse`): a
  subscription's :meth:`get_publisher_count` counts only *live* publishers, so a peer killed or
  cut off drops out of it within the lease -- that is how the engine notices a lost machine
  (:mod:`execution_engine.engine.group_link`) -- and a peer that was silent for a moment counts
  again as soon as it pulses (Cyclone's own liveliness comes back only when the writer writes).

Threads: no Cyclone listeners (a write of this process waiting for a listener that waits for the
GIL hangs the process, see :mod:`~node_transport.dds_waiter`); one waiter thread per
transport takes and decodes the samples of every reader and hands them to the asyncio loop in
arrival order, all that one wake took in one ``call_soon_threadsafe`` (:class:`~node_transport.dds_waiter.Inbox`).  A sample that
does not decode (truncated CDR, garbage) or does not convert is counted per topic
(:attr:`DdsTransport.rejected`) and logged once per topic, never delivered, never fatal.
Like the rclpy transport it runs in wall time; durations given to it are run seconds.  A node with
``use_sim_time`` (declared as rclpy declares it) measures them on the simulator's ``/clock``
(:mod:`~node_transport.sim_time`).
"""
from __future__ import annotations

import asyncio
import itertools
import logging
import os
from collections import Counter
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any, Generic, TypeVar

from node_transport.clock import Clock
from node_transport import dds_graph as graph
from node_transport.dds_args import RosArguments, parse_ros_arguments, user_arguments
from node_transport.dds_convert import DdsConverter
from node_transport.dds_entities import Caller, Taker, delete, matched, write
from node_transport.dds_parameters import serve as serve_parameters
from node_transport.dds_pulse import LiveCount, Pulse
from node_transport.dds_waiter import DdsWaiter, Inbox
from node_transport.idl import InterfaceError, InterfaceRegistry
from node_transport.idl_hash import type_hash_user_data
from node_transport.port import (
    EndpointNode,
    ParameterChange,
    ParameterValue,
    Publisher,
    ServiceClient,
    ServiceServer,
    ServiceUnavailable,
    Subscription,
    Transport,
    TransportError,
    poll_until,
    resolve_name,
    unwrap_reply,
)
from node_transport.qos import QoS
from node_transport.ros_args import raw_parameter_texts
from node_transport.ros_convert import failure_response
from node_transport.sim_time import STALL_TIMEOUT, USE_SIM_TIME, USE_SIM_TIME_DESCRIPTION, follow_clock

M = TypeVar("M")
log = logging.getLogger(__name__)

_POLL = 0.02  # run seconds between discovery checks
_REPLY_MATCH_WAIT = 1.0  # wall seconds a reply waits at most for the caller's reply reader to match


def _import_cyclonedds() -> Any:
    try:  # optional: cyclonedds (pip extra 'dds'), imported when a DDS transport starts
        import cyclonedds.core
        import cyclonedds.domain
        import cyclonedds.pub
        import cyclonedds.sub
        import cyclonedds.topic
    except ImportError as error:
        raise TransportError(f"the dds transport needs the cyclonedds package ({error}): pip install '.[dds]'") from None
    return cyclonedds


_DOMAINS: dict[int, tuple[str | None, Any]] = {}  # one Cyclone domain per id and process, kept alive


def _domain(dds: Any, domain_id: int, config: str | None) -> Any:
    """The process's Cyclone domain ``domain_id`` with ``config`` (made once; Cyclone refuses a second)."""
    known = _DOMAINS.get(domain_id)
    if known is not None:
        if known[0] != config:
            raise TransportError(f"DDS domain {domain_id} is already configured differently in this process")
        return known[1]
    domain = dds.domain.Domain(domain_id, config) if config else None
    _DOMAINS[domain_id] = (config, domain)
    return domain


# =================================================================================== endpoints
class _DdsPublisher(Publisher[M], Generic[M]):
    def __init__(self, node: DdsNode, msg_type: type[M], topic: str, qos: QoS) -> None:
        self.node, self.msg_type, self.topic, self.qos = node, msg_type, topic, qos
        transport = node.transport
        self.wire_type = transport.converter.wire_class(msg_type)
        dds = transport.dds
        self.writer = dds.pub.DataWriter(
            transport.participant, transport.topic(graph.topic_name(topic), self.wire_type),
            qos=graph.dds_qos(qos, lease=transport.lease, user_data=transport.type_hash(msg_type.ROS_TYPE)),  # type: ignore[attr-defined]
        )
        self.alive = True
        node.add_entity(self.writer, reader=False)

    def publish(self, msg: M) -> None:
        if not self.alive:
            raise TransportError(f"publisher on {self.topic} of {self.node.fully_qualified_name} was destroyed")
        self._check(msg)
        write(self.writer, self.node.transport.converter.to_wire(msg))

    def get_subscription_count(self) -> int:
        """Matched subscriptions: Cyclone's count, one call (a machine asks before every status event)."""
        return int(self.writer.get_publication_matched_status().current_count) if self.alive else 0

    def destroy(self) -> None:
        if self.alive:
            self.alive = False
            delete(self.writer)


class _DdsSubscription(Subscription[M], Generic[M]):
    def __init__(self, node: DdsNode, msg_type: type[M], topic: str, callback: Callable[[M], None], qos: QoS) -> None:
        self.node, self.msg_type, self.topic, self.qos = node, msg_type, topic, qos
        transport = node.transport
        self._callback = callback
        self._taker = Taker(transport, topic)
        self.alive = True
        self.reader = transport.dds.sub.DataReader(
            transport.participant, transport.topic(graph.topic_name(topic), transport.converter.wire_class(msg_type)),
            qos=graph.dds_qos(qos, user_data=transport.type_hash(msg_type.ROS_TYPE)),  # type: ignore[attr-defined]
        )
        node.add_entity(self.reader, reader=True)
        self._live = LiveCount(self.reader, transport.pulse)
        self._watch = transport.waiter.watch(self.reader, self._on_data)

    def _on_data(self) -> None:
        """The waiter's thread: decode, convert, queue on the loop. Never raises."""
        if not self.alive:
            return
        transport = self.node.transport
        for sample in self._taker.take(self.reader):
            try:
                msg = transport.converter.from_wire(self.msg_type, sample)
            except Exception as error:  # noqa: BLE001 - garbage that decoded: still garbage
                transport.reject(self.topic, f"{type(error).__name__}: {error}")
                continue
            transport.inbox.put(self._deliver, msg)

    def get_publisher_count(self) -> int:
        """Matched publishers whose liveliness holds (:class:`~node_transport.dds_pulse.LiveCount`):
        a killed peer drops out within its lease, one that pulses again is back at once."""
        if not self.alive:
            return 0
        return self._live.count()

    def publisher_nodes(self) -> list[str]:
        """The nodes of the matched publishers, from what their processes put on ros_discovery_info."""
        if not self.alive:
            return []
        owners = self.node.transport.refresh_owners()
        return sorted({owners[d.key.bytes] for d in matched(self.reader, subscriptions=False) if d.key.bytes in owners})

    def destroy(self) -> None:
        if self.alive:
            self.alive = False
            self.node.transport.waiter.forget(self._watch)
            delete(self.reader)


class _ServiceEndpoints:
    """A request/reply pair of a service or client, with the user data that pairs them."""

    def __init__(self, node: DdsNode, srv_type: type, name: str, role: str, on_data: Callable[[], None]) -> None:
        transport = self.transport = node.transport
        ros_type = getattr(srv_type, "ROS_TYPE", None)
        if not isinstance(ros_type, str):
            raise TransportError(f"{srv_type!r} is not a service mirror")
        try:
            self.request_type, self.reply_type = transport.registry.wire_service(ros_type)
        except InterfaceError as error:
            raise TransportError(str(error)) from None
        self.id = transport.new_endpoint_id()
        user_data = f"{role}={self.id};".encode()
        dds = transport.dds
        ours, theirs = (self.reply_type, self.request_type) if role == "serviceid" else (self.request_type, self.reply_type)
        hashes = {part: transport.type_hash(f"{ros_type}_{part}") for part in ("Request", "Response")}
        write_hash, read_hash = (hashes["Response"], hashes["Request"]) if role == "serviceid" else (hashes["Request"], hashes["Response"])
        write_topic, read_topic = (
            (graph.reply_topic(name), graph.request_topic(name)) if role == "serviceid"
            else (graph.request_topic(name), graph.reply_topic(name))
        )
        qos = graph.dds_qos(graph.SERVICES, user_data=user_data + write_hash, lease=transport.lease)
        self.writer = dds.pub.DataWriter(transport.participant, transport.topic(write_topic, ours), qos=qos)
        self.reader = dds.sub.DataReader(
            transport.participant, transport.topic(read_topic, theirs),
            qos=graph.dds_qos(graph.SERVICES, user_data=user_data + read_hash),
        )
        node.add_entity(self.writer, reader=False)
        node.add_entity(self.reader, reader=True)
        self.watch = transport.waiter.watch(self.reader, on_data)

    def destroy(self) -> None:
        self.transport.waiter.forget(self.watch)
        delete(self.reader)
        delete(self.writer)


class _DdsService(ServiceServer):
    def __init__(self, node: DdsNode, srv_type: type, name: str, handler: Callable[[Any], Awaitable[Any]]) -> None:
        self.node, self.srv_type, self.name = node, srv_type, name
        self._handler = handler
        self.alive = True
        self._taker = Taker(node.transport, f"{name} (request)")
        self.ends = _ServiceEndpoints(node, srv_type, name, "serviceid", self._on_request)

    def _on_request(self) -> None:
        """The waiter's thread. Never raises."""
        ends = getattr(self, "ends", None)
        if ends is None or not self.alive:
            return
        reader = ends.reader
        transport = self.node.transport
        for sample in self._taker.take(reader):
            try:
                request = transport.converter.from_wire(self.srv_type.Request, sample)
                client = Caller.of(reader.get_matched_publication_data(sample.sample_info.publication_handle))
            except Exception as error:  # noqa: BLE001
                transport.reject(f"{self.name} (request)", f"{type(error).__name__}: {error}")
                continue
            transport.inbox.put(self._start, request, int(sample.guid), int(sample.seq), client)

    def _start(self, request: Any, guid: int, seq: int, client: Caller) -> None:
        if self.alive:
            task = self.node.transport.loop.create_task(self._serve(request, guid, seq, client), name=f"service {self.name}")
            self.node.transport.handlers.add(task)
            task.add_done_callback(self.node.transport.handlers.discard)

    async def _serve(self, request: Any, guid: int, seq: int, client: Caller) -> None:
        transport = self.node.transport
        try:
            # a handler that waits for a long job on purpose (an action's get_result) says so
            timeout = None if getattr(self._handler, "long_running", False) else transport.handler_timeout
            response, then = unwrap_reply(await transport.clock.wait_for(self._handler(request), timeout))
            if type(response) is not self.srv_type.Response:
                raise TransportError(f"handler answered {type(response).__name__}, not {self.srv_type.Response.__name__}")
        except asyncio.CancelledError:
            raise
        except Exception as error:  # noqa: BLE001 - the caller gets a failure answer, the node a fault
            self.node.report_fault(f"service {self.name}", error)
            response, then = failure_response(self.srv_type.Response, f"{self.name}: {type(error).__name__}: {error}"), None
        await self._wait_for_client(client)
        if self.alive:
            write(self.ends.writer, transport.converter.to_wire_service(self.ends.reply_type, response, guid, seq))
        if then is not None:  # written first: what follows the answer reaches the caller after it
            try:
                then()
            except Exception as error:  # noqa: BLE001
                self.node.report_fault(f"service {self.name} (after its answer)", error)

    async def _wait_for_client(self, client: Caller) -> None:
        """Until the reply writer has matched the caller's reply reader (bounded, 1 s): a reply
        written before that is lost (volatile), and the caller waits in vain."""
        clock = self.node.transport.clock
        deadline = clock.now() + clock.speed * _REPLY_MATCH_WAIT
        writer = self.ends.writer
        while clock.now() < deadline:
            if any(client.reads(data) for data in matched(writer, subscriptions=True)):
                return
            await clock.sleep(_POLL)

    def destroy(self) -> None:
        if self.alive:
            self.alive = False
            self.ends.destroy()


class _DdsClient(ServiceClient[Any, Any]):
    def __init__(self, node: DdsNode, srv_type: type, name: str) -> None:
        self.node, self.srv_type, self.name = node, srv_type, name
        self.alive = True
        self._pending: dict[int, asyncio.Future[Any]] = {}
        self._seq = itertools.count(1)
        self._taker = Taker(node.transport, f"{name} (reply)")
        self.ends = _ServiceEndpoints(node, srv_type, name, "clientid", self._on_reply)
        self.guid = int(self.ends.writer.instance_handle) & 0xFFFF_FFFF_FFFF_FFFF  # rmw: the writer's handle, unsigned

    def _on_reply(self) -> None:
        ends = getattr(self, "ends", None)
        if ends is None or not self.alive or not hasattr(self, "guid"):
            return
        reader = ends.reader
        transport = self.node.transport
        for sample in self._taker.take(reader):
            if int(sample.guid) != self.guid:
                continue  # another client's answer
            try:
                response = transport.converter.from_wire(self.srv_type.Response, sample)
            except Exception as error:  # noqa: BLE001
                transport.reject(f"{self.name} (reply)", f"{type(error).__name__}: {error}")
                continue
            transport.inbox.put(self._settle, int(sample.seq), response)

    def _settle(self, seq: int, response: Any) -> None:
        future = self._pending.pop(seq, None)
        if future is not None and not future.done():
            future.set_result(response)

    def available(self) -> bool:
        """A server's request reader and reply writer are both matched (rmw's serviceid rule)."""
        writer, reader = self.ends.writer, self.ends.reader
        servers = {graph.user_data_value(d.qos, "serviceid") for d in matched(writer, subscriptions=True)}
        repliers = {graph.user_data_value(d.qos, "serviceid") for d in matched(reader, subscriptions=False)}
        servers.discard(None)
        return bool(servers & repliers)

    async def wait_for_service(self, timeout: float) -> bool:
        return await poll_until(self.node.clock, self.available, timeout, _POLL)

    async def call(self, request: Any, timeout: float = 5.0) -> Any:
        if type(request) is not self.srv_type.Request:
            raise TransportError(f"service {self.name} takes {self.srv_type.Request.__name__}, got {type(request).__name__}")
        if not self.alive:
            raise TransportError(f"client of {self.name} was destroyed")
        clock = self.node.clock
        start = clock.now()
        if not await self.wait_for_service(timeout):
            raise ServiceUnavailable(f"no server for service {self.name} within {timeout:g} s")
        seq = next(self._seq)
        future: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._pending[seq] = future
        converter = self.node.transport.converter
        write(self.ends.writer, converter.to_wire_service(self.ends.request_type, request, self.guid, seq))
        try:
            return await clock.wait_for(future, max(0.0, timeout - (clock.now() - start)))
        finally:
            self._pending.pop(seq, None)

    def destroy(self) -> None:
        if self.alive:
            self.alive = False
            for future in self._pending.values():
                future.cancel()
            self.ends.destroy()


# ======================================================================================= node
class DdsNode(EndpointNode):
    publisher_class, subscription_class = _DdsPublisher, _DdsSubscription
    service_class, client_class = _DdsService, _DdsClient

    def __init__(
        self, transport: DdsTransport, name: str, namespace: str, parameters: Mapping[str, ParameterValue] | None
    ) -> None:
        args = transport.args
        name = args.node_name or name
        namespace = args.namespace or namespace
        fqn = f"{namespace.rstrip('/')}/{name}"
        overrides = {**args.overrides_for(fqn), **(parameters or {})}
        super().__init__(name, namespace, transport.clock, overrides, raw_parameter_texts(transport.argv, fqn))
        self.transport = transport
        if args.log_level is not None:
            self.logger.setLevel(args.log_level)
        self._endpoints: list[Any] = []
        self.readers: list[bytes] = []
        self.writers: list[bytes] = []
        self.destroyed = False
        self._parameter_services: list[ServiceServer] = []  # ros2 param set/get, once a parameter may change (dds_parameters.py)
        # rclpy's own parameter, declared as rclpy declares it: with it, the run clock follows /clock
        if self.declare_parameter(USE_SIM_TIME, False, USE_SIM_TIME_DESCRIPTION) is True:
            self.clock = follow_clock(self, transport.loop, transport.clock_stall_timeout)

    def changeable_parameter(self, name: str, change: ParameterChange) -> None:
        super().changeable_parameter(name, change)
        if not self._parameter_services:
            self._parameter_services = serve_parameters(self)

    def resolve(self, name: str) -> str:
        resolved = resolve_name(name, self.namespace, self.name)
        for source, target in self.transport.args.remaps.items():
            if resolve_name(source, self.namespace, self.name) == resolved:
                return resolve_name(target, self.namespace, self.name)
        return resolved

    def add_entity(self, entity: Any, *, reader: bool) -> None:
        (self.readers if reader else self.writers).append(entity.guid.bytes)
        self.transport.graph_changed()

    def destroy(self) -> None:
        if self.destroyed:
            return
        self.destroyed = True
        for endpoint in self._endpoints:
            endpoint.destroy()
        self._endpoints.clear()
        self.transport.remove_node(self)


# ================================================================================== transport
class DdsTransport(Transport):
    """The nodes of one process on one Cyclone DDS participant (as rmw_cyclonedds_cpp has one per
    process), in ``ROS_DOMAIN_ID``.  Create it inside the running loop its clock is bound to;
    ``args`` is the process's argv (its ``--ros-args`` are read here).  ``lease`` (wall seconds)
    is the liveliness lease of every writer; ``handler_timeout`` bounds a service handler (run s);
    ``clock_stall_timeout`` is how long a node with ``use_sim_time`` waits for ``/clock`` before
    its waits end (wall seconds).
    """

    def __init__(
        self,
        clock: Clock,
        args: Sequence[str] | None = None,
        *,
        env: Mapping[str, str] | None = None,
        lease: float = 1.0,
        handler_timeout: float = 30.0,
        clock_stall_timeout: float = STALL_TIMEOUT,
    ) -> None:
        super().__init__(clock)
        if clock.simulated:
            raise ValueError("the dds transport runs in wall time: a simulated clock would jump over every network wait")
        self.dds = _import_cyclonedds()
        self.argv = list(args or [])
        self.args: RosArguments = parse_ros_arguments(self.argv)
        environment = os.environ if env is None else env
        self.loop = clock.loop
        self.lease = lease
        self.handler_timeout = handler_timeout
        self.clock_stall_timeout = clock_stall_timeout
        self.registry = InterfaceRegistry()
        self.converter = DdsConverter(self.registry)
        self.domain_id = graph.domain_id(environment)
        config = graph.domain_config(environment)
        try:
            self.domain = _domain(self.dds, self.domain_id, config)
            self.participant = self.dds.domain.DomainParticipant(
                self.domain_id, qos=self.dds.qos.Qos(self.dds.qos.Policy.Userdata(data=graph.ENCLAVE_USER_DATA))
            )
        except Exception as error:  # noqa: BLE001 - DDSException from a bad CYCLONEDDS_URI and the like
            raise TransportError(f"cannot join DDS domain {self.domain_id}: {error} (check CYCLONEDDS_URI)") from None
        self.spin_error: BaseException | None = None
        self._closed = asyncio.Event()
        self.waiter = DdsWaiter(self.dds, self.participant, f"domain {self.domain_id}", on_stop=self._waiter_stopped)
        self.inbox = Inbox(self.loop)  # what the waiter's thread takes reaches the loop once per wake
        self.waiter.after_each(self.inbox.hand_over)
        self._topics: dict[tuple[str, type], Any] = {}
        self._hashes: dict[str, bytes] = {}
        self._ids = itertools.count(1)
        self._guid = self.participant.guid.bytes
        self._guid_hex = self._guid.hex()
        self._deleted = False
        self._nodes: dict[str, DdsNode] = {}
        self.rejected: Counter[str] = Counter()
        self.handlers: set[asyncio.Task[Any]] = set()
        self._graph_pending = False
        discovery_topic = self.topic(graph.DISCOVERY_TOPIC, self.registry.message(graph.DISCOVERY_TYPE))
        discovery_qos = graph.dds_qos(graph.DISCOVERY, user_data=self.type_hash(graph.DISCOVERY_TYPE))
        self._discovery = self.dds.pub.DataWriter(self.participant, discovery_topic, qos=discovery_qos)
        #: writer GUID (16 bytes) -> fully qualified name of its node, from every process's ros_discovery_info
        self.owners = graph.WriterOwners()
        self._discovery_taker = Taker(self, graph.DISCOVERY_TOPIC)
        # Read on the loop, never from a listener: this process writes the topic too, and cyclonedds
        # writes holding the GIL, so a local delivery waiting for a listener that waits for the GIL
        # (a peer's sample arriving at the same moment) would hang the process.
        self._discovery_reader = self.dds.sub.DataReader(
            self.participant, discovery_topic, qos=graph.dds_qos(graph.DISCOVERY_READER, user_data=self.type_hash(graph.DISCOVERY_TYPE)),
        )
        self.pulse = Pulse(self, lease)
        self.waiter.watch(self.pulse.reader, self.pulse.on_data)
        self.waiter.every(self.pulse.beat)
        self.stopping = False

    # ------------------------------------------------------------------------- plumbing
    def topic(self, name: str, wire_type: type) -> Any:
        key = (name, wire_type)
        topic = self._topics.get(key)
        if topic is None:
            topic = self._topics[key] = self.dds.topic.Topic(self.participant, name, wire_type)
        return topic

    def type_hash(self, ros_type: str) -> bytes:
        """``typehash=RIHS01_...;`` for an endpoint's user data, as rmw gives it."""
        cached = self._hashes.get(ros_type)
        if cached is None:
            try:
                cached = self._hashes[ros_type] = type_hash_user_data(self.registry, ros_type)
            except InterfaceError as error:
                raise TransportError(str(error)) from None
        return cached

    def new_endpoint_id(self) -> str:
        return f"{self._guid_hex}.{next(self._ids)}"

    def call_soon(self, callback: Callable[..., Any], *args: Any) -> bool:
        """Schedule ``callback`` on the loop from any thread; False once the loop is closed."""
        try:
            self.loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:
            return False
        return True

    def reject(self, topic: str, why: str) -> None:
        """Any thread: one more sample on ``topic`` that could not be used."""
        self.rejected[topic] += 1
        if self.rejected[topic] == 1 or self.rejected[topic] % 1000 == 0:
            log.warning("dds: %d sample(s) on %s rejected; last: %s", self.rejected[topic], topic, why)

    def refresh_owners(self) -> graph.WriterOwners:
        """Which node each writer of the graph belongs to, with what has come on ros_discovery_info
        since the last call (the loop's thread; a peer's garbage costs only its sample)."""
        if not self._deleted:
            for sample in self._discovery_taker.take(self._discovery_reader):
                try:
                    self.owners.update(sample)
                except Exception as error:  # noqa: BLE001
                    self.reject(graph.DISCOVERY_TOPIC, f"{type(error).__name__}: {error}")
        return self.owners

    def graph_changed(self) -> None:
        """Publish ros_discovery_info once this loop pass has made its changes."""
        if not self._graph_pending and not self.stopping:
            self._graph_pending = True
            self.call_soon(self._publish_graph)

    def _publish_graph(self) -> None:
        self._graph_pending = False
        if self._deleted:
            return
        nodes = {(n.namespace, n.name): (n.readers, n.writers) for n in self._nodes.values()}
        write(self._discovery, graph.discovery_message(self.registry, self._guid, nodes))

    # ---------------------------------------------------------------------------- nodes
    def create_node(
        self, name: str, namespace: str = "/", parameters: Mapping[str, ParameterValue] | None = None
    ) -> DdsNode:
        if self.stopping:
            raise TransportError("the dds transport is shut down")
        node = DdsNode(self, name, namespace, parameters)
        if node.fully_qualified_name in self._nodes:
            raise TransportError(f"a node named {node.fully_qualified_name} already exists")
        self._nodes[node.fully_qualified_name] = node
        self.graph_changed()
        return node

    def remove_node(self, node: DdsNode) -> None:
        if self._nodes.get(node.fully_qualified_name) is node:
            del self._nodes[node.fully_qualified_name]
            self.graph_changed()

    def node_names(self) -> list[str]:
        return sorted(self._nodes)

    def user_args(self, argv: Sequence[str]) -> list[str]:
        """``argv`` without the program name and its ROS arguments."""
        return user_arguments(argv)

    def _waiter_stopped(self, error: BaseException) -> None:
        """The waiter's thread stopped by itself: this process hears nothing any more, so it ends
        as an rclpy process does when its executor dies (``spin_error``, non-zero exit; the
        launch names the node and the other groups stop)."""
        self.spin_error = error
        self.call_soon(self._closed.set)

    async def wait_closed(self) -> None:
        await self._closed.wait()

    async def shutdown(self) -> None:
        """Destroy every node (its endpoints leave the graph), then the participant."""
        if self.stopping:
            return
        for node in list(self._nodes.values()):
            node.destroy()
        self.stopping = True
        for task in list(self.handlers):
            task.cancel()
        await asyncio.gather(*self.handlers, return_exceptions=True)
        self._publish_graph()
        self._deleted = True
        self.waiter.close()
        delete(self.pulse.reader)
        delete(self.pulse.writer)
        delete(self._discovery_reader)
        delete(self._discovery)
        delete(self.participant)
        self._closed.set()
