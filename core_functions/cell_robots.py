"""A cell of several robots: each one's model, base pose in the cell's world frame and back end.

A cell file may list ``<robot>`` elements; an application with ``robot="cell"`` then runs on all of
them at once.  Its groups are the robots' own groups (a KUKA's ``arm``, a Nextage's ``left_arm``...),
so the engine and the machines, which already talk per group, need nothing new: each machine
drives its group with its own robot's model, each robot gets a bridge of its own back end, and the
dry run places every robot's base in the one world frame the cell's frames are written in.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from core_functions.geometry import Pose
from core_functions.robots import GroupSpec, RobotModel

#: The application's ``robot`` value that means "the robots its cell lists".
CELL_ROBOT = "cell"
#: The back ends a cell's robot may name (robot_bridges.registry.BACKENDS, checked equal there).
BACKEND_NAMES = ("nextage-sim", "vplus", "kuka-rsi", "ros2-control")
#: The registry's name of the back end that runs every robot of a cell, each on its own.
CELL_BACKEND = "cell"


@dataclass(frozen=True)
class CellRobot:
    """One robot of a cell: its name there, its model, where its base stands and what drives it."""

    name: str
    model: RobotModel
    base: Pose
    backend: str
    options: tuple[tuple[str, str], ...] = ()

    @property
    def groups(self) -> tuple[str, ...]:
        return self.model.group_names


@dataclass(frozen=True)
class CellRobotModel(RobotModel):
    """Every robot of a cell as one model for the application: the union of their groups."""

    members: tuple[CellRobot, ...] = field(default=())

    def member_of(self, group: str) -> CellRobot:
        """The robot whose group ``group`` is (KeyError if none)."""
        for member in self.members:
            if group in member.model.group_names:
                return member
        raise KeyError(group)


def cell_robot_model(cell_name: str, members: tuple[CellRobot, ...]) -> CellRobotModel:
    """The application's robot for a cell of ``members`` (their groups must be apart: the cell reader checks)."""
    groups: list[GroupSpec] = [g for m in members for g in m.model.groups]
    poses: dict[str, dict[str, float]] = {}
    for member in members:
        for pose_name, values in member.model.poses.items():  # a pose of one robot names only its joints
            poses.setdefault(pose_name, {}).update(values)
    described = ", ".join(f"{m.name}: {m.model.name} on {m.backend}" for m in members)
    return CellRobotModel(
        name=f"cell {cell_name}" if cell_name else CELL_ROBOT,
        description=f"the robots of cell {cell_name} ({described})",
        groups=tuple(groups),
        poses=poses,
        default_backend=CELL_BACKEND,
        joint_order=tuple(j for m in members for j in m.model.joint_names),
        camera_names=tuple(dict.fromkeys(c for m in members for c in m.model.cameras)),
        workspace="World frame: the cell's; each robot's base is placed in it by its <robot> xyz and rpy.",
        members=members,
    )
