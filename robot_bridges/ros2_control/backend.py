"""The ``ros2-control`` back end: any robot whose ROS 2 driver offers FollowJointTrajectory.

ros2_control's joint_trajectory_controller (and every driver built like it: UR, KUKA's kuka_drivers,
ABB, Motoman, Franka, the simulators) takes a timed joint trajectory and plays it.  This back end
turns the engine's primitives into such trajectories on the robot's own URDF (``/robot_description``,
or a file): joint moves, Cartesian moves through inverse kinematics on that model (point to point,
or a straight line of closely spaced poses), relative moves, replays of recorded trajectories, all
timed within the URDF's speed limits at the set speed fraction (:mod:`.planning`).  Where the arm
is comes only from ``/joint_states``, checked sample by sample (:mod:`.feed`).

Pause cancels the running trajectory -- the controller holds the arm where it is -- and resume
plans what is left of the path again from where the arm really stopped, never sending the old
trajectory a second time; stop cancels and abandons.  FollowJointTrajectory has no way to scale a
running trajectory, so a change of the speed override does what a pause and resume do: it cancels the
goal, the arm comes to rest on its path, and the rest of the path goes again from where it stands,
timed at the new share of the speed (0 %: it waits on the path until the override is raised).  Grippers are driven through
control_msgs/action/GripperCommand where a group names one, a tool (``tool_on``/``tool_off``) through the
std_srvs/srv/SetBool service a group names; vision through the robot's cameras on ROS topics with
``camera_source=ros`` (:mod:`.cameras`; the dry run renders the cell instead).  Anything else, and these
without their option, is not available on such a robot and says so (in the dry run: at the call's line, before a run).
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Coroutine
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
    FullBodyMove,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    SetSpeed,
    TrajectoryResult,
    Vision,
    VisionResult,
    describe,
)
from core_functions.robots import RobotModel
from core_functions.urdf_tree import parent_joint
from node_transport.wire import CellSnapshot
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind, JointLimits, RobotBackend  # JointLimits: the port's signature
from robot_bridges.camera.sources import CameraSource
from robot_bridges.camera.vision import CameraVision
from robot_bridges.ros2_control.cameras import camera_pose
from robot_bridges.ros2_control.feed import JointFeed
from robot_bridges.ros2_control.link import CANCELED, SUCCEEDED, ControllerLink
from robot_bridges.ros2_control.model import Chain, UrdfError, UrdfModel
from robot_bridges.ros2_control.options import GroupSettings, Ros2ControlSettings
from robot_bridges.ros2_control.planning import Limits, Timed, line_path, line_poses, remainder, retime, time_path

#: s: how long the arm must keep still (within STILL rad) after a cancel before a resume plans from it.
SETTLE_TIME = 0.1
STILL = 1e-4
GRIPPER_ACTIONS = {"gripper_open": "gripper_open", "gripper_close": "gripper_closed"}
TOOL_ACTIONS = {"tool_on": True, "tool_off": False}


@dataclass
class _GroupRun:
    """One group's motion state: speed fraction, and the pause/stop of its running primitive."""

    speed: float = 1.0
    busy: bool = False
    following: bool = False  # a goal of it is with the controller (a change of the speed override cancels it)
    paused: bool = False
    stopping: bool = False
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    team: tuple[str, ...] = ()  # the groups a full-body move of this group's drives with it (itself included)


class Ros2ControlBackend(RobotBackend):
    """The robot behind ``link`` (a ROS graph's controllers, or the URDF model for the dry run)."""

    holds_within_motion = True

    def __init__(self, clock: Clock, robot: RobotModel, settings: Ros2ControlSettings, link: ControllerLink) -> None:
        self.clock, self.robot, self.settings, self.link = clock, robot, settings, link
        self.name = "ros2_control" if settings.transport != "model" else "ros2_control_model"
        self.model: UrdfModel | None = None
        self.chains: dict[str, Chain] = {}
        self.limits: dict[str, Limits] = {}
        self.runs = {g.group: _GroupRun() for g in settings.groups}
        self.holder: dict[str, str] = {}  # a group moved by another's full-body move -> that group
        self._cancels: set[asyncio.Task[None]] = set()  # the cancels a change of the speed override sent
        #: The robot's cameras with camera_source=ros (:meth:`use_cameras`), else None: vision is not available.
        self.cameras: CameraVision | None = None
        self._cell: CellSnapshot | None = None

    @property
    def groups(self) -> tuple[str, ...]:
        return tuple(g.group for g in self.settings.groups)

    async def start(self) -> None:
        urdf = await self.link.description()
        try:
            self.model, self.chains = model, _ = group_chains(urdf, self.settings)
        except UrdfError as error:
            raise BridgeError(FaultKind.CONNECTION, str(error)) from None
        self.world_frame = model.root
        for group in self.settings.groups:
            velocity = np.array([model.ranges[j].velocity for j in group.joints])
            chain = self.chains[group.group]
            self.limits[group.group] = Limits(group.joints, chain.lower, chain.upper, velocity, velocity / self.settings.acceleration_time)
        speeds = {j: model.ranges[j].velocity for g in self.settings.groups for j in g.joints}
        await self.link.start(JointFeed(self.clock, speeds))

    async def close(self) -> None:
        await self.link.close()

    def use_cameras(self, source: CameraSource) -> None:
        """Take the robot's cameras' images from ``source`` (ROS topics, or the renderer in the dry run)."""
        assert self.settings.cameras is not None
        self.cameras = CameraVision(source, None, self.settings.cameras.specs)
        if self._cell is not None:
            self.cameras.set_cell(self._cell)

    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell
        if self.cameras is not None:
            self.cameras.set_cell(cell)

    # ------------------------------------------------------------------ where the robot is
    def _positions(self) -> dict[str, float]:
        problem = self.link.trouble()
        if problem is not None:
            raise BridgeError(FaultKind.CONTROLLER, problem)
        latest = self.link.feed.latest
        assert latest is not None
        return latest.positions

    def _q(self) -> np.ndarray:
        """The whole model's joints: measured where the feed has them, the URDF's zero elsewhere (no group moves them)."""
        assert self.model is not None
        where = self._positions()
        return np.array([where.get(name, 0.0) for name in self.model.joint_names])

    def _group_q(self, group: GroupSettings) -> np.ndarray:
        where = self._positions()
        return np.array([where[j] for j in group.joints])

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        latest = self.link.feed.latest if hasattr(self.link, "feed") else None
        if latest is None:
            return (), ()
        names: list[str] = []
        values: list[float] = []
        for group in self.settings.groups:
            names += group.app_joints
            values += [latest.positions[j] for j in group.joints]
        return tuple(names), tuple(values)

    def tcp_pose(self, group: str) -> Pose | None:
        if self.model is None or group not in self.chains:
            return None
        return self.chains[group].tip_pose(self._q())

    async def measure(self, group: str) -> MotionResult:
        settings = self.settings.group(group)
        q = self._group_q(settings)
        return MotionResult(settings.app_joints, tuple(float(v) for v in q), self.tcp_pose(group))

    def joint_limits(self, group: str) -> JointLimits | None:
        """None: the robot's driver serves its own FollowJointTrajectory, under the names this back end is
        configured with; the bridge serving a second one (a proxy of the same action) would only clash with it."""
        return None

    # ------------------------------------------------------------------------- commands
    def _run_of(self, group: str) -> tuple[_GroupRun, tuple[str, ...]]:
        """The run that moves ``group`` (its own, or the full-body move holding it) and every group it moves."""
        leader = self.holder.get(group, group)
        run = self.runs[leader]
        return run, run.team or (leader,)

    async def pause(self, group: str) -> None:
        run, team = self._run_of(group)
        if run.busy and not run.paused:
            run.paused = True
            run.wake.clear()
            for member in team:
                await self.link.cancel(self.settings.group(member))

    async def resume(self, group: str) -> None:
        run, _ = self._run_of(group)
        run.paused = False
        run.wake.set()

    async def stop(self, group: str) -> None:
        run, team = self._run_of(group)
        if run.busy:
            run.stopping = True
            run.wake.set()
            for member in team:
                await self.link.cancel(self.settings.group(member))

    def set_speed_override(self, rate: float) -> None:
        """Cancel every running goal; its motion goes on from where the arm stops, timed at the new share (_move)."""
        before = self.speed_override
        super().set_speed_override(rate)
        for leader, run in self.runs.items():
            if rate > 0.0:
                run.wake.set()
            if run.following and rate != before:
                task = asyncio.get_running_loop().create_task(self._cancel_team(run.team or (leader,)))
                self._cancels.add(task)
                task.add_done_callback(self._cancels.discard)

    async def _following(self, run: _GroupRun, goal: Coroutine[Any, Any, str]) -> str:
        run.following = True
        try:
            return await goal
        finally:
            run.following = False

    async def _cancel_team(self, team: tuple[str, ...]) -> None:
        for member in team:
            await self.link.cancel(self.settings.group(member))

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        if group not in self.runs:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{self.name} drives {', '.join(self.groups)}, not {group}")
        team = self._team(group, primitive) if isinstance(primitive, FullBodyMove) else (group,)
        busy = [g for g in team if self.runs[g].busy or g in self.holder]
        if busy:
            raise BridgeError(FaultKind.BUSY, f"{busy[0]} is running a primitive")
        run = self.runs[group]
        run.busy, run.paused, run.stopping, run.team = True, False, False, team
        self.holder.update({g: group for g in team if g != group})
        try:
            if isinstance(primitive, FullBodyMove):
                return await self._full_body(tuple(self.settings.group(g) for g in team), run, primitive)
            return await self._execute(self.settings.group(group), run, primitive)
        finally:
            run.busy, run.team = False, ()
            for g in team:
                self.holder.pop(g, None)

    def _team(self, group: str, primitive: FullBodyMove) -> tuple[str, ...]:
        """The groups whose joints a full-body move names (the leader first); UNSUPPORTED naming a joint no group has."""
        owner = {name: g.group for g in self.settings.groups for name in g.app_joints}
        strangers = [n for n in primitive.joint_names if n not in owner]
        if strangers:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group}: full_body_move names {strangers[0]}, a joint of no configured group")
        named = {owner[n] for n in primitive.joint_names}
        return (group, *(g for g in self.groups if g in named and g != group))

    async def _full_body(self, team: tuple[GroupSettings, ...], run: _GroupRun, primitive: FullBodyMove) -> MotionResult:
        """One move of several groups' joints, on one time line: each group's controller gets its columns of it."""
        target = dict(zip(primitive.joint_names, primitive.positions))
        here = self._team_q(team)
        app = [n for g in team for n in g.app_joints]
        goal = np.array([target.get(n, q) for n, q in zip(app, here)])
        await self._move(team, run, np.vstack((here, goal)), describe(primitive))
        names, positions = self.joint_state()
        return MotionResult(names, positions, self.tcp_pose(team[0].group))

    async def _execute(self, group: GroupSettings, run: _GroupRun, primitive: Primitive) -> PrimitiveResult:
        what = describe(primitive)
        if isinstance(primitive, SetSpeed):
            run.speed = primitive.fraction
            return await self.measure(group.group)
        if isinstance(primitive, MoveJoints):
            target = self._joint_target(group, primitive)
            return await self._move((group,), run, np.vstack((self._group_q(group), target)), what)
        if isinstance(primitive, (MoveCartesian, MoveRelative)):
            start = self.tcp_pose(group.group)
            assert start is not None
            target = primitive.target if isinstance(primitive, MoveCartesian) else primitive.goal(start)
            return await self._move((group,), run, self._cartesian_path(group, start, target, primitive.interpolation), what)
        if isinstance(primitive, ExecuteTrajectory):
            return await self._replay(group, run, primitive, what)
        if isinstance(primitive, RecordTrajectory):
            return await self._record(group, run, primitive)
        if isinstance(primitive, Dwell):
            await self._hold(run, primitive.seconds)
            return await self.measure(group.group)
        if isinstance(primitive, EndEffector):
            return await self._end_effector(group, primitive)
        if isinstance(primitive, Vision):
            return await self._look(group, primitive)
        raise BridgeError(FaultKind.UNSUPPORTED, f"{what} is not available on this robot: the ros2-control back end drives joints "
                          "through FollowJointTrajectory, grippers through GripperCommand, tools through SetBool and cameras on ROS topics")

    async def _look(self, group: GroupSettings, primitive: Vision) -> VisionResult:
        """Images of the cameras where the URDF's kinematics put them now (a hand camera moves with its arm,
        a camera whose link is a cell frame stands there), then located as on every back end."""
        if self.cameras is None or self.settings.cameras is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: {describe(primitive)} is not available on this robot: no cameras "
                              "(give --backend-option camera_source=ros: the cameras' <camera>/image_raw and camera_info topics)")
        name = primitive.camera or self.robot.group(group.group).camera
        try:
            cameras = self.settings.cameras.taking_part(name)
        except KeyError:
            raise BridgeError(FaultKind.VISION, f"{group.group}: no camera {name!r} (cameras: {', '.join(self.settings.cameras.specs)})") from None
        assert self.model is not None
        # A motion ends within goal_tolerance of its target: the arm may still be closing the last millimetres. An image
        # taken then, placed by the joints read a moment before, puts the hole off by as much (1 mm seen on the Jazzy mock).
        await self._settle((group,))
        q = self._q()
        placed = []
        for cam in cameras:
            pose = camera_pose(cam, self.model, q, self._cell)
            if pose is None:
                raise BridgeError(FaultKind.VISION, f"{cam.name}: its link {cam.link!r} is neither a link of the URDF nor a frame of the cell")
            placed.append((cam, pose))
        return await self.cameras.observe(primitive, placed)

    def _joint_target(self, group: GroupSettings, primitive: MoveJoints) -> np.ndarray:
        values = np.array(primitive.positions, dtype=float)
        if primitive.joint_names and tuple(primitive.joint_names) != group.app_joints:
            order = {name: k for k, name in enumerate(primitive.joint_names)}
            missing = [n for n in group.app_joints if n not in order]
            if missing:
                raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: a joint move without {', '.join(missing)}")
            values = np.array([primitive.positions[order[n]] for n in group.app_joints])
        if len(values) != len(group.joints):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: {len(values)} joint values for {len(group.joints)} joints")
        return self._group_q(group) + values if primitive.relative else values

    def _cartesian_path(self, group: GroupSettings, start: Pose, target: Pose, interpolation: str) -> np.ndarray:
        chain, q = self.chains[group.group], self._q()
        here = q[chain.indices]
        if interpolation != "linear":
            return np.vstack((here, chain.solve(target, q)))

        def solve(pose: Pose, seed: np.ndarray) -> np.ndarray:
            return chain.solve(pose, chain.with_joints(q, seed))

        return line_path(group.group, here, line_poses(start, target), solve, group.joints)

    def _team_q(self, team: tuple[GroupSettings, ...]) -> np.ndarray:
        return np.concatenate([self._group_q(g) for g in team])

    def _team_limits(self, team: tuple[GroupSettings, ...]) -> Limits:
        if len(team) == 1:
            return self.limits[team[0].group]
        parts = [self.limits[g.group] for g in team]
        return Limits(tuple(n for p in parts for n in p.names), *(np.concatenate([getattr(p, a) for p in parts]) for a in ("lower", "upper", "velocity", "acceleration")))

    async def _move(self, team: tuple[GroupSettings, ...], run: _GroupRun, path: np.ndarray, what: str) -> MotionResult:
        """Play ``path`` (its first point: where the arm is; the team's joints side by side); a pause cancels,
        a resume re-plans from where the arms stopped."""
        limits = self._team_limits(team)
        limits.check_positions(team[0].group, path[1:], what)
        plan, progress = path, 0
        while True:
            await self._wait_while_paused(team[0], run)
            timed = time_path(plan, limits, run.speed * self.speed_override)
            outcome = await self._following(run, self._follow(team, timed))
            if outcome != CANCELED:
                break
            if run.stopping:
                raise BridgeError(FaultKind.STOPPED, f"{team[0].group}: stopped during {what}")
            await self._settle(team)
            plan, progress = remainder(path, self._team_q(team), progress)
        await self._arrive(team, path[-1], what)
        return await self.measure(team[0].group)

    async def _follow(self, team: tuple[GroupSettings, ...], timed: Timed) -> str:
        """``timed`` on every group of ``team`` at once, each its own columns; the first failure cancels the others."""
        if len(team) == 1:
            return await self.link.follow(team[0], timed)
        tasks: list[asyncio.Future[str]] = []
        start = 0
        for group in team:
            end = start + len(group.joints)
            part = Timed(timed.times, timed.points[:, start:end], timed.velocities[:, start:end])
            tasks.append(asyncio.ensure_future(self.link.follow(group, part)))
            start = end
        _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
        for group, task in zip(team, tasks):
            if task in pending:
                await self.link.cancel(group)
        outcomes = await asyncio.gather(*tasks, return_exceptions=True)
        failure = next((o for o in outcomes if isinstance(o, BaseException)), None)
        if failure is not None:
            raise failure
        return CANCELED if CANCELED in outcomes else SUCCEEDED

    async def _wait_while_paused(self, group: GroupSettings, run: _GroupRun) -> None:
        while (run.paused or self.speed_override == 0.0) and not run.stopping:  # paused, or held on the path at 0 %
            run.wake.clear()
            await run.wake.wait()
        if run.stopping:
            raise BridgeError(FaultKind.STOPPED, f"{group.group}: stopped")

    async def _settle(self, team: tuple[GroupSettings, ...]) -> None:
        """Wait (within result_timeout) until the arms stand still: after a cancel (the resume plans from there), before
        a capture (the cameras are placed from there)."""
        deadline = self.clock.now() + self.settings.result_timeout
        before = self._team_q(team)
        still_since = self.clock.now()
        while self.clock.now() - still_since < SETTLE_TIME:
            if self.clock.now() > deadline:
                raise BridgeError(FaultKind.CONTROLLER, f"{team[0].group}: the arm did not come to rest within {self.settings.result_timeout:g} s (result_timeout)")
            await self.clock.sleep(SETTLE_TIME / 4)
            now = self._team_q(team)
            if float(np.max(np.abs(now - before))) > STILL:
                still_since = self.clock.now()
            before = now

    async def _arrive(self, team: tuple[GroupSettings, ...], target: np.ndarray, what: str) -> None:
        """The controller said done: the joint states must say so too (within goal_tolerance, in result_timeout)."""
        deadline = self.clock.now() + self.settings.result_timeout
        joints = [j for g in team for j in g.joints]
        while True:
            off = np.abs(self._team_q(team) - target)
            if float(np.max(off)) <= self.settings.goal_tolerance:
                return
            if self.clock.now() > deadline:
                j = int(np.argmax(off))
                raise BridgeError(FaultKind.CONTROLLER, f"{team[0].group}: {what} ended with {joints[j]} {off[j]:.4f} rad from its target "
                                  f"(goal_tolerance {self.settings.goal_tolerance:g} rad)")
            await self.clock.sleep(0.02)

    async def _replay(self, group: GroupSettings, run: _GroupRun, primitive: ExecuteTrajectory, what: str) -> MotionResult:
        order = {name: k for k, name in enumerate(primitive.joint_names)}
        missing = [n for n in group.app_joints if n not in order]
        if missing:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: trajectory {primitive.name!r} has no {', '.join(missing)}")
        points = np.array([[p[order[n]] for n in group.app_joints] for p in primitive.points], dtype=float)
        limits = self.limits[group.group]
        limits.check_positions(group.group, points, what)
        here = self._group_q(group)
        if float(np.max(np.abs(points[0] - here))) > self.settings.goal_tolerance:
            await self._move((group,), run, np.vstack((here, points[0])), f"{what}: to its first point")
        await self._wait_while_paused(group, run)
        timed = retime(primitive.times, points, limits, run.speed * self.speed_override)
        if math.isclose(timed.duration, 0.0):
            return await self.measure(group.group)
        # played as a path: a pause re-plans the rest from where the arm stopped, at the same speed limits
        first = await self._following(run, self._follow((group,), timed)) if not run.paused else CANCELED
        if first == CANCELED:
            if run.stopping:
                raise BridgeError(FaultKind.STOPPED, f"{group.group}: stopped during {what}")
            await self._settle((group,))
            rest, _ = remainder(points, self._group_q(group))
            return await self._move((group,), run, rest, what)
        await self._arrive((group,), points[-1], what)
        return await self.measure(group.group)

    async def _record(self, group: GroupSettings, run: _GroupRun, primitive: RecordTrajectory) -> TrajectoryResult:
        chain, limits = self.chains[group.group], self.limits[group.group]
        if primitive.mode == "teach":
            return await self._teach(group, run, primitive)
        q = self._q()
        current, pose = q[chain.indices], chain.tip_pose(q)
        times, points = [0.0], [current]
        for waypoint in primitive.waypoints:
            if primitive.interpolation == "linear":
                leg = line_path(group.group, current, line_poses(pose, waypoint), lambda p, s: chain.solve(p, chain.with_joints(q, s)), group.joints)
            else:
                leg = np.vstack((current, chain.solve(waypoint, chain.with_joints(q, current))))
            limits.check_positions(group.group, leg, describe(primitive))
            timed = time_path(leg, limits, 1.0, period=primitive.sample_period)  # each leg from rest to rest: no corner at a waypoint
            times += [times[-1] + float(t) for t in timed.times[1:]]
            points += list(timed.points[1:])
            current, pose = leg[-1], waypoint
        return TrajectoryResult(group.app_joints, tuple(tuple(float(v) for v in p) for p in points), tuple(times))

    async def _teach(self, group: GroupSettings, run: _GroupRun, primitive: RecordTrajectory) -> TrajectoryResult:
        """The arm guided by hand (or by its teach pendant): its joint states sampled every sample_period."""
        begin = self.clock.now()
        times: list[float] = []
        points: list[tuple[float, ...]] = []
        count = max(1, math.ceil(primitive.duration / primitive.sample_period - 1e-9))
        for k in range(count + 1):
            at = min(k * primitive.sample_period, primitive.duration)
            await self.clock.sleep_until(begin + at)
            if run.stopping:
                raise BridgeError(FaultKind.STOPPED, f"{group.group}: stopped while teaching {primitive.name!r}")
            times.append(at)
            points.append(tuple(float(v) for v in self._group_q(group)))
        return TrajectoryResult(group.app_joints, tuple(points), tuple(times))

    async def _hold(self, run: _GroupRun, seconds: float) -> None:
        """A dwell: robot time passes only while not paused; a stop ends it."""
        left = seconds
        while left > 0:
            if run.stopping:
                raise BridgeError(FaultKind.STOPPED, "stopped during a dwell")
            if run.paused:
                await run.wake.wait()
                continue
            step = min(left, 0.05)
            await self.clock.sleep(step)
            left -= step

    async def _end_effector(self, group: GroupSettings, primitive: EndEffector) -> EndEffectorResult:
        if primitive.action in TOOL_ACTIONS:
            if group.tool_service is None:
                raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: {primitive.action} is not available on this robot: no tool service is configured "
                                  f"(give its std_srvs/srv/SetBool service with --backend-option {group.group}.tool_service=NAME)")
            await self.link.set_tool(group, TOOL_ACTIONS[primitive.action])
            return EndEffectorResult()
        option = GRIPPER_ACTIONS.get(primitive.action)
        if option is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: end effector action {primitive.action} is not available on this robot "
                              "(the ros2-control back end drives grippers and tools: gripper_open, gripper_close, tool_on, tool_off)")
        if group.gripper is None:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{group.group}: {primitive.action} is not available on this robot: no gripper is configured "
                              f"(give its control_msgs/action/GripperCommand action with --backend-option {group.group}.gripper=NAME)")
        await self.link.grip(group, getattr(group, option))
        return EndEffectorResult()


def group_chains(urdf: str, settings: Ros2ControlSettings) -> tuple[UrdfModel, dict[str, Chain]]:
    """The URDF's model and each group's chain on it; UrdfError naming the URDF and the option otherwise."""
    where = f"urdf={settings.urdf}" if settings.urdf else "/robot_description"
    try:
        model = UrdfModel(urdf)
        chains = {}
        for group in settings.groups:
            chains[group.group] = Chain(model, group.group, group.joints, group.tip or default_tip(model, group.joints[-1]), group.tool)
    except UrdfError as error:
        raise UrdfError(f"ros2-control: {where}: {error}") from None
    return model, chains


def default_tip(model: UrdfModel, last_joint: str) -> str:
    """``tool0`` (the ROS-Industrial convention) when the URDF has it, else the link the group's last joint moves."""
    if model.has_frame("tool0"):
        return "tool0"
    jid = model.model.getJointId(last_joint)
    for frame in model.model.frames:
        if parent_joint(frame) == jid and frame.name != last_joint:
            return str(frame.name)
    raise UrdfError(f"no link after joint {last_joint!r} to use as the tip: name one (option GROUP.tip)")
