"""Every bridge serves control_msgs/action/FollowJointTrajectory per group, as ros2_control's joint_trajectory_controller does.

For each group whose limits the back end knows (:meth:`RobotBackend.joint_limits`), the bridge node
serves the action at ``<controller>/follow_joint_trajectory`` and publishes
``control_msgs/msg/JointTrajectoryControllerState`` on ``<controller>/controller_state``, where
``<controller>`` is the node parameter ``controller_name`` with ``{group}`` replaced
(``{group}_controller`` by default: ``left_arm_controller``, ``arm_controller``; empty: no action).
The names are relative, resolved in the node's namespace, as the bridge's other topics.  The action is
:class:`node_transport.action.ActionServer` (rcl_action on the wire), so it works over the local, DDS
and rclpy transports alike; MoveIt 2's simple controller manager drives the bridge through it.

How goals are taken, as joint_trajectory_controller takes them where it can, and where not, why:

* A goal is checked (:func:`~robot_bridges.trajectory_goal.plan_goal`) and, when refused, ends ABORTED
  with the action's error code and a message naming the joint and the point in ``error_string``.
  joint_trajectory_controller rejects such a goal in its goal response, which carries no reason;
  here the goal is accepted and ends at once, so the client reads why (MoveIt logs it).
* A goal for a group the engine's run holds (``execution_engine/status``: a run in progress with the
  group in it), or whose bridge is executing a machine's primitive, is refused (INVALID_GOAL, naming
  the run); while a goal holds a group, the bridge refuses the machines' primitives for it (BUSY,
  naming the goal).  So the engine and an action client never command one group at once.
* The cell's pause (the engine paused by an operator) stops a running goal's
  arm on its path and the path's time with it; the engine's resume goes on with the rest of the path
  from where the arm stands (:func:`~robot_bridges.trajectory_goal.continued`).  A ``true`` on
  ``cell/safety_stop`` stops a running goal on its path and ends it (PATH_TOLERANCE_VIOLATED, saying
  so): clearing the stop restarts nothing; a new goal is needed.  New goals are refused while the
  cell is paused or the safety stop is on.
* A new valid goal preempts the running one: the running goal ends ABORTED with INVALID_GOAL
  ("preempted"), as joint_trajectory_controller ends it.  The arm stops on its path first (the back
  ends cannot blend one motion into another) and the new path starts from where it stopped.  A new
  goal that is refused leaves the running one alone.
* Cancel stops the arm on its path and the goal ends CANCELED.
"""
from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from node_transport import mirrors
from node_transport.action import CLOSE_GRACE, ActionServer, GoalHandle
from node_transport.carriage import subscribe
from node_transport.clock import Clock
from node_transport.msgs import Bool, Header
from node_transport.port import Node, TransportError
from node_transport.qos import COMMANDS, LATCHED
from node_transport.wire import ENGINE_STATUS, SAFETY_STOP, EngineStatus
from robot_bridges.backend import BridgeError, JointLimits, RobotBackend
from robot_bridges.trajectory_follow import Follower, Sample
from robot_bridges.trajectory_goal import (
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    Feedback,
    FollowJointTrajectory,
    Refused,
    Result,
    plan_goal,
    point_message,
)

log = logging.getLogger(__name__)

JointTrajectoryControllerState = mirrors.mirror("control_msgs/msg/JointTrajectoryControllerState")
#: Engine states in which a run holds its groups (execution_engine/engine/run_action.py's busy states).
RUN_STATES = ("running", "paused", "stepping", "error", "alarm", "stopping")
DEFAULT_CONTROLLER = "{group}_controller"


def declare_controllers(node: Node, groups: tuple[str, ...]) -> dict[str, str]:
    """Declare the ``controller_name`` parameter: ``{group: controller}``; a name that cannot be one ends
    the node's start-up as a mistyped parameter does (TransportError naming the node)."""
    template = str(node.declare_parameter(
        "controller_name", DEFAULT_CONTROLLER,
        "FollowJointTrajectory per group at <controller_name>/follow_joint_trajectory, {group} replaced by the group ('' = none)",
    ))
    try:
        return controller_names(template, groups)
    except ValueError as error:
        raise TransportError(f"{node.fully_qualified_name}: parameter 'controller_name': {error}") from None


def controller_names(template: str, groups: tuple[str, ...]) -> dict[str, str]:
    """``{group: controller}`` from the ``controller_name`` parameter; ValueError naming what is wrong."""
    if not template:
        return {}
    if template.count("{group}") != 1 and len(groups) > 1:
        raise ValueError(f"controller_name {template!r} must contain {{group}} once: the bridge has groups {', '.join(groups)}")
    names = {g: template.replace("{group}", g) for g in groups}
    for name in names.values():
        if not name or any(c in name for c in "{} ") or name.endswith("/"):
            raise ValueError(f"controller_name {template!r} gives {name!r}, not a ROS name")
    return names


@dataclass
class _Goal:
    handle: GoalHandle
    follower: Follower | None = None
    ending: tuple[int, str] | None = None  # ended before it moved (cancel, preemption)
    done: asyncio.Event = field(default_factory=asyncio.Event)


class CellGate:
    """What the rest of the cell says about commanding a group: the engine's run, its pause, the safety stop."""

    def __init__(self, node: Node, changed: Callable[[], None]) -> None:
        self.node = node
        self.engine: EngineStatus | None = None
        self.safety = False
        self._changed = changed
        subscribe(node, EngineStatus, ENGINE_STATUS, self._on_status, lambda error: node.logger.warning("ignored engine status: %s", error), LATCHED)
        node.create_subscription(Bool, SAFETY_STOP, self._on_safety, LATCHED)

    def _on_status(self, status: EngineStatus) -> None:
        self.engine = status
        self._changed()

    def _on_safety(self, msg: Bool) -> None:
        self.safety = bool(msg.data)
        self._changed()

    @property
    def paused(self) -> bool:
        return self.safety or (self.engine is not None and self.engine.state == "paused")

    def refusal(self, group: str) -> str | None:
        """Why no goal may move ``group`` now, or None."""
        if self.safety:
            return f"{group}: the cell's safety stop is on ({self.node.resolve(SAFETY_STOP)})"
        status = self.engine
        if status is None:
            return None
        if status.state == "paused":
            return f"{group}: the cell is paused ({self.node.resolve(ENGINE_STATUS)}: paused): resume it first"
        if status.state in RUN_STATES and group in status.groups:
            return (
                f"{group}: the engine's run of application {status.app!r} holds the group "
                f"({self.node.resolve(ENGINE_STATUS)}: {status.state}): no FollowJointTrajectory goal until it ends"
            )
        return None


class GroupTrajectoryServer:
    """The FollowJointTrajectory action and controller state of one group."""

    def __init__(
        self, node: Node, backend: RobotBackend, group: str, controller: str, limits: JointLimits, gate: CellGate,
        primitive_running: Callable[[str], bool], clock: Clock, period: float,
    ) -> None:
        self.node, self.backend, self.group, self.limits, self.gate, self.clock, self.period = node, backend, group, limits, gate, clock, period
        self.primitive_running = primitive_running
        self.action_name = node.resolve(f"{controller}/follow_joint_trajectory")
        self.server = ActionServer(node, FollowJointTrajectory, self.action_name, execute=self._execute, accept=lambda goal: None, cancel=self._cancel)
        self._state = node.create_publisher(JointTrajectoryControllerState, f"{controller}/controller_state", COMMANDS)
        self._goals: dict[tuple[int, ...], _Goal] = {}
        self._current: _Goal | None = None  # the newest goal past its checks: it holds the group
        self._turn = asyncio.Lock()  # one goal moves the group at a time; a preempted one ends first
        self._tasks: set[asyncio.Task[None]] = set()

    # ------------------------------------------------------------------------------ holding
    def holder(self) -> str | None:
        """The goal holding the group, in words for a refused primitive; None when none does."""
        goal = self._current
        if goal is None:
            return None
        uuid = bytes(goal.handle.goal_id.uuid).hex()
        return f"{self.group} is following FollowJointTrajectory goal {uuid[:8]} from {self.action_name}"

    # ----------------------------------------------------------------------------- goals
    async def _execute(self, handle: GoalHandle) -> Any:
        entry = self._goals[tuple(handle.goal_id.uuid)] = _Goal(handle)
        try:
            code, text = await self._follow(entry)
        finally:
            self._goals.pop(tuple(handle.goal_id.uuid), None)
            if self._current is entry:
                self._current = None
            entry.done.set()
        handle.aborted = code != SUCCESSFUL
        if code != SUCCESSFUL or text:
            log_at = logging.INFO if handle.cancel_requested else logging.WARNING
            self.node.logger.log(log_at, "%s: %s", self.action_name, text)
        return Result(code, text)

    async def _follow(self, entry: _Goal) -> tuple[int, str]:
        handle = entry.handle
        try:
            self._check(handle.goal, self._positions())  # refused before anything changes: the running goal goes on
        except Refused as refused:
            return refused.code, str(refused)
        previous, self._current = self._current, entry
        if previous is not None:
            self._end(previous, INVALID_GOAL, f"{self.group}: preempted by a new goal on {self.action_name}; the arm stopped on its path")
        async with self._turn:
            if entry.ending is not None:
                return entry.ending
            if handle.cancel_requested:
                return SUCCESSFUL, f"{self.group}: cancelled before it moved"
            try:
                measured = await self.backend.measure(self.group)  # where the arm is by the robot's word, after any stop
                names = list(measured.joint_names)
                plan = self._check(handle.goal, [measured.positions[names.index(n)] for n in self.limits.joint_names])
            except Refused as refused:
                return refused.code, str(refused)
            except BridgeError as error:
                return INVALID_GOAL, f"{self.group}: where the arm is could not be known: {error}"
            if entry.ending is not None:
                return entry.ending
            name = f"follow_joint_trajectory {bytes(handle.goal_id.uuid).hex()[:8]}"
            follower = entry.follower = Follower(self.backend, self.group, plan, self.limits, self.clock, self.period, name, lambda s: self._feedback(handle, s))
            if self.gate.paused:
                await follower.hold()
            return await follower.run()

    def _check(self, goal: Any, current: list[float]) -> Any:
        refusal = self.gate.refusal(self.group)
        if refusal is None and self.primitive_running(self.group):
            refusal = f"{self.group} is executing a primitive of its group machine: no FollowJointTrajectory goal until the engine's run ends"
        if refusal is not None:
            raise Refused(INVALID_GOAL, refusal)
        return plan_goal(self.group, goal, self.limits, current, self.node.now_stamp().to_seconds())

    def _positions(self) -> list[float]:
        names, positions = self.backend.joint_state()
        return [positions[names.index(n)] for n in self.limits.joint_names]

    def _cancel(self, handle: GoalHandle) -> None:
        entry = self._goals.get(tuple(handle.goal_id.uuid))
        if entry is not None:
            self._end(entry, SUCCESSFUL, f"{self.group}: cancelled; the arm stopped on its path")

    def _end(self, entry: _Goal, code: int, reason: str) -> None:
        """End a goal early: a running one stops the arm on its path, one still waiting never moves."""
        if entry.ending is None:
            entry.ending = (code, reason)
        follower = entry.follower
        if follower is not None:
            follower.end(code, reason)
            self._spawn(follower.stop_backend(), f"{self.action_name}: stopping")

    def cell_changed(self) -> None:
        """The cell paused, resumed or raised its safety stop: hold, release or end the running goal."""
        entry = self._current
        if entry is None or entry.follower is None:
            return
        follower = entry.follower
        if self.gate.safety:
            self._end(entry, PATH_TOLERANCE_VIOLATED, (
                f"{self.group}: the cell's safety stop ({self.node.resolve(SAFETY_STOP)}) stopped the arm on its path; "
                "the goal ends here, send a new one once the stop is cleared"
            ))
        elif self.gate.paused:
            self._spawn(follower.hold(), f"{self.action_name}: hold")
        else:
            self._spawn(follower.release(), f"{self.action_name}: release")

    # ---------------------------------------------------------------------------- outbound
    def _feedback(self, handle: GoalHandle, sample: Sample) -> None:
        feedback = Feedback(
            header=Header(stamp=self.node.now_stamp()), joint_names=self.limits.joint_names,
            desired=point_message(sample.desired, sample.desired_velocity, sample.t),
            actual=point_message(sample.actual, sample.actual_velocity, sample.t),
            error=point_message(sample.error, sample.desired_velocity - sample.actual_velocity, sample.t),
        )
        self.server.publish_feedback(handle, feedback)

    def publish_state(self) -> None:
        """The controller's state (joint_trajectory_controller's ``~/controller_state``): the reference
        is the running path, or where the arm holds without one."""
        if self._state.get_subscription_count() == 0:
            return
        entry = self._current
        sample = entry.follower.latest if entry is not None and entry.follower is not None else None
        if sample is None:
            here = np.array(self._positions())
            sample = Sample(0.0, here, np.zeros_like(here), here, np.zeros_like(here))
        reference = point_message(sample.desired, sample.desired_velocity, sample.t)
        self._state.publish(JointTrajectoryControllerState(
            header=Header(stamp=self.node.now_stamp()), joint_names=self.limits.joint_names, reference=reference,
            feedback=point_message(sample.actual, sample.actual_velocity, sample.t),
            error=point_message(sample.error, sample.desired_velocity - sample.actual_velocity, sample.t),
            output=reference, speed_scaling_factor=1.0,
        ))

    def _spawn(self, coro: Any, name: str) -> None:
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        error = None if task.cancelled() else task.exception()
        if error is not None:
            self.node.report_fault(task.get_name(), error)

    async def close(self) -> None:
        """Every goal ends ("the bridge is shutting down"), the arm stopped on its path; bounded by the action
        server's close and :data:`CLOSE_GRACE` for the stops under way: a node stops on SIGTERM within 2 s."""
        for entry in list(self._goals.values()):
            self._end(entry, INVALID_GOAL, f"{self.group}: the bridge is shutting down")
        await self.server.close()
        if not self._tasks:
            return
        stops = asyncio.gather(*self._tasks, return_exceptions=True)
        try:  # the stops asked for end on their own (the arm held on its path), or are cancelled
            await self.node.clock.wait_for(asyncio.shield(stops), CLOSE_GRACE)
        except asyncio.TimeoutError:
            for task in list(self._tasks):
                task.cancel()
            try:
                await self.node.clock.wait_for(asyncio.shield(stops), CLOSE_GRACE)
            except asyncio.TimeoutError:
                self.node.logger.warning("%s: %d task(s) did not end at the bridge's close", self.action_name, len(self._tasks))


class TrajectoryServers:
    """Every group's FollowJointTrajectory server of one bridge node (see the module's docstring)."""

    def __init__(self, node: Node, backend: RobotBackend, controllers: dict[str, str], primitive_running: Callable[[str], bool], period: float) -> None:
        self.node = node
        clock = backend.clock or node.clock  # the path's time is the robot's (a simulator may run faster than the node's clock)
        self.groups: dict[str, GroupTrajectoryServer] = {}  # before the gate: a latched status may arrive as it subscribes
        self.gate = CellGate(node, self._cell_changed)
        for group, controller in controllers.items():
            limits = backend.joint_limits(group)
            if limits is None:
                node.logger.info("%s: no joint limits known for %s: no FollowJointTrajectory action for it", backend.name, group)
                continue
            try:
                self.groups[group] = GroupTrajectoryServer(node, backend, group, controller, limits, self.gate, primitive_running, clock, period)
            except TransportError as error:  # rclpy without control_msgs installed: the bridge still serves the engine
                node.logger.warning(
                    "%s: no FollowJointTrajectory action for %s: %s (install control_msgs and trajectory_msgs: rosdep install --from-paths src)",
                    node.fully_qualified_name, group, error,
                )

    def holder(self, group: str) -> str | None:
        server = self.groups.get(group)
        return None if server is None else server.holder()

    def _cell_changed(self) -> None:
        for server in self.groups.values():
            server.cell_changed()

    def publish_state(self) -> None:
        for server in self.groups.values():
            server.publish_state()

    async def close(self) -> None:
        await asyncio.gather(*(server.close() for server in self.groups.values()))
