"""The flight recorder: a node that subscribes to every topic of the graph and records it as MCAP.

It is a plain participant of the transport port, like ``ros2 bag record -a``: it discovers the
topics (:meth:`Node.topic_names_and_types`) at start and then every ``poll`` run seconds, and
subscribes to each with a QoS no stronger than its publishers offer (best effort if any publisher
is, transient-local only when all are, so the latched state, structure and cell reach it).  The
same code records the in-process deployment of ``run --record`` and a ROS 2 graph (the engine
node's ``record`` parameter).  Every message is handed to an :class:`McapSink`, whose encoder process
does the converting, encoding and writing; the callbacks only enqueue the message and its stamp.
In an in-process run the encoder also works ``tf`` out of ``joint_states`` (:mod:`.derived_tf`).

What ran goes in with it: the application XML and its cell model as attachments, and a
``dual_arm_executive`` metadata record (application, digests, robot, back end, software version,
the recording it continues after a resume).
"""
from __future__ import annotations

import asyncio
import hashlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

from execution_engine.app_model.model import Application
from execution_engine.engine.remainder_swap import Swap
from execution_engine.machine.table import FINISH
from execution_engine.recorder.definitions import known
from execution_engine.recorder.writer import McapSink, RecordingStats
from node_transport import typed
from node_transport.port import Node, Subscription, TopicInfo, TransportError, poll_until
from node_transport.qos import Durability, History, QoS, Reliability
from node_transport.wire import ENGINE_STATUS, JOINT_STATES, ROBOT_DESCRIPTION_TOPIC, TF_TOPIC, sm_topic

POLL = 0.5  # run seconds between looks for new topics (rosbag2 polls every 0.1 s of wall time)
DEPTH = 1000  # a recorder keeps up with bursts: every state change matters
WAIT_STEP = 0.05  # run seconds between looks while waiting for the graph (ready, settle)


def software_version() -> str:
    try:
        return metadata.version("dual_arm_executive")
    except metadata.PackageNotFoundError:
        return "0.1.0 (source tree)"


def file_digest(path: Path | None) -> str:
    """sha256 of a file's bytes, "" when there is no file."""
    if path is None or not Path(path).is_file():
        return ""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def reader_qos(offered: tuple[QoS, ...]) -> QoS:
    """What a recorder asks for so that it matches every publisher of a topic."""
    best_effort = any(q.reliability is Reliability.BEST_EFFORT for q in offered)
    latched = bool(offered) and all(q.durability is Durability.TRANSIENT_LOCAL for q in offered)
    return QoS(
        Reliability.BEST_EFFORT if best_effort else Reliability.RELIABLE,
        Durability.TRANSIENT_LOCAL if latched else Durability.VOLATILE,
        History.KEEP_LAST,
        max([DEPTH, *(q.depth for q in offered)]),
    )


class Recorder:
    """Records every topic ``node`` can see into ``sink`` until :meth:`close`."""

    def __init__(self, node: Node, sink: McapSink, poll: float = POLL, *, derive_tf: bool = False) -> None:
        self.node = node
        self.sink = sink
        self.poll = poll
        # In a run whose bridge is in this process, tf is its joint_states through its URDF: the
        # encoder works it out (:mod:`.derived_tf`) and the bridge need not compute it for us.
        self._derived_tf = node.resolve(TF_TOPIC) if derive_tf else None
        self._topics: dict[str, TopicInfo] = {}
        self._subscriptions: dict[str, Subscription[Any]] = {}
        self._states: dict[str, str] = {}  # <group>/sm/state topic -> the last state recorded on it
        self._operation: str | None = None
        self._task: asyncio.Task[None] | None = None
        self._engine_status = node.resolve(ENGINE_STATUS)
        self._edits = 0  # edits of the paused run recorded so far

    def start(self) -> None:
        """Subscribe to what exists now, to every topic a node of this process starts publishing
        the moment it does, and keep looking for the topics of other processes."""
        self.node.transport.publisher_listeners.append(self._on_publisher)
        self.discover()
        self._task = asyncio.get_running_loop().create_task(self._watch(), name="recorder discovery")

    def discover(self) -> list[str]:
        """Subscribe to topics not seen before; the new topic names."""
        return [info.name for info in self.node.topic_names_and_types() if info.name not in self._topics and self._subscribe(info)]

    def _on_publisher(self, created: TopicInfo) -> None:
        """A node of this process made a publisher and has not published yet: a topic new to the
        recording is subscribed now, or its first messages (an operation's first request) would
        be gone before the next look at the graph.  Never raises into the publisher's maker."""
        if created.name in self._topics:
            return
        try:
            known_info = next((i for i in self.node.topic_names_and_types() if i.name == created.name), None)
            offered = known_info.offered if known_info is not None else ()
            offered += tuple(q for q in created.offered if q not in offered)
            self._subscribe(TopicInfo(created.name, created.msg_type, offered))
        except TransportError as error:
            self.node.logger.warning("recorder: cannot subscribe to %s: %s", created.name, error)

    def _subscribe(self, info: TopicInfo) -> bool:
        """Record ``info``'s topic from now on; False when it cannot be (no message definition)."""
        self._topics[info.name] = info
        ros_type = str(getattr(info.msg_type, "ROS_TYPE", ""))
        if not known(ros_type):
            self.node.logger.warning("recorder: %s is not recorded: no message definition of %s", info.name, ros_type or info.msg_type.__name__)
            return False
        if info.name == self._derived_tf:
            self.sink.derive_tf(info.name, info.offered, self.node.resolve(JOINT_STATES), self.node.resolve(ROBOT_DESCRIPTION_TOPIC))
            return True
        self._subscriptions[info.name] = self.node.create_subscription(info.msg_type, info.name, self._callback(info), reader_qos(info.offered))
        return True

    async def _watch(self) -> None:
        while True:
            await self.node.clock.sleep(self.poll)
            try:
                self.discover()
            except TransportError as error:  # the graph changed under us: try again next time
                self.node.logger.warning("recorder: topic discovery failed: %s", error)

    def _callback(self, info: TopicInfo) -> Callable[[Any], None]:
        topic, offered, sink, node = info.name, info.offered, self.sink, self.node

        def record(msg: Any) -> None:
            stamp = node.now_stamp()
            sink.put(topic, msg, offered, stamp.sec * 1_000_000_000 + stamp.nanosec)
            if topic == self._engine_status and isinstance(msg, typed.EngineStatusMsg):
                self._on_engine_status(msg)

        if not topic.endswith("/sm/state"):
            return record

        def record_state(msg: Any) -> None:
            record(msg)
            self._states[topic] = str(getattr(msg, "state", ""))

        return record_state

    # ------------------------------------------------------------ a graph of processes (ROS 2, DDS)
    async def ready(self, groups: Iterable[str], timeout: float) -> bool:
        """Before a run on a graph: wait (bounded) until each group's machine state is subscribed
        and every subscription has matched the publishers the graph showed, so the run's first
        transitions are not still on their way to a reader that does not exist yet."""
        wanted = self._state_topics(groups)

        def matched() -> bool:
            self.discover()
            return all(t in self._subscriptions for t in wanted) and all(
                sub.get_publisher_count() >= len(self._topics[t].offered) for t, sub in self._subscriptions.items()
            )

        return await poll_until(self.node.clock, matched, timeout, WAIT_STEP)

    async def settle(self, groups: Iterable[str], timeout: float) -> bool:
        """After a run on a graph: wait (bounded) until each group's Finish is in the recording
        (the engine returns when it has seen them; the recorder's own readers may not have yet)."""
        wanted = self._state_topics(groups)
        return await poll_until(self.node.clock, lambda: all(self._states.get(t) == FINISH for t in wanted), timeout, WAIT_STEP)

    def _state_topics(self, groups: Iterable[str]) -> list[str]:
        return [self.node.resolve(sm_topic(g, "state")) for g in groups]

    def _on_engine_status(self, msg: Any) -> None:
        """An operation boundary: the chunk so far goes to disk, as the trace does.  Only the
        operation's id is read (the file keeps the whole message): no decoding on the control path."""
        operation = msg.operation_id
        if isinstance(operation, str) and operation != self._operation:
            self._operation = operation
            self.sink.sync()

    def describe_run(
        self,
        application: Path,
        cell: Path | None,
        fields: Mapping[str, str],
        includes: Sequence[Path] = (),
        iterations: Mapping[str, str] | None = None,
    ) -> None:
        """Store what ran: the application, cell and called files as attachments, and a metadata
        record; ``iterations`` (the loop iteration or call each expanded operation was made for, by
        id) as a metadata record of its own, ``dual_arm_executive_iterations``."""
        stamp = self.node.now_stamp()
        now_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        for path, kind in ((application, "application"), (cell, "cell"), *((p, "calls") for p in includes)):
            if path is not None and Path(path).is_file():
                self.sink.add_attachment(f"{kind}/{Path(path).name}", "application/xml", Path(path).read_bytes(), now_ns)
        if iterations:
            self.sink.add_metadata("dual_arm_executive_iterations", iterations)
        self.sink.add_metadata("dual_arm_executive", {
            "application_path": str(application),
            "clock_epoch": repr(self.node.clock.epoch),  # ROS time of run time 0: stamps -> the trace's t
            "application_sha256": file_digest(application),
            "cell_path": str(cell or ""),
            "cell_sha256": file_digest(cell),
            "software_version": software_version(),
            **fields,
        })

    def swapped(self, app: Application, swap: Swap) -> None:
        """A paused run's remainder was edited (the engine's hook, engine/remainder_swap.py): the edited application
        as an attachment ``edited/<n>/<file>`` and a metadata record ``dual_arm_executive_edit_<n>`` (both digests,
        where, who); the engine's ``swap`` event is in the recording already."""
        self._edits += 1
        stamp = self.node.now_stamp()
        now_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if Path(app.path).is_file():
            self.sink.add_attachment(f"edited/{self._edits}/{Path(app.path).name}", "application/xml", Path(app.path).read_bytes(), now_ns)
        self.sink.add_metadata(f"dual_arm_executive_edit_{self._edits}", {
            "t": repr(swap.t), "from_operation": str(swap.frontier + 1), "after_operation": swap.operation or "",
            "from_digest": swap.old_digest, "to_digest": swap.new_digest, "application_path": swap.file,
            "application_sha256": file_digest(Path(app.path)), "source": swap.source,
            **({"groups": swap.where()} if swap.groups else {}),  # sync="flags": where each group stood
        })

    async def close(self) -> RecordingStats:
        """Stop looking for topics, let the last messages arrive, finish the file (the sink adds
        the ``recording_stats`` metadata: what was written and dropped)."""
        if self._on_publisher in self.node.transport.publisher_listeners:
            self.node.transport.publisher_listeners.remove(self._on_publisher)
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
        await asyncio.sleep(0)  # deliveries already scheduled on the loop
        with self.node.clock.held():  # simulated time waits for the file: the cell's periodic tasks would race ahead
            return await asyncio.get_running_loop().run_in_executor(None, self.sink.close)
