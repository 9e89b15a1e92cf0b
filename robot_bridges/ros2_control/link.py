"""How the ros2-control back end reaches a robot: a ROS graph's controllers, or its own model (the dry run).

:class:`GraphLink` is a client of what a ros2_control driver offers: ``/robot_description``,
``/joint_states`` (every sample through :class:`~.feed.JointFeed`), one FollowJointTrajectory action
per group and, where configured, a GripperCommand action and a tool's std_srvs/SetBool service.  :class:`ModelLink` answers the same calls
from the URDF alone -- a trajectory is followed on the back end's clock, sample by sample, so a dry
run's timeline and a pause inside a motion behave as on the robot -- and never touches a controller.
"""
from __future__ import annotations

import asyncio
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from node_transport import mirrors
from node_transport.action import GoalStatus
from node_transport.action_client import ActionClient, ActionError, ClientGoal
from node_transport.clock import Clock
from node_transport.msgs import JointState, String
from node_transport.port import Node, ServiceUnavailable, poll_until
from node_transport.qos import ROBOT_DESCRIPTION, Durability, History, QoS, Reliability
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.ros2_control.feed import JointFeed
from robot_bridges.ros2_control.options import GroupSettings, Ros2ControlSettings
from robot_bridges.ros2_control.planning import Timed
from robot_bridges.trajectory_goal import FollowJointTrajectory, point_message

GripperCommand = mirrors.action("control_msgs/action/GripperCommand")
GripperCommandMsg = mirrors.mirror("control_msgs/msg/GripperCommand")
SetBool = mirrors.service("std_srvs/srv/SetBool")
JointTrajectory = mirrors.mirror("trajectory_msgs/msg/JointTrajectory")
ControllerState = mirrors.mirror("control_msgs/msg/JointTrajectoryControllerState")
#: /joint_states as joint_state_broadcaster offers it (reliable) or a driver (best effort): best effort takes both.
#: 100 samples: a second of joint_state_broadcaster at 100 Hz, so a process that falls behind for a moment (a loaded
#: machine, images decoded beside the states) still sees every sample, not two a fraction of a second apart (a "jump").
STATE_QOS = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_LAST, 100)
FJT_CODES = {0: "SUCCESSFUL", -1: "INVALID_GOAL", -2: "INVALID_JOINTS", -3: "OLD_HEADER_TIMESTAMP", -4: "PATH_TOLERANCE_VIOLATED", -5: "GOAL_TOLERANCE_VIOLATED"}
SUCCEEDED, CANCELED = "succeeded", "canceled"
#: s between the checks of a running motion (the joint states' age, a pause)
WATCH_PERIOD = 0.02
GRIP_MODEL_TIME = 0.5  # s a modelled gripper takes
TOOL_MODEL_TIME = 0.1  # s a modelled tool's service takes to answer


class ControllerLink(ABC):
    """What the back end needs of a robot; ``feed`` holds its trusted joint states once started."""

    feed: JointFeed

    @abstractmethod
    async def description(self) -> str:
        """The robot's URDF."""

    @abstractmethod
    async def start(self, feed: JointFeed) -> None:
        """Connect (raise BridgeError naming the option of what is missing) and wait for the first states."""

    @abstractmethod
    async def follow(self, group: GroupSettings, timed: Timed) -> str:
        """Play ``timed`` on ``group``'s joints to its end: SUCCEEDED, or CANCELED after :meth:`cancel`;
        BridgeError with the controller's words otherwise."""

    @abstractmethod
    async def cancel(self, group: GroupSettings) -> None:
        """Stop the group's running trajectory (the controller holds where the arm is)."""

    @abstractmethod
    async def grip(self, group: GroupSettings, position: float) -> None:
        """Move the group's gripper to ``position`` (m) and wait until it is there or holds a part."""

    @abstractmethod
    async def set_tool(self, group: GroupSettings, on: bool) -> None:
        """Switch the group's tool on or off through its SetBool service; BridgeError with the driver's words if it says no."""

    def trouble(self) -> str | None:
        """Why the robot's state cannot be trusted now (a bad or stale joint_states), or None."""
        return self.feed.stale(self.settings.state_timeout)  # type: ignore[attr-defined]

    async def close(self) -> None:  # noqa: B027 - nothing to release by default
        """Release what the link holds."""


def trajectory_goal(joints: tuple[str, ...], timed: Timed) -> Any:
    """A FollowJointTrajectory goal that starts when it arrives (a zero header stamp, as MoveIt sends)."""
    points = tuple(point_message(p, v, float(t)) for t, p, v in zip(timed.times, timed.points, timed.velocities))
    return FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=joints, points=points))


@dataclass
class _Running:
    client: ActionClient
    goal: ClientGoal
    canceled: bool = False


class GraphLink(ControllerLink):
    """A ros2_control driver's interfaces on ``node`` (any transport: DDS, rclpy, local for tests)."""

    def __init__(self, node: Node, settings: Ros2ControlSettings) -> None:
        self.node, self.settings, self.clock = node, settings, node.clock
        self.controllers: dict[str, ActionClient] = {}
        self.grippers: dict[str, ActionClient] = {}
        self.tools: dict[str, Any] = {}  # group -> its tool's SetBool client
        self.controller_joints: dict[str, tuple[str, ...]] = {}
        self.running: dict[str, _Running] = {}
        self.cancel_pending: set[str] = set()  # a cancel that came while the goal was on its way
        self._description: str | None = None

    async def description(self) -> str:
        if self.settings.urdf is not None:
            with open(self.settings.urdf, encoding="utf-8") as file:
                return file.read()

        def keep(msg: String) -> None:
            self._description = msg.data

        self.node.create_subscription(String, "/robot_description", keep, ROBOT_DESCRIPTION)
        if not await poll_until(self.clock, lambda: self._description is not None, self.settings.start_timeout, WATCH_PERIOD):
            raise BridgeError(FaultKind.CONNECTION, f"no /robot_description in {self.settings.start_timeout:g} s (start_timeout): is "
                              "robot_state_publisher running in this ROS_DOMAIN_ID? Or give the URDF with the option urdf=FILE")
        assert self._description is not None
        return self._description

    async def start(self, feed: JointFeed) -> None:
        self.feed = feed
        self.node.create_subscription(JointState, "/joint_states", feed.on_message, STATE_QOS)
        for group in self.settings.groups:
            self.controllers[group.group] = ActionClient(self.node, FollowJointTrajectory, group.controller)
            state_topic = group.controller.rsplit("/", 1)[0] + "/controller_state" if "/" in group.controller.strip("/") else ""
            if state_topic:
                self.node.create_subscription(ControllerState, state_topic, self._state_keeper(group.group), STATE_QOS)
            if group.gripper is not None:
                self.grippers[group.group] = ActionClient(self.node, GripperCommand, group.gripper)
            if group.tool_service is not None:
                self.tools[group.group] = self.node.create_client(SetBool, group.tool_service)
        timeout = self.settings.start_timeout
        for group in self.settings.groups:
            if not await self.controllers[group.group].wait_for_server(timeout):
                raise BridgeError(FaultKind.CONNECTION, f"{group.group}: no FollowJointTrajectory server at {group.controller} in {timeout:g} s "
                                  f"(option {group.group}.controller): is the controller spawned and active?")
            if group.group in self.grippers and not await self.grippers[group.group].wait_for_server(timeout):
                raise BridgeError(FaultKind.CONNECTION, f"{group.group}: no GripperCommand server at {group.gripper} in {timeout:g} s (option {group.group}.gripper)")
            if group.group in self.tools and not await self.tools[group.group].wait_for_service(timeout):
                raise BridgeError(FaultKind.CONNECTION, f"{group.group}: no std_srvs/srv/SetBool service at {group.tool_service} in {timeout:g} s "
                                  f"(option {group.group}.tool_service)")
        if not await poll_until(self.clock, lambda: feed.latest is not None or feed.fault is not None, timeout, WATCH_PERIOD):
            joints = sorted(feed.speeds)
            raise BridgeError(FaultKind.CONNECTION, f"no /joint_states with the joints {', '.join(joints)} in {timeout:g} s: is joint_state_broadcaster "
                              "running, and are the groups' joints (options GROUP.joints) the controller's names?")
        if feed.fault is not None:
            raise BridgeError(FaultKind.CONTROLLER, feed.fault)
        await poll_until(self.clock, lambda: len(self.controller_joints) == len(self.settings.groups), min(timeout, 1.0), WATCH_PERIOD)
        for group in self.settings.groups:
            served = self.controller_joints.get(group.group)
            if served is not None and set(group.joints) != set(served):
                raise BridgeError(FaultKind.CONNECTION, f"{group.group}: the controller at {group.controller} drives {', '.join(served)}, "
                                  f"the group is configured with {', '.join(group.joints)} (option {group.group}.joints)")

    def _state_keeper(self, group: str) -> Any:
        def keep(msg: Any) -> None:
            self.controller_joints.setdefault(group, tuple(msg.joint_names))
        return keep

    async def follow(self, group: GroupSettings, timed: Timed) -> str:
        client = self.controllers[group.group]
        self.cancel_pending.discard(group.group)
        try:
            goal = await client.send_goal(trajectory_goal(group.joints, timed), self.settings.result_timeout)
        except ActionError as error:
            raise BridgeError(FaultKind.CONNECTION, f"{group.group}: {error}") from None
        if goal is None:
            raise BridgeError(FaultKind.CONTROLLER, f"{group.group}: {group.controller} refused the trajectory (the controller's log says why)")
        running = self.running[group.group] = _Running(client, goal)
        if group.group in self.cancel_pending:
            await self._abandon(running)
        deadline = self.clock.now() + timed.duration + self.settings.result_timeout
        result = asyncio.ensure_future(client.result(goal, timed.duration + 2 * self.settings.result_timeout))
        try:
            while not result.done():
                problem = self.trouble()
                if problem is not None or self.clock.now() > deadline:
                    why = problem or f"{group.controller} did not end the trajectory within {self.settings.result_timeout:g} s of its end (result_timeout)"
                    await self._abandon(running)
                    raise BridgeError(FaultKind.CONTROLLER if problem else FaultKind.TIMEOUT, f"{group.group}: {why}")
                await self.clock.sleep(WATCH_PERIOD)
            status, answer = result.result()
        except ActionError as error:
            raise BridgeError(FaultKind.CONNECTION, f"{group.group}: {error}") from None
        finally:
            self.running.pop(group.group, None)
            if not result.done():
                result.cancel()
        if status == GoalStatus.STATUS_SUCCEEDED and answer.error_code == 0 or status == GoalStatus.STATUS_CANCELED and running.canceled:
            return CANCELED if running.canceled else SUCCEEDED
        code = FJT_CODES.get(answer.error_code, str(answer.error_code))
        said = answer.error_string or "no reason given"
        raise BridgeError(FaultKind.CONTROLLER, f"{group.group}: {group.controller} ended the trajectory with {code}: {said}")

    async def _abandon(self, running: _Running) -> None:
        running.canceled = True
        try:
            await running.client.cancel(running.goal, self.settings.result_timeout)
        except ActionError:
            pass  # the fault being raised is the news; the controller's own watchdog holds the arm

    async def cancel(self, group: GroupSettings) -> None:
        running = self.running.get(group.group)
        if running is None:
            self.cancel_pending.add(group.group)
            return
        running.canceled = True
        try:
            await running.client.cancel(running.goal, self.settings.result_timeout)
        except ActionError as error:
            raise BridgeError(FaultKind.CONNECTION, f"{group.group}: {error}") from None

    async def grip(self, group: GroupSettings, position: float) -> None:
        client = self.grippers[group.group]
        command = GripperCommand.Goal(command=GripperCommandMsg(position=position, max_effort=group.gripper_effort))
        try:
            goal = await client.send_goal(command, self.settings.result_timeout)
            if goal is None:
                raise BridgeError(FaultKind.CONTROLLER, f"{group.group}: {group.gripper} refused the command to {position:g} m")
            status, answer = await client.result(goal, self.settings.result_timeout + 30.0)
        except ActionError as error:
            raise BridgeError(FaultKind.CONNECTION, f"{group.group}: {error}") from None
        if status != GoalStatus.STATUS_SUCCEEDED:
            raise BridgeError(FaultKind.CONTROLLER, f"{group.group}: {group.gripper} did not reach {position:g} m (ended at {answer.position:g} m)")


    async def set_tool(self, group: GroupSettings, on: bool) -> None:
        what = f"{group.group}: {group.tool_service}"
        try:
            answer = await self.tools[group.group].call(SetBool.Request(data=on), self.settings.result_timeout)
        except (ServiceUnavailable, TimeoutError, asyncio.TimeoutError) as error:
            raise BridgeError(FaultKind.CONNECTION, f"{what} did not answer the tool {'on' if on else 'off'} in {self.settings.result_timeout:g} s "
                              f"(result_timeout): {error or type(error).__name__}") from None
        if not answer.success:
            raise BridgeError(FaultKind.CONTROLLER, f"{what} refused the tool {'on' if on else 'off'}: {answer.message or 'no reason given'}")


class ModelLink(ControllerLink):
    """The URDF model as the robot, on ``clock``: the dry run's link (never a controller)."""

    def __init__(self, clock: Clock, settings: Ros2ControlSettings, urdf: str, start: Mapping[str, float]) -> None:
        self.clock, self.settings, self.urdf = clock, settings, urdf
        self.positions = dict(start)
        self.cancelled: set[str] = set()

    async def description(self) -> str:
        return self.urdf

    def trouble(self) -> str | None:
        return self.feed.fault  # the model publishes only when it moves: its states are never stale

    async def start(self, feed: JointFeed) -> None:
        self.feed = feed
        self._publish()

    def _publish(self, names: tuple[str, ...] | None = None) -> None:
        """The joints of ``names`` (default: all) as a joint state: each group's own, so no group's
        stale value looks like a fresh sample of it."""
        names = tuple(self.positions) if names is None else names
        self.feed.on_message(JointState(name=names, position=tuple(self.positions[n] for n in names)))

    async def follow(self, group: GroupSettings, timed: Timed) -> str:
        self.cancelled.discard(group.group)
        begin = self.clock.now()
        for t, point in zip(timed.times, timed.points):
            await self.clock.sleep_until(begin + float(t))
            if group.group in self.cancelled:
                self.cancelled.discard(group.group)
                return CANCELED
            self.positions.update(zip(group.joints, (float(v) for v in point)))
            self._publish(group.joints)
        return SUCCEEDED

    async def cancel(self, group: GroupSettings) -> None:
        self.cancelled.add(group.group)

    async def set_tool(self, group: GroupSettings, on: bool) -> None:
        await self.clock.sleep(TOOL_MODEL_TIME)

    async def grip(self, group: GroupSettings, position: float) -> None:
        if not math.isfinite(position):
            raise BridgeError(FaultKind.CONTROLLER, f"{group.group}: gripper position {position}")
        await self.clock.sleep(GRIP_MODEL_TIME)
