"""A robot whose base stands somewhere in the cell: poses go in and out in the cell's world frame.

Each back end works in its own robot's base frame (a KUKA's ``base``, a Nextage's ``WAIST``); in a
cell of several robots the application's frames are written in the cell's one world frame.  This
wrapper turns every pose a primitive carries into the robot's base frame before the back end sees
it, and every pose the back end reports (TCP, located features, the cell it is given) back, so a
back end never needs to know where it stands.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from core_functions.geometry import Pose, rotate
from core_functions.primitives import (
    MasterSlaveMove,
    MotionResult,
    MoveCartesian,
    MoveRelative,
    Primitive,
    PrimitiveResult,
    RecordTrajectory,
    Vision,
    VisionResult,
)
from node_transport.wire import CellSnapshot
from robot_bridges.backend import JointLimits, RobotBackend


class PlacedBackend(RobotBackend):
    """``inner`` with its base at ``base`` in the cell's world frame."""

    def __init__(self, inner: RobotBackend, base: Pose, robot_name: str) -> None:
        self.inner = inner
        self.base = base
        self.to_base = base.inverse()
        self.name = f"{robot_name}: {inner.name}"
        self.world_frame = "world"
        self.holds_within_motion = inner.holds_within_motion
        self.clock = inner.clock

    def __getattr__(self, name: str) -> Any:  # what a bridge or a dry run asks of a simulator beyond the interface
        if name == "inner":  # not set yet (or never): no recursion through this method
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def groups(self) -> tuple[str, ...]:
        return self.inner.groups

    async def start(self) -> None:
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
        return self.outward(await self.inner.execute(group, self.inward(primitive)))

    async def pause(self, group: str) -> None:
        await self.inner.pause(group)

    async def resume(self, group: str) -> None:
        await self.inner.resume(group)

    async def stop(self, group: str) -> None:
        await self.inner.stop(group)

    async def measure(self, group: str) -> MotionResult:
        result = await self.inner.measure(group)
        return replace(result, tcp=self._out(result.tcp))

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        return self.inner.joint_state()

    def tcp_pose(self, group: str) -> Pose | None:
        return self._out(self.inner.tcp_pose(group))

    def set_speed_override(self, rate: float) -> None:
        super().set_speed_override(rate)
        self.inner.set_speed_override(rate)  # the robot plays its motions at it; where its base stands changes nothing

    def set_cell(self, cell: CellSnapshot) -> None:
        """The cell as the robot sees it: every frame and true pose in its base frame."""
        frames = tuple(replace(f, pose=self._in(f.pose)) for f in cell.frames)
        truth = {name: self._in(pose) for name, pose in cell.truth.items()}
        self.inner.set_cell(replace(cell, frames=frames, truth=truth))

    def joint_limits(self, group: str) -> JointLimits | None:
        return self.inner.joint_limits(group)

    def robot_description(self) -> str | None:
        return None  # its URDF's root is the robot's base, not the cell's world: not published as the cell's
