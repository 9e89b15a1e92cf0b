"""An independent FollowJointTrajectory client, as MoveIt 2's simple controller manager is one: it knows
only the wire -- the action's name, control_msgs' types built from their interface files, rcl_action's
services and topics (rclpy_like.RclpyLikeActionClient) -- and ``/joint_states``; nothing of the server.

And the three bridges it is pointed at, each started as its executable starts it (the back end from its
simulator, a :class:`BridgeNode` on a transport).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN
from node_transport import mirrors
from node_transport.action import CancelGoalRequest, GoalInfo
from node_transport.clock import Clock
from node_transport.msgs import JointState
from node_transport.port import Node, poll_until
from node_transport.qos import JOINT_STATES
from rclpy_like import Handle, RclpyLikeActionClient
from robot_bridges.backend import BackendOptions, RobotBackend
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.kuka_rsi.external import LoopSettings
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec
from robot_bridges.registry import create_backend

FJT = mirrors.action("control_msgs/action/FollowJointTrajectory")
JointTrajectory = mirrors.mirror("trajectory_msgs/msg/JointTrajectory")
Point = mirrors.mirror("trajectory_msgs/msg/JointTrajectoryPoint")
Duration = mirrors.mirror("builtin_interfaces/msg/Duration")
JointTolerance = mirrors.mirror("control_msgs/msg/JointTolerance")
ControllerState = mirrors.mirror("control_msgs/msg/JointTrajectoryControllerState")
Header = mirrors.mirror("std_msgs/msg/Header")
Time = mirrors.mirror("builtin_interfaces/msg/Time")


@dataclass(frozen=True)
class Kind:
    """A bridge as a client sees it: the controller's name and the group's joints."""

    name: str
    controller: str
    joints: tuple[str, ...]


NEXTAGE = Kind("nextage", "left_arm_controller", NEXTAGE_OPEN.group("left_arm").joint_names)
VPLUS = Kind("vplus", "arm_controller", ADEPT_VIPER_S850.group("arm").joint_names)
RSI = Kind("rsi", "arm_controller", ("A1", "A2", "A3", "A4", "A5", "A6"))
KINDS = {k.name: k for k in (NEXTAGE, VPLUS, RSI)}
RSI_START = tuple(math.radians(v) for v in (0.0, -80.0, 85.0, 0.0, 30.0, 0.0))


async def make_backend(kind: Kind, clock: Clock, real_time: bool = False) -> RobotBackend:
    """The bridge's back end on its simulator: the Nextage kinematic simulator, an AdeptServer simulator on
    loopback, a simulated KR C4 answering the RSI loop on loopback -- in lockstep with the loop for a test on
    simulated time, its 4 ms cycles on the wall clock with ``real_time``."""
    if kind is NEXTAGE:
        return await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
    if kind is VPLUS:
        return await create_backend("vplus", clock, BackendOptions(robot=ADEPT_VIPER_S850))
    return KukaRsiBackend(
        listen=("127.0.0.1", 0),
        simulator=SimulatorSpec(runner="thread", accelerated=not real_time, context=RsiContext(start_deg=tuple(math.degrees(v) for v in RSI_START))),
        runner="thread", settings=LoopSettings(silence_timeout=1.0),
    )


async def start_bridge(kind: Kind, node: Node, clock: Clock, real_time: bool = False) -> BridgeNode:
    bridge = BridgeNode(node, await make_backend(kind, clock, real_time))
    await bridge.start()
    return bridge


def duration(seconds: float) -> Any:
    whole = math.floor(seconds)
    return Duration(int(whole), int(round((seconds - whole) * 1e9)))


def goal(names: Sequence[str], points: Sequence[tuple[float, Sequence[float]]], **fields: Any) -> Any:
    """A FollowJointTrajectory goal: ``(time from start, positions)`` per point."""
    trajectory = JointTrajectory(
        header=fields.pop("header", Header()), joint_names=tuple(names),
        points=tuple(Point(positions=tuple(float(v) for v in p), time_from_start=duration(t)) for t, p in points),
    )
    return FJT.Goal(trajectory=trajectory, **fields)


@dataclass
class Arm:
    """The client's view: the action, and every joint state the bridge published (with the client's clock)."""

    node: Node
    kind: Kind
    clock: Clock
    client: RclpyLikeActionClient = field(init=False)
    states: list[tuple[float, dict[str, float]]] = field(default_factory=list)
    numbers: int = 0

    def __post_init__(self) -> None:
        self.client = RclpyLikeActionClient(self.node, f"/{self.kind.controller}/follow_joint_trajectory", FJT)
        self.node.create_subscription(JointState, "/joint_states", self._on_state, JOINT_STATES)

    def _on_state(self, msg: JointState) -> None:
        self.states.append((self.clock.now(), dict(zip(msg.name, msg.position))))

    async def ready(self, bound: float) -> None:
        assert await self.client.send.wait_for_service(bound), "the action's send_goal service never appeared"
        assert await poll_until(self.clock, lambda: bool(self.states), bound, 0.01), "no joint_states"

    def joints(self) -> np.ndarray:
        """The group's joints in the latest joint state."""
        where = self.states[-1][1]
        return np.array([where[n] for n in self.kind.joints])

    async def at_rest(self, bound: float) -> np.ndarray:
        """The group's joints once joint_states has stood still for 0.2 s (a braking KR C4 on a loaded machine takes
        a while): polled, bounded by ``bound``."""
        deadline = self.clock.now() + bound
        while True:
            before = self.joints()
            await self.clock.sleep(0.2)
            now = self.joints()
            if float(np.max(np.abs(now - before))) <= 1e-7:
                return now
            assert self.clock.now() < deadline, "the arm never came to rest"

    def trail(self, since: float = -math.inf) -> np.ndarray:
        return np.array([[where[n] for n in self.kind.joints] for t, where in self.states if t >= since])

    async def send(self, the_goal: Any, bound: float) -> Handle:
        self.numbers += 1
        handle = await self.client.send_goal(the_goal, self.numbers, timeout=bound)
        assert handle is not None, "the goal was not accepted (refusals end the goal with an error code)"
        return handle

    async def run(self, the_goal: Any, bound: float) -> Any:
        return await self.client.result(await self.send(the_goal, bound), timeout=bound)

    async def cancel(self, handle: Handle, bound: float) -> Any:
        return await self.client.cancel_client.call(CancelGoalRequest(GoalInfo(handle.goal_id)), timeout=bound)


def three_points(start: np.ndarray, step: Sequence[float], spacing: float = 1.0) -> list[tuple[float, np.ndarray]]:
    """Three points ``step`` apart from ``start`` (one per ``spacing`` s)."""
    delta = np.array(step, dtype=float)
    return [(spacing * (k + 1), start + delta * (k + 1)) for k in range(3)]


def where_on_path(q: np.ndarray, path: Sequence[np.ndarray]) -> tuple[float, float]:
    """How far ``q`` is from the polyline through ``path`` (rad, the largest joint's), and how far along it the
    nearest place is (segment index + fraction)."""
    best, along = math.inf, 0.0
    for k, (a, b) in enumerate(zip(path, path[1:])):
        span = b - a
        length = float(span @ span)
        s = 0.0 if length == 0.0 else min(1.0, max(0.0, float((q - a) @ span) / length))
        distance = float(np.max(np.abs(q - (a + s * span))))
        if distance < best - 1e-12:
            best, along = distance, k + s
    return best, along


def distance_to_path(q: np.ndarray, path: Sequence[np.ndarray]) -> float:
    return where_on_path(q, path)[0]


def follows(trail: np.ndarray, path: Sequence[np.ndarray], tolerance: float = 0.01) -> str | None:
    """Whether joint_states ``trail`` followed ``path`` from its start to its end: every sample on it, never going
    back along it, the last at its end; None, or what went wrong."""
    placed = [where_on_path(q, path) for q in trail]
    off = [d for d, _ in placed if d > tolerance]
    if off:
        return f"{len(off)} samples off the path, up to {max(off):.4f} rad"
    along = [a for _, a in placed]
    if any(b < a - 1e-3 for a, b in zip(along, along[1:])):
        return "went back along the path"
    if along[-1] < len(path) - 1 - 1e-3:
        return f"ended {along[-1]:.3f} of {len(path) - 1} segments along"
    return None
