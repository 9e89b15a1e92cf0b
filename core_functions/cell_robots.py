"""A cell of several robots: each one's model, base pose in the cell's world frame and back end.

A cell file may list ``<robot>`` elements; an application with ``robot="cell"`` then runs on all of
them at once.  Its groups are the robots' groups as the cell names them: their own (a KUKA's ``arm``,
a Nextage's ``left_arm``...), or renamed for the cell (:class:`CellNames`: a ``prefix`` on every group
and joint, as a URDF's ``prefix`` argument does, and an explicit name per group), so that two robots
whose models share a group name (a Viper and a KUKA: each ``arm``) stand side by side.  The engine and
the machines, which already talk per group, need nothing new: each machine drives its group with its
robot's model under the cell's names (:func:`named_model`), each robot gets a bridge of its own back
end that speaks the cell's names outward and its own inward, and the dry run places every robot's base
in the one world frame the cell's frames are written in.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

from core_functions.geometry import Pose
from core_functions.robots import GroupSpec, RobotModel, find_robot

#: The application's ``robot`` value that means "the robots its cell lists".
CELL_ROBOT = "cell"
#: The back ends a cell's robot may name (robot_bridges.registry.BACKENDS, checked equal there).
BACKEND_NAMES = ("nextage-sim", "vplus", "kuka-rsi", "ros2-control")
#: The registry's name of the back end that runs every robot of a cell, each on its own.
CELL_BACKEND = "cell"


@dataclass(frozen=True)
class CellNames:
    """How one robot's groups and joints are named in its cell: ``prefix`` before every group and joint
    name (``viper_``: ``viper_arm``, ``viper_joint_1``), and ``groups``, the robot's own group name -> the
    cell's, for a group named outright (taking precedence over the prefix).  Empty: the robot's own names."""

    prefix: str = ""
    groups: tuple[tuple[str, str], ...] = ()

    @property
    def identity(self) -> bool:
        return not self.prefix and all(own == named for own, named in self.groups)

    def group(self, own: str) -> str:
        """The cell's name of the robot's group ``own``."""
        return dict(self.groups).get(own, self.prefix + own)

    def joint(self, own: str) -> str:
        """The cell's name of the robot's joint ``own`` (what /joint_states and FollowJointTrajectory carry)."""
        return self.prefix + own

    def camera(self, own: str) -> str:
        """The cell's name of the robot's camera ``own``: prefixed as a joint is (a camera belongs to the robot, as
        its joints do, and a group named outright keeps its camera's name unique only with the prefix), so two
        robots' ``tool_camera`` are ``kuka_tool_camera`` and ``viper_tool_camera`` in the cell, its vision
        calls and its image topics."""
        return self.prefix + own if own else own

    def own(self, named: str) -> str:
        """The robot's own name of the cell's joint or camera name ``named`` (:meth:`joint`, :meth:`camera` undone:
        the prefix taken off); a name without the prefix as it is, for the robot to refuse as the unknown name it is."""
        return named[len(self.prefix):] if self.prefix and named.startswith(self.prefix) else named

    def text(self) -> str:
        """One parameter's text (``prefix=viper_;arm=loader``), read back by :meth:`parse`: how ``launch``
        tells a robot's bridge and machines the cell's names."""
        return ";".join([f"prefix={self.prefix}"] * bool(self.prefix) + [f"{own}={named}" for own, named in self.groups])

    @classmethod
    def parse(cls, text: str) -> CellNames:
        """:meth:`text` back; ValueError for an entry that is not ``key=value``."""
        prefix = ""
        groups: list[tuple[str, str]] = []
        for item in (part.strip() for part in text.split(";")):
            if not item:
                continue
            key, equals, value = item.partition("=")
            if not equals or not key.strip() or not value.strip():
                raise ValueError(f"cell names: {item!r} is not prefix=TEXT or GROUP=NAME")
            if key.strip() == "prefix":
                prefix = value.strip()
            else:
                groups.append((key.strip(), value.strip()))
        return cls(prefix, tuple(groups))


def named_model(model: RobotModel, names: CellNames) -> RobotModel:
    """``model`` under the cell's names: its groups, joints, cameras, poses and joint order renamed, its name (what
    finds its URDF, collision model and back end) kept.  ``model`` itself when nothing is renamed."""
    if names.identity:
        return model
    groups = tuple(
        replace(group, name=names.group(group.name), joints=tuple(replace(j, name=names.joint(j.name)) for j in group.joints),
                camera=names.camera(group.camera))
        for group in model.groups
    )
    poses = {pose: {names.joint(j): v for j, v in values.items()} for pose, values in model.poses.items()}
    return replace(model, groups=groups, poses=poses, joint_order=tuple(names.joint(j) for j in model.joint_order),
                   camera_names=tuple(names.camera(c) for c in model.camera_names))


def cell_group_names(model_name: str, names: CellNames) -> tuple[str, ...]:
    """The cell's names of the groups of the robot model ``model_name`` (none for a model that does not exist)."""
    try:
        return named_model(find_robot(model_name), names).group_names
    except KeyError:
        return ()


@dataclass(frozen=True)
class CellRobot:
    """One robot of a cell: its name there, its model, where its base stands, what drives it and how the
    cell names its groups and joints (``model`` is the robot's own: its back end is built from it)."""

    name: str
    model: RobotModel
    base: Pose
    backend: str
    options: tuple[tuple[str, str], ...] = ()
    names: CellNames = CellNames()

    @cached_property
    def cell_model(self) -> RobotModel:
        """The robot as the application sees it: its groups, joints and cameras under the cell's names."""
        return named_model(self.model, self.names)

    @property
    def groups(self) -> tuple[str, ...]:
        return self.cell_model.group_names

    def own_group(self, group: str) -> str:
        """The robot's own name of its cell group ``group`` (KeyError if it has none of that name)."""
        for own in self.model.group_names:
            if self.names.group(own) == group:
                return own
        raise KeyError(group)


@dataclass(frozen=True)
class CellRobotModel(RobotModel):
    """Every robot of a cell as one model for the application: the union of their groups."""

    members: tuple[CellRobot, ...] = field(default=())

    def member_of(self, group: str) -> CellRobot:
        """The robot whose group ``group`` is (KeyError if none)."""
        for member in self.members:
            if group in member.groups:
                return member
        raise KeyError(group)


def cell_robot_model(cell_name: str, members: tuple[CellRobot, ...]) -> CellRobotModel:
    """The application's robot for a cell of ``members`` (their groups must be apart: the cell reader checks)."""
    groups: list[GroupSpec] = [g for m in members for g in m.cell_model.groups]
    poses: dict[str, dict[str, float]] = {}
    for member in members:
        for pose_name, values in member.cell_model.poses.items():  # a pose of one robot names only its joints
            poses.setdefault(pose_name, {}).update(values)
    described = ", ".join(f"{m.name}: {m.model.name} on {m.backend}" for m in members)
    return CellRobotModel(
        name=f"cell {cell_name}" if cell_name else CELL_ROBOT,
        description=f"the robots of cell {cell_name} ({described})",
        groups=tuple(groups),
        poses=poses,
        default_backend=CELL_BACKEND,
        joint_order=tuple(j for m in members for j in m.cell_model.joint_names),
        camera_names=tuple(dict.fromkeys(c for m in members for c in m.cell_model.cameras)),
        workspace="World frame: the cell's; each robot's base is placed in it by its <robot> xyz and rpy.",
        members=members,
    )
