"""The bridge node: carries primitives from group machines to a :class:`RobotBackend`.

Subscribes ``/<group>/bridge/command`` for each group of the back end, answers on
``/<group>/bridge/feedback`` (accepted, then done or error; paused / resumed / stopped for the
control commands), and publishes ``/joint_states`` and ``/<group>/tcp_pose`` periodically.
One primitive runs per group at a time; a second one is refused as BUSY rather than queued,
because a machine that sends two primitives at once has lost track of its robot.  A command id
is carried out once: a machine re-sends a command it got no answer for (it may have been lost
before DDS discovery matched the topics), so a repeated id is not run again -- its latest
feedback is repeated instead, or nothing while it is still being taken up.

A ``measure`` command asks where an idle group is (answered ``measured`` with a MotionResult):
the machine fixes a relative move's absolute goal from it before sending the move, so a retry can
be re-based instead of repeating it.

Every failure becomes an ``error`` feedback naming the command: garbage on the command topic is
reported (it has no id to answer), a back-end exception is reported even when it is a bug.
"""
from __future__ import annotations

import asyncio
import logging
import types
from collections import OrderedDict
from collections.abc import Coroutine, Generator
from typing import Any

from core_functions.primitives import PrimitiveResult, describe
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.msgs import Header, JointState, Point, Pose, PoseStamped, Quaternion, TFMessage
from node_transport.bounded import declare_bounded
from node_transport.port import Node, Publisher
from node_transport.qos import COMMANDS, LATCHED, SENSOR
from node_transport.qos import JOINT_STATES as JOINT_STATES_QOS
from node_transport.wire import (
    ENGINE_CELL,
    ENGINE_STATUS,
    JOINT_STATES,
    BridgeCommand,
    BridgeFeedback,
    CellSnapshot,
    EngineStatus,
    bridge_topic,
    tcp_pose_topic,
)
from robot_bridges.backend import BridgeError, FaultKind, RobotBackend
from robot_bridges.camera.ros_camera import attach_cameras
from robot_bridges.robot_state import RobotStatePublisher, publish_mount
from robot_bridges.trajectory_server import TrajectoryServers, declare_controllers
from robot_bridges.turnaround import Turnaround

log = logging.getLogger(__name__)


def start_now(coro: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None] | None:
    """Run ``coro`` up to its first wait here and now: the task that carries it on from there, or None
    when it finished without waiting.  A primitive that is over in its first step then costs no task
    and no turn of the loop (what Python 3.12's eager tasks do); one that waits goes on as a task."""
    try:
        waiting = coro.send(None)
    except StopIteration:
        return None
    return asyncio.get_running_loop().create_task(_carry_on(coro, waiting), name=name)


@types.coroutine
def _carry_on(coro: Coroutine[Any, Any, None], waiting: Any) -> Generator[Any, Any, None]:
    """Steps ``coro`` on from its first wait, as a task steps a coroutine: what the task is sent or
    thrown (a cancellation) goes into it, what it waits on goes up to the task."""
    while True:
        try:
            sent = yield waiting
        except BaseException as error:  # noqa: BLE001 - passed on: the coroutine decides, as under a task
            try:
                waiting = coro.throw(error)
            except StopIteration:
                return
        else:
            try:
                waiting = coro.send(sent)
            except StopIteration:
                return
_REMEMBERED_IDS = 256  # command ids a re-sent command is recognised by (a machine keeps far fewer waiting)


class BridgeNode:
    """Binds one back end to the transport through one node."""

    def __init__(self, node: Node, backend: RobotBackend) -> None:
        self.node = node
        self.backend = backend
        self.clock = node.clock
        self.state_period = float(declare_bounded(node, "state_period", 0.05, "joint_states / tcp_pose period (s)"))
        self.stop_timeout = float(declare_bounded(node, "stop_timeout", 5.0, "longest a stopped primitive may take to end (s)"))
        self._controllers = declare_controllers(node, backend.groups)  # FollowJointTrajectory per group (trajectory_server.py)
        self.trajectories: TrajectoryServers | None = None
        self._feedback: dict[str, TypedPublisher[BridgeFeedback]] = {}
        self._answered: OrderedDict[str, BridgeFeedback | None] = OrderedDict()  # command id -> latest feedback
        self._running: dict[str, asyncio.Task[None]] = {}
        self._tasks: set[asyncio.Task[None]] = set()
        self._joint_pub = node.create_publisher(JointState, JOINT_STATES, JOINT_STATES_QOS)
        self._tcp_pubs = {g: node.create_publisher(PoseStamped, tcp_pose_topic(g), SENSOR) for g in backend.groups}
        self._robot_state = RobotStatePublisher.for_backend(node, backend)  # robot_description, tf: for RViz
        self._mount: Publisher[TFMessage] | None = None
        for group in backend.groups:
            self._feedback[group] = TypedPublisher(node, BridgeFeedback, bridge_topic(group, "feedback"), COMMANDS)
        subscribe(node, CellSnapshot, ENGINE_CELL, self.backend.set_cell, lambda error: self._report(f"ignored cell model: {error}"), LATCHED)
        # the operator's speed override travels in the engine's status: every motion on its path at that share
        subscribe(node, EngineStatus, ENGINE_STATUS, self._on_engine, lambda error: self._report(f"ignored engine status: {error}"), LATCHED)
        self._camera = attach_cameras(node, backend)  # camera parameters: publish_images, camera_source (ROS image topics)
        self._state_task: asyncio.Task[None] | None = None
        self.errors: list[str] = []
        self.turnaround: Turnaround | None = None  # hold_turnarounds(): a paced simulator in its own process
        #: joints another node of this graph publishes on joint_states under these very names -- a ros2-control
        #: robot's driver -- left out of the bridge's: a copy would reach the back end (which reads the driver's)
        #: as fresh samples and hide a driver that stopped
        self.graph_joints: frozenset[str] = frozenset()

    # ---------------------------------------------------------------------------- lifecycle
    async def start(self) -> None:
        """Start the back end, then listen for commands.

        The command subscriptions exist only once the robot is ready: a machine uses a bridge
        only after discovery has matched it, so no primitive reaches a back end still in its
        start-up (the KUKA RSI handshake takes seconds; a move sent into it was never carried
        out), and a bridge that fails to start is never matched at all.
        """
        await self.backend.start()
        if self._robot_state is None:  # a placed robot its own driver draws: its base on tf_static (its root known once started)
            self._mount = publish_mount(self.node, self.backend)
        self.trajectories = TrajectoryServers(self.node, self.backend, self._controllers, self.primitive_running, self.state_period)
        for group in self.backend.groups:
            subscribe(
                self.node, BridgeCommand, bridge_topic(group, "command"), lambda command, g=group: self._on_command(g, command),
                lambda error: self._report(f"rejected command: {error}"), COMMANDS, hand_over=True,
            )  # a hand-over (node_transport/local.py): a primitive starts inside the machine's publish, up to its first wait
        self._state_task = asyncio.get_running_loop().create_task(self._publish_state_loop(), name="bridge state")

    async def close(self) -> None:
        if self.turnaround is not None:
            self.turnaround.release_all()
        for task in [*self._running.values(), *self._tasks]:
            task.cancel()
        if self._state_task:
            self._state_task.cancel()
        await asyncio.gather(*self._running.values(), *self._tasks, return_exceptions=True)
        if self._state_task:
            await asyncio.gather(self._state_task, return_exceptions=True)
        if self.trajectories is not None:
            await self.trajectories.close()
        await self.backend.close()
        self.node.destroy()

    def hold_turnarounds(self) -> None:
        """Robot time stands still while a group's next step is on its way from another process
        (:mod:`robot_bridges.turnaround`); for a paced simulator's bridge in a process of its own."""
        self.turnaround = Turnaround(
            self.node, asyncio.get_running_loop(), self.backend.groups,
            lambda: [group for group, task in self._running.items() if not task.done()],
        )

    # ------------------------------------------------------------------------------ inbound
    def _on_command(self, group: str, command: BridgeCommand) -> None:
        if command.group != group:
            source = self.node.resolve(bridge_topic(group, "command"))
            self._send(group, command.id, "error", error=f"command for group {command.group!r} arrived on {source}", fault=FaultKind.PROTOCOL)
            return
        if self.turnaround is not None:
            self.turnaround.commanded(group)
        if command.id in self._answered:  # re-sent: carried out once, answered again
            latest = self._answered[command.id]
            if latest is not None:
                self._feedback[group].publish(latest)
            return
        self._answered[command.id] = None
        if len(self._answered) > _REMEMBERED_IDS:
            self._answered.popitem(last=False)
        held = self.trajectories.holder(group) if self.trajectories is not None and command.op in ("execute", "measure") else None
        if held is not None:  # an action client moves the group: the engine's run and it never command it at once
            self._send(group, command.id, "error", error=f"{FaultKind.BUSY.value}: {held}: {command.op} refused", fault=FaultKind.BUSY)
            return
        if command.op == "execute":
            self._start_execute(command)
        elif command.op == "measure":
            self._spawn(self._measure(command))
        else:
            self._spawn(self._control(command))

    def _on_engine(self, status: EngineStatus) -> None:
        """A new speed override scales the running motion (and every later one) on its path: robot_bridges/path_rate.py."""
        rate = status.speed_override / 100.0
        if rate == self.backend.speed_override:
            return
        try:
            self.backend.set_speed_override(rate)
        except Exception as error:  # noqa: BLE001 - a back end that cannot take it is a fault, reported
            self.node.report_fault(f"speed override {status.speed_override:g} %", error)

    def primitive_running(self, group: str) -> bool:
        """Whether a machine's primitive runs on ``group`` now."""
        busy = self._running.get(group)
        return busy is not None and not busy.done()

    def _start_execute(self, command: BridgeCommand) -> None:
        group = command.group
        busy = self._running.get(group)
        if busy is not None and not busy.done():
            self._send(group, command.id, "error", error=f"{FaultKind.BUSY.value}: {group} is already executing a primitive", fault=FaultKind.BUSY)
            return
        task = start_now(self._execute(command), f"bridge {group} {command.id}")
        if task is None:  # done in its first step (set_speed, an I/O toggle): 'done' is sent already
            self._running.pop(group, None)
            return
        self._running[group] = task
        self._send(group, command.id, "accepted")  # a long primitive is under way

    async def _execute(self, command: BridgeCommand) -> None:
        assert command.primitive is not None
        group = command.group
        try:
            result = await self.backend.execute(group, command.primitive)
        except BridgeError as error:
            self._send(group, command.id, "error", error=str(error), fault=error.kind)
        except asyncio.CancelledError:
            self._send(group, command.id, "error", error=f"{FaultKind.STOPPED.value}: bridge shutting down", fault=FaultKind.STOPPED)
            raise
        except Exception as error:  # noqa: BLE001 - a back-end defect must still reach the machine
            log.exception("%s: %s failed", self.backend.name, describe(command.primitive))
            self._send(group, command.id, "error", error=f"{FaultKind.INTERNAL.value}: {type(error).__name__}: {error}", fault=FaultKind.INTERNAL)
        else:
            self._send(group, command.id, "done", result=result)

    async def _control(self, command: BridgeCommand) -> None:
        group = command.group
        status = {"pause": "paused", "resume": "resumed", "stop": "stopped"}[command.op]
        try:
            await getattr(self.backend, command.op)(group)
            if command.op == "stop":
                await self._await_stopped(group)
        except BridgeError as error:
            self._send(group, command.id, "error", error=str(error), fault=error.kind)
        except Exception as error:  # noqa: BLE001
            log.exception("%s: %s of %s failed", self.backend.name, command.op, group)
            self._send(group, command.id, "error", error=f"{FaultKind.INTERNAL.value}: {type(error).__name__}: {error}", fault=FaultKind.INTERNAL)
        else:
            self._send(group, command.id, status)

    async def _measure(self, command: BridgeCommand) -> None:
        group = command.group
        busy = self._running.get(group)
        try:
            if busy is not None and not busy.done():  # the machine measures only between primitives
                raise BridgeError(FaultKind.BUSY, f"{group} is executing a primitive: no measurement now")
            result = await self.backend.measure(group)
        except BridgeError as error:
            self._send(group, command.id, "error", error=str(error), fault=error.kind)
        except Exception as error:  # noqa: BLE001 - a back-end defect must still reach the machine
            log.exception("%s: measuring %s failed", self.backend.name, group)
            self._send(group, command.id, "error", error=f"{FaultKind.INTERNAL.value}: {type(error).__name__}: {error}", fault=FaultKind.INTERNAL)
        else:
            self._send(group, command.id, "measured", result=result)

    async def _await_stopped(self, group: str) -> None:
        """'stopped' promises the primitive is over, so the group can take the next one at once."""
        task = self._running.get(group)
        if task is None or task.done():
            return
        try:
            await self.clock.wait_for(asyncio.shield(task), self.stop_timeout)
        except asyncio.TimeoutError:
            raise BridgeError(FaultKind.TIMEOUT, f"{group}: the primitive did not stop within {self.stop_timeout:g} s") from None

    # ----------------------------------------------------------------------------- outbound
    def _send(
        self, group: str, command_id: str, status: str, *, error: str | None = None, fault: FaultKind | None = None, result: PrimitiveResult | None = None
    ) -> None:
        """One feedback message; an error carries its FaultKind, so the machine need not parse text."""
        feedback = BridgeFeedback(id=command_id, group=group, status=status, error=error, fault=fault, result=result, t=self.clock.now())  # type: ignore[arg-type]
        if command_id in self._answered:
            self._answered[command_id] = feedback
        self._feedback[group].publish(feedback)
        if self.turnaround is not None and status in ("done", "measured"):
            self.turnaround.hold(group)

    def _report(self, text: str) -> None:
        self.errors.append(text)
        self.node.logger.error("%s: %s", self.node.fully_qualified_name, text)

    def _spawn(self, coro: object) -> None:
        task = asyncio.get_running_loop().create_task(coro)  # type: ignore[arg-type]
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def publish_state(self) -> None:
        """Publish joint_states and every TCP pose once."""
        stamp = self.node.now_stamp()
        names, positions = self.backend.joint_state()
        if self.graph_joints:
            kept = [(n, p) for n, p in zip(names, positions) if n not in self.graph_joints]
            if kept:
                self._joint_pub.publish(JointState(header=Header(stamp=stamp), name=tuple(n for n, _ in kept), position=tuple(p for _, p in kept)))
        else:
            self._joint_pub.publish(JointState(header=Header(stamp=stamp), name=tuple(names), position=tuple(positions)))
        if self._robot_state is not None:
            self._robot_state.publish(names, positions, stamp)
        if self.trajectories is not None:
            self.trajectories.publish_state()
        for group, pub in self._tcp_pubs.items():
            pose = self.backend.tcp_pose(group)
            if pose is None:
                continue
            msg_pose = Pose(Point(pose.x, pose.y, pose.z), Quaternion(pose.qx, pose.qy, pose.qz, pose.qw))
            pub.publish(PoseStamped(header=Header(stamp=stamp, frame_id=self.backend.world_frame), pose=msg_pose))

    async def _publish_state_loop(self) -> None:
        while True:
            try:
                self.publish_state()
            except Exception as error:  # noqa: BLE001 - reported; the loop keeps the robot visible
                self.node.report_fault("joint state publishing", error)
            await self.clock.sleep(self.state_period)
