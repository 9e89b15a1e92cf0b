"""A robot of a cell of several: poses in the cell's world frame, groups and joints under the cell's names.

Each back end works in its own robot's base frame (a KUKA's ``base``, a Nextage's ``WAIST``); in a
cell of several robots the application's frames are written in the cell's one world frame.  This
wrapper turns every pose a primitive carries into the robot's base frame before the back end sees
it, and every pose the back end reports (TCP, located features, the cell it is given) back, so a
back end never needs to know where it stands.

The same goes for names: a cell may name a robot's groups and joints for itself
(:class:`core_functions.cell_robots.CellNames`: a Viper's ``arm`` as ``inspector``, its ``joint_1`` as
``viper_joint_1``), so that two robots whose models share a group or joint name stand side by side.
The back end keeps its own names; everything that leaves this wrapper (its groups, hence the bridge's
per-group topics and FollowJointTrajectory actions, /joint_states, results, limits, its cameras' names and
image topics, and the messages of its faults) carries the cell's, and every group or joint name coming in is turned back into the robot's own.  A
fault's message is renamed word by word (:meth:`PlacedBackend.cell_text`): an operator reading "inspector:
viper_joint_2 ... outside its limits" finds the group and joint the application names, never the model's ``arm``.
"""
from __future__ import annotations

import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import replace
from typing import Any

from core_functions.cell_robots import CellNames
from core_functions.geometry import Pose, rotate
from core_functions.primitives import (
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    TrajectoryResult,
    Vision,
    VisionResult,
)
from node_transport.wire import CellSnapshot
from robot_bridges.backend import BridgeError, JointLimits, RobotBackend
from robot_bridges.placed_urdf import placed_urdf


class PlacedBackend(RobotBackend):
    """``inner`` with its base at ``base`` in the cell's world frame, its groups and joints named by ``names``."""

    def __init__(self, inner: RobotBackend, base: Pose, robot_name: str, names: CellNames = CellNames(),
                 cameras: tuple[str, ...] = ()) -> None:
        self.inner = inner
        #: the robot model's cameras (a stereo pair's name among them), which its faults may name
        self.model_cameras = cameras
        self.base = base
        self.to_base = base.inverse()
        self.names = names
        self._own_group = {names.group(g): g for g in inner.groups}
        self._renaming: tuple[re.Pattern[str], dict[str, str]] | None = None
        self.name = f"{robot_name}: {inner.name}"
        self.robot_name = robot_name
        #: where its bridge publishes its URDF: one topic per robot of the cell (robot_state_publisher's in a namespace
        #: named after the robot), so /robot_description stays a single robot's -- a ros2_control driver's, for one
        self.description_topic = "/" + (re.sub(r"\W+", "_", robot_name).strip("_") or "robot") + "/robot_description"
        self._description: str | None = None
        self.world_frame = "world"
        self.holds_within_motion = inner.holds_within_motion
        self.clock = inner.clock

    def __getattr__(self, name: str) -> Any:  # what a bridge or a dry run asks of a simulator beyond the interface
        if name == "inner":  # not set yet (or never): no recursion through this method
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def groups(self) -> tuple[str, ...]:
        return tuple(self._own_group)

    def own_group(self, group: str) -> str:
        """The robot's name of its cell group ``group`` (a name it does not have: as it is, for the robot to refuse)."""
        return self._own_group.get(group, group)

    def own_joints(self, joints: tuple[str, ...]) -> tuple[str, ...]:
        """The robot's names of the cell's joint names ``joints``: the prefix taken off; a name without the
        prefix is passed as it is, for the robot to refuse as the unknown joint it is."""
        return tuple(self.names.own(j) for j in joints)

    def own_camera(self, camera: str) -> str:
        """The robot's name of the cell's camera ``camera`` (the prefix taken off, as of a joint)."""
        return self.names.own(camera)

    def cell_camera(self, own: str) -> str:
        """The cell's name of the robot's camera ``own``: what the bridge names its image topics after."""
        return self.names.camera(own)

    def own_cameras(self) -> tuple[str, ...]:
        """The cameras the robot has by its own names: its model's and those of its back end's camera set."""
        specs = getattr(getattr(self.inner, "cameras", None), "specs", None)
        return tuple(dict.fromkeys(self.model_cameras + (tuple(specs) if isinstance(specs, dict) else ())))

    def cell_joints(self, joints: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(self.names.joint(j) for j in joints)

    def cell_text(self, text: str) -> str:
        """``text`` (a back end's message) with the robot's own group and joint names, as whole words, turned into
        the cell's: ``arm: joint_2 ... outside its limits`` -> ``inspector: viper_joint_2 ...``.  A name that is part
        of a longer word (``arm_controller``, an already prefixed ``viper_joint_2``) stays as it is, so nothing is
        renamed twice."""
        if self.names.identity or not text:
            return text
        renaming = self._renaming or self._renaming_table()
        if renaming is None:
            return text
        pattern, table = renaming
        return pattern.sub(lambda match: table[match.group(0)], text)

    def _renaming_table(self) -> tuple[re.Pattern[str], dict[str, str]] | None:
        """The robot's own names (groups, joints, cameras) -> the cell's, as one pattern of whole words; kept once the joints are known
        (from the limits a back end has from its model and the joints it reports: a ros2-control robot's once its
        driver's /joint_states came; until then its group names alone)."""
        limits = (self.inner.joint_limits(g) for g in self.inner.groups)
        joints = [j for lim in limits if lim is not None for j in lim.joint_names] + list(self.inner.joint_state()[0])
        table = {j: self.names.joint(j) for j in joints} | {c: self.names.camera(c) for c in self.own_cameras()}
        table.update({g: self.names.group(g) for g in self.inner.groups})  # a group named like a joint: the group's name
        table = {own: named for own, named in table.items() if own and own != named}
        if not table:
            return None
        words = "|".join(re.escape(own) for own in sorted(table, key=len, reverse=True))
        renaming = (re.compile(rf"(?<!\w)(?:{words})(?!\w)"), table)
        if joints:
            self._renaming = renaming
        return renaming

    @asynccontextmanager
    async def cell_faults(self) -> AsyncIterator[None]:
        """A :class:`BridgeError` out of the back end raised again with its message under the cell's names."""
        try:
            yield
        except BridgeError as error:
            renamed = self.cell_text(error.detail)
            if renamed == error.detail:
                raise
            raise BridgeError(error.kind, renamed) from error

    def renamed_in(self, primitive: Primitive) -> Primitive:
        """``primitive`` with the robot's own group and joint names."""
        if self.names.identity:
            return primitive
        if isinstance(primitive, (MoveJoints, ExecuteTrajectory, FullBodyMove)) and primitive.joint_names:
            return replace(primitive, joint_names=self.own_joints(primitive.joint_names))
        if isinstance(primitive, MasterSlaveMove):
            return replace(primitive, master=self.own_group(primitive.master), slave=self.own_group(primitive.slave))
        if isinstance(primitive, Vision) and primitive.camera:
            return replace(primitive, camera=self.own_camera(primitive.camera))
        return primitive

    def renamed_out(self, result: PrimitiveResult) -> PrimitiveResult:
        """``result`` with the cell's joint names."""
        if self.names.identity:
            return result
        if isinstance(result, (MotionResult, TrajectoryResult)) and result.joint_names:
            return replace(result, joint_names=self.cell_joints(result.joint_names))
        if isinstance(result, VisionResult) and result.report is not None and result.report.camera:
            return replace(result, report=replace(result.report, camera=self.names.camera(result.report.camera)))
        return result

    async def start(self) -> None:
        async with self.cell_faults():
            await self.inner.start()
        self.clock = self.inner.clock

    async def close(self) -> None:
        await self.inner.close()

    def _in(self, pose: Pose) -> Pose:
        return self.to_base.compose(pose)

    def _out(self, pose: Pose | None) -> Pose | None:
        return None if pose is None else self.base.compose(pose)

    def tcp_out(self, pose: Pose) -> Pose:
        """A pose the robot reports in its base frame, in the cell's world frame."""
        return self.base.compose(pose)

    def inward(self, primitive: Primitive) -> Primitive:
        """``primitive`` with its poses in the robot's base frame."""
        if isinstance(primitive, MoveCartesian):
            return replace(primitive, target=self._in(primitive.target))
        if isinstance(primitive, MoveRelative) and primitive.reference == "world":
            turn = self.to_base.quaternion
            delta = primitive.delta
            moved = Pose(*rotate(turn, delta.position), *delta.quaternion)
            spun = Pose(0.0, 0.0, 0.0, *turn).compose(Pose(0.0, 0.0, 0.0, *delta.quaternion)).compose(Pose(0.0, 0.0, 0.0, *self.base.quaternion))
            return replace(primitive, delta=Pose(*moved.position, *spun.quaternion))
        if isinstance(primitive, RecordTrajectory) and primitive.waypoints:
            return replace(primitive, waypoints=tuple(self._in(p) for p in primitive.waypoints))
        if isinstance(primitive, MasterSlaveMove) and primitive.master_path:
            return replace(primitive, master_path=tuple(self._in(p) for p in primitive.master_path))
        if isinstance(primitive, Vision) and primitive.nominal is not None:
            return replace(primitive, nominal=self._in(primitive.nominal))
        return primitive

    def outward(self, result: PrimitiveResult) -> PrimitiveResult:
        """``result`` with its poses in the cell's world frame."""
        if isinstance(result, MotionResult) and result.tcp is not None:
            return replace(result, tcp=self._out(result.tcp))
        if isinstance(result, VisionResult) and result.pose is not None:
            report = result.report
            if report is not None:
                report = replace(report, nominal=self._out(report.nominal), measured=self._out(report.measured),
                                 correction=rotate(self.base.quaternion, report.correction))
            return replace(result, pose=self._out(result.pose), report=report)
        return result

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        async with self.cell_faults():
            result = await self.inner.execute(self.own_group(group), self.renamed_in(self.inward(primitive)))
        return self.renamed_out(self.outward(result))

    async def pause(self, group: str) -> None:
        async with self.cell_faults():
            await self.inner.pause(self.own_group(group))

    async def resume(self, group: str) -> None:
        async with self.cell_faults():
            await self.inner.resume(self.own_group(group))

    async def stop(self, group: str) -> None:
        async with self.cell_faults():
            await self.inner.stop(self.own_group(group))

    async def measure(self, group: str) -> MotionResult:
        async with self.cell_faults():
            result = await self.inner.measure(self.own_group(group))
        return replace(result, tcp=self._out(result.tcp), joint_names=self.cell_joints(result.joint_names))

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names, positions = self.inner.joint_state()
        return self.cell_joints(names), positions

    def tcp_pose(self, group: str) -> Pose | None:
        return self._out(self.inner.tcp_pose(self.own_group(group)))

    def set_speed_override(self, rate: float) -> None:
        super().set_speed_override(rate)
        self.inner.set_speed_override(rate)  # the robot plays its motions at it; where its base stands changes nothing

    def set_cell(self, cell: CellSnapshot) -> None:
        """The cell as the robot sees it: every frame and true pose in its base frame, its joint poses (those of
        its own joints) under its own names."""
        frames = tuple(replace(f, pose=self._in(f.pose)) for f in cell.frames)
        truth = {name: self._in(pose) for name, pose in cell.truth.items()}
        seen = replace(cell, frames=frames, truth=truth)
        if not self.names.identity:
            prefix = self.names.prefix
            poses = {name: dict(zip(self.own_joints(tuple(values)), values.values()))
                     for name, values in cell.joint_poses.items() if all(j.startswith(prefix) for j in values)}
            groups = {name: self._own_group[g] for name, g in cell.joint_pose_groups.items() if g in self._own_group and name in poses}
            seen = replace(seen, joint_poses=poses, joint_pose_groups=groups)
        self.inner.set_cell(seen)

    def joint_limits(self, group: str) -> JointLimits | None:
        limits = self.inner.joint_limits(self.own_group(group))
        return None if limits is None else replace(limits, joint_names=self.cell_joints(limits.joint_names))

    def robot_description(self) -> str | None:
        """The robot's URDF hung from the cell's world at its base, its links and joints under the cell's prefix
        (:func:`robot_bridges.placed_urdf.placed_urdf`): its movable joints are those :meth:`joint_state` names."""
        if self._description is None:
            urdf = self.inner.robot_description()
            if urdf is None:
                return None
            prefix = self.names.prefix
            self._description = placed_urdf(urdf, self.base, prefix, f"{prefix}{self.inner.world_frame}_mount", self.world_frame)
        return self._description
