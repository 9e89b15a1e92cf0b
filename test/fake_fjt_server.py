"""A stand-in for a ros2_control driver, written from joint_trajectory_controller's documented behaviour only.

What the ros2-control back end is tested against: ``/robot_description`` (latched), ``/joint_states``
every ``state_period`` (as joint_state_broadcaster), per controller a FollowJointTrajectory action
and ``<controller>/controller_state`` (the joints it drives), and optionally a GripperCommand action.
A goal is checked as joint_trajectory_controller checks it (every joint of the controller named
once, points with positions, times increasing, within the URDF's ranges and speeds) and refused by
ending ABORTED with control_msgs' error code and a message; an accepted one is played in the
server's clock, positions interpolated linearly between points (a positions-only goal in the
controller), cancel holds the arm where it is, a new goal preempts the running one.  Grippers
(``gripper``, ``grippers``) serve GripperCommand, tools (``tools``) std_srvs/SetBool, each call kept in
``grips``/``tool_calls``.  Test knobs: ``tool_refusal`` (the tools say no, with that message),
``refuse`` (the next goal ends with that code and text), ``states_on`` (stop publishing), ``corrupt``
(the next joint state carries that value for a joint).
"""
from __future__ import annotations

import asyncio
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from node_transport import mirrors
from node_transport.action import ActionServer, GoalHandle
from node_transport.clock import Clock
from node_transport.msgs import Header, JointState, String
from node_transport.port import Node
from node_transport.qos import JOINT_STATES, ROBOT_DESCRIPTION

FJT = mirrors.action("control_msgs/action/FollowJointTrajectory")
Gripper = mirrors.action("control_msgs/action/GripperCommand")
SetBool = mirrors.service("std_srvs/srv/SetBool")
ControllerState = mirrors.mirror("control_msgs/msg/JointTrajectoryControllerState")
R = FJT.Result


def urdf_limits(urdf: str) -> dict[str, tuple[float, float, float]]:
    """joint -> (lower, upper, velocity) of every revolute/prismatic joint (the server's own reading of the URDF)."""
    limits = {}
    for joint in ET.fromstring(urdf).iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") in ("revolute", "prismatic") and limit is not None:
            limits[joint.get("name", "")] = (float(limit.get("lower", "0")), float(limit.get("upper", "0")), float(limit.get("velocity", "0")))
    return limits


def seconds(duration: Any) -> float:
    return duration.sec + duration.nanosec * 1e-9


@dataclass
class Played:
    """One goal as the server saw it: its joints, point times and positions, and how it ended."""

    joints: tuple[str, ...]
    times: tuple[float, ...]
    points: tuple[tuple[float, ...], ...]
    outcome: str = "running"
    started: float = 0.0


@dataclass(frozen=True)
class _Playing:
    begin: float
    joints: tuple[str, ...]
    times: tuple[float, ...]  # from 0.0, where the arm was
    points: tuple[tuple[float, ...], ...]


@dataclass
class FakeDriver:
    node: Node
    clock: Clock
    urdf: str
    controllers: Mapping[str, Sequence[str]]  # action name -> joints
    start: Mapping[str, float]
    gripper: str | None = None
    state_period: float = 0.02
    grippers: Sequence[str] = ()  # more GripperCommand actions (a dual-arm robot's hands)
    tools: Sequence[str] = ()  # std_srvs/SetBool services switching a tool
    period: float = 0.01
    positions: dict[str, float] = field(init=False)
    limits: dict[str, tuple[float, float, float]] = field(init=False)
    goals: list[Played] = field(default_factory=list)
    refuse: tuple[int, str] | None = None
    states_on: bool = True
    corrupt: tuple[str, float] | None = None
    grips: list[float] = field(default_factory=list)
    tool_calls: list[tuple[str, bool]] = field(default_factory=list)
    tool_refusal: str | None = None  # the tools answer success=False with this message
    cancels: int = 0

    def __post_init__(self) -> None:
        self.limits = urdf_limits(self.urdf)
        self.positions = {name: float(self.start.get(name, 0.0)) for name in self.limits}
        self.node.create_publisher(String, "/robot_description", ROBOT_DESCRIPTION).publish(String(self.urdf))
        self.states = self.node.create_publisher(JointState, "/joint_states", JOINT_STATES)
        self.servers: list[ActionServer] = []
        self.active: dict[str, GoalHandle] = {}
        self.playing: dict[str, _Playing] = {}  # controller -> the trajectory it plays
        self.state_pubs = {}
        for name, joints in self.controllers.items():
            self.servers.append(ActionServer(
                self.node, FJT, name, execute=self._executor(name, tuple(joints)), accept=lambda goal: None, cancel=self._on_cancel,
            ))
            self.state_pubs[name] = (self.node.create_publisher(ControllerState, name.rsplit("/", 1)[0] + "/controller_state", JOINT_STATES), tuple(joints))
        for gripper in (*([self.gripper] if self.gripper is not None else []), *self.grippers):
            self.servers.append(ActionServer(self.node, Gripper, gripper, execute=self._grip, accept=lambda goal: None, cancel=lambda handle: None))
        self.services = [self.node.create_service(SetBool, name, self._tool(name)) for name in self.tools]
        self.task = asyncio.get_running_loop().create_task(self._publish_states())

    async def _publish_states(self) -> None:
        while True:
            if self.states_on:
                for name in list(self.playing):
                    self._sample(name)
                names = tuple(self.positions)
                values = [self.positions[n] for n in names]
                if self.corrupt is not None:
                    values[names.index(self.corrupt[0])] = self.corrupt[1]
                    self.corrupt = None
                self.states.publish(JointState(Header(stamp=self.node.now_stamp()), names, tuple(values)))
                for publisher, joints in self.state_pubs.values():
                    publisher.publish(ControllerState(joint_names=joints))
            await self.clock.sleep(self.state_period)

    def _on_cancel(self, handle: GoalHandle) -> None:
        self.cancels += 1

    def _check(self, joints: tuple[str, ...], goal: Any) -> tuple[int, str] | None:
        trajectory = goal.trajectory
        names = tuple(trajectory.joint_names)
        unknown = [n for n in names if n not in joints]
        if unknown or len(set(names)) != len(names) or set(names) != set(joints):
            return R.INVALID_JOINTS, f"joints {list(names)} do not match the controller's {list(joints)}"
        if not trajectory.points:
            return R.INVALID_GOAL, "empty trajectory"
        last = -1.0
        for k, point in enumerate(trajectory.points):
            t = seconds(point.time_from_start)
            if len(point.positions) != len(names) or t <= last and k:
                return R.INVALID_GOAL, f"point {k}: positions or time_from_start invalid"
            last = t
            for name, value in zip(names, point.positions):
                lower, upper, _ = self.limits[name]
                if not lower - 1e-9 <= value <= upper + 1e-9:
                    return R.INVALID_GOAL, f"point {k}: {name} {value:.4f} outside [{lower:.4f}, {upper:.4f}]"
            for name, speed in zip(names, point.velocities):
                if abs(speed) > self.limits[name][2] + 1e-9:
                    return R.INVALID_GOAL, f"point {k}: {name} velocity {speed:.4f} above {self.limits[name][2]:.4f}"
        return None

    def _executor(self, name: str, joints: tuple[str, ...]) -> Any:
        async def execute(handle: GoalHandle) -> Any:
            trajectory = handle.goal.trajectory
            names = tuple(trajectory.joint_names)
            played = Played(names, tuple(seconds(p.time_from_start) for p in trajectory.points), tuple(tuple(p.positions) for p in trajectory.points),
                            started=self.clock.now())
            self.goals.append(played)
            refusal = self.refuse or self._check(joints, handle.goal)
            self.refuse = None
            if refusal is not None:
                handle.aborted = True
                played.outcome = "refused"
                return R(error_code=refusal[0], error_string=refusal[1])
            previous = self.active.get(name)
            if previous is not None:
                previous.cancel_requested = True  # preempted, as the controller does with a new goal
                self._sample(name)
            self.active[name] = handle
            start = [self.positions[n] for n in names]
            playing = self.playing[name] = _Playing(self.clock.now(), names, (0.0, *played.times), (tuple(start), *played.points))
            try:
                while True:
                    if handle.cancel_requested:
                        played.outcome = "canceled"
                        return R(error_code=R.SUCCESSFUL)
                    self._sample(name)
                    if self.clock.now() - playing.begin >= playing.times[-1]:
                        played.outcome = "succeeded"
                        return R(error_code=R.SUCCESSFUL)
                    await self.clock.sleep(self.period)
            finally:
                if self.active.get(name) is handle:
                    del self.active[name]
                if self.playing.get(name) is playing:
                    self._sample(name)  # held where it is now
                    del self.playing[name]

        return execute

    def _sample(self, name: str) -> None:
        """The positions of controller ``name``'s trajectory now: as the controller's update loop, the states
        published at a time are where the trajectory is at that time, however late the server's loop runs."""
        playing = self.playing.get(name)
        if playing is None:
            return
        times, points = playing.times, playing.points
        t = min(max(self.clock.now() - playing.begin, 0.0), times[-1])
        k = min(max(i for i in range(len(times)) if times[i] <= t), len(times) - 2)
        u = min(1.0, (t - times[k]) / (times[k + 1] - times[k]))
        self.positions.update((n, a + u * (b - a)) for n, a, b in zip(playing.joints, points[k], points[k + 1]))

    async def _grip(self, handle: GoalHandle) -> Any:
        target = handle.goal.command.position
        self.grips.append(target)
        await self.clock.sleep(0.3)
        return Gripper.Result(position=target, reached_goal=True)

    def _tool(self, name: str) -> Any:
        async def switch(request: Any) -> Any:
            self.tool_calls.append((name, bool(request.data)))
            if self.tool_refusal is not None:
                return SetBool.Response(success=False, message=self.tool_refusal)
            return SetBool.Response(success=True, message="on" if request.data else "off")

        return switch

    async def close(self) -> None:
        for service in self.services:
            service.destroy()
        self.task.cancel()
        await asyncio.gather(self.task, return_exceptions=True)
        for server in self.servers:
            await server.close()


def moved_too_fast(played: Played, limits: Mapping[str, tuple[float, float, float]]) -> list[str]:
    """Every segment of a goal faster than a joint's URDF speed (what the back end must never send)."""
    bad = []
    times = played.times
    for k in range(1, len(times)):
        dt = times[k] - times[k - 1]
        for j, name in enumerate(played.joints):
            speed = abs(played.points[k][j] - played.points[k - 1][j]) / dt
            if speed > limits[name][2] * (1 + 1e-6):
                bad.append(f"{name} {speed:.3f} > {limits[name][2]:.3f} rad/s at point {k}")
    return bad
