"""Robot descriptions the application model is checked against: groups, joints, limits, poses.

An application names its robot; the robot decides which groups may appear in an operation,
how many joints a joint move needs, and which joint values are plausible.  The Nextage Open
data follow the public nextage_description URDF (docs/architecture.md); the simulator's URDF is
tested against this table so the two cannot drift apart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

GroupKind = Literal["arm", "torso_head"]


@dataclass(frozen=True)
class JointSpec:
    name: str
    lower: float  # rad
    upper: float  # rad
    max_velocity: float  # rad/s

    def contains(self, value: float, tolerance: float = 1e-9) -> bool:
        return self.lower - tolerance <= value <= self.upper + tolerance


@dataclass(frozen=True)
class GroupSpec:
    name: str
    kind: GroupKind
    joints: tuple[JointSpec, ...]
    camera: str = ""  # the camera a vision request of this group uses by default

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


@dataclass(frozen=True)
class RobotModel:
    name: str
    description: str
    groups: tuple[GroupSpec, ...]
    aliases: tuple[str, ...] = ()
    #: Named whole-robot joint poses (rad), e.g. Nextage "initial" and "off".
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    #: The back end ``run`` uses when none is chosen.
    default_backend: str = "nextage-sim"
    #: The robot's conventional joint order for whole-robot lists (default: group by group).
    joint_order: tuple[str, ...] = ()
    #: Every camera a vision request may name (default: each group's own camera).
    camera_names: tuple[str, ...] = ()
    #: Where the tool can go, in words an application writer can plan poses with.
    workspace: str = ""
    #: The robot's base frame: what a cell model calls ``world``, the root link of the robot's
    #: URDF and the frame of its TCP poses, so tf joins the cell's frames to the robot's links.
    world_frame: str = "world"

    def __post_init__(self) -> None:
        own = [j.name for g in self.groups for j in g.joints]
        if self.joint_order and sorted(self.joint_order) != sorted(own):
            raise ValueError(f"{self.name}: joint_order must list exactly the joints of the groups")

    def group(self, name: str) -> GroupSpec:
        for g in self.groups:
            if g.name == name:
                return g
        raise KeyError(name)

    @property
    def group_names(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.groups)

    @property
    def arm_groups(self) -> tuple[str, ...]:
        return tuple(g.name for g in self.groups if g.kind == "arm")

    @cached_property
    def cameras(self) -> tuple[str, ...]:
        return self.camera_names or tuple(dict.fromkeys(g.camera for g in self.groups if g.camera))

    @cached_property
    def joints(self) -> tuple[JointSpec, ...]:
        """Every joint, in :attr:`joint_names` order."""
        by_name = {j.name: j for g in self.groups for j in g.joints}
        return tuple(by_name[name] for name in self.joint_names)

    @cached_property
    def joint_names(self) -> tuple[str, ...]:
        """The robot's joint order (Nextage: torso, head, right arm, left arm, as its controller lists them)."""
        return self.joint_order or tuple(j.name for g in self.groups for j in g.joints)

    def joint(self, name: str) -> JointSpec:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def group_pose(self, pose_name: str, group: str) -> tuple[float, ...]:
        """The joint values of ``group`` in the named whole-robot pose."""
        pose = self.poses[pose_name]
        return tuple(pose[j] for j in self.group(group).joint_names)


def _deg(*values: float) -> tuple[float, ...]:
    return tuple(math.radians(v) for v in values)


def _joint(name: str, lower_deg: float, upper_deg: float, velocity: float) -> JointSpec:
    return JointSpec(name, math.radians(lower_deg), math.radians(upper_deg), velocity)


def _nextage_arm(prefix: str, j3: tuple[float, float]) -> tuple[JointSpec, ...]:
    limits = [(-88, 88), (-140, 60), (-158, 0), j3, (-100, 100), (-163, 163)]
    return tuple(_joint(f"{prefix}_JOINT{i}", lo, hi, 1.0) for i, (lo, hi) in enumerate(limits))


def _pose(names: tuple[str, ...], values_deg: tuple[float, ...]) -> dict[str, float]:
    return dict(zip(names, _deg(*values_deg)))


_NEXTAGE_TORSO_HEAD = (
    _joint("CHEST_JOINT0", -163, 163, 0.5),
    _joint("HEAD_JOINT0", -70, 70, 0.5),
    _joint("HEAD_JOINT1", -20, 70, 0.5),
)
_NEXTAGE_RARM = _nextage_arm("RARM", (-165, 105))
_NEXTAGE_LARM = _nextage_arm("LARM", (-105, 165))
_NEXTAGE_ORDER = tuple(j.name for j in (*_NEXTAGE_TORSO_HEAD, *_NEXTAGE_RARM, *_NEXTAGE_LARM))

NEXTAGE_OPEN = RobotModel(
    name="nextage_open",
    description="Kawada Nextage Open: 15 DOF, two 6-DOF arms on a rotating torso, 2-DOF head",
    aliases=("nextage",),
    groups=(
        GroupSpec("left_arm", "arm", _NEXTAGE_LARM, camera="left_hand_camera"),
        GroupSpec("right_arm", "arm", _NEXTAGE_RARM, camera="right_hand_camera"),
        GroupSpec("torso_head", "torso_head", _NEXTAGE_TORSO_HEAD, camera="head_camera"),
    ),
    poses={
        "initial": _pose(_NEXTAGE_ORDER, (0, 0, 0, -0.6, 0, -100, 15.2, 9.4, 3.2, 0.6, 0, -100, -15.2, 9.4, -3.2)),
        "off": _pose(_NEXTAGE_ORDER, (0, 0, 0, 25, -140, -150, 45, 0, 0, -25, -140, -150, -45, 0, 0)),
    },
    default_backend="nextage-sim",
    world_frame="WAIST",
    joint_order=_NEXTAGE_ORDER,
    camera_names=("head_camera", "head_camera_left", "head_camera_right", "left_hand_camera", "right_hand_camera"),
    workspace=(
        "World frame: WAIST (x forward, y left, z up). Each arm's TCP is the wrist flange with z pointing out of the "
        "hand. At the initial pose the TCPs are at (0.326, +/-0.182, 0.068) m with the hands pointing down. With the "
        "tool pointing down (rpy 180 0 90 deg), both arms reach about x 0.25..0.43 m, y -0.12..0.12 m, z 0.0..0.10 m, "
        "and each arm to about |y| = 0.28 m on its own side; rpy 180 0 0 would need the wrist roll beyond its limit."
    ),
)

_VIPER_JOINTS = (
    _joint("joint_1", -170, 170, math.radians(328)),
    _joint("joint_2", -190, 45, math.radians(300)),
    _joint("joint_3", -29, 256, math.radians(375)),
    _joint("joint_4", -190, 190, math.radians(375)),
    _joint("joint_5", -120, 120, math.radians(375)),
    _joint("joint_6", -360, 360, math.radians(600)),
)

ADEPT_VIPER_S850 = RobotModel(
    name="adept_viper_s850",
    description="Adept Viper s850: 6-axis arm on an Adept V+ controller (AdeptServer over TCP)",
    aliases=("viper", "vplus"),
    groups=(GroupSpec("arm", "arm", _VIPER_JOINTS, camera="tool_camera"),),
    # AdeptServer movehome and the seed's init_move: #PPOINT(0,-90,180,0,90,0), flange pointing down
    poses={"home": dict(zip((j.name for j in _VIPER_JOINTS), _deg(0, -90, 180, 0, 90, 0)))},
    default_backend="vplus",
    workspace="World frame: the robot base. Reach 0.85 m; at home the tool flange is at (0.48, 0, 0.71) m pointing down.",
)

_KUKA_JOINTS = (
    _joint("A1", -170, 170, math.radians(156)),
    _joint("A2", -190, 45, math.radians(156)),
    _joint("A3", -120, 156, math.radians(156)),
    _joint("A4", -185, 185, math.radians(343)),
    _joint("A5", -120, 120, math.radians(362)),
    _joint("A6", -350, 350, math.radians(659)),
)

KUKA_KR = RobotModel(
    name="kuka_kr",
    description="KUKA KR (6-axis, KR C4 controller) driven through RSI over UDP",
    aliases=("kuka", "kuka_rsi"),
    groups=(GroupSpec("arm", "arm", _KUKA_JOINTS, camera="tool_camera"),),
    poses={"home": dict(zip((j.name for j in _KUKA_JOINTS), _deg(0, -90, 90, 0, 0, 0)))},
    default_backend="kuka-rsi",
    world_frame="base",
    workspace="World frame: the robot base (x forward, z up). Reach about 0.9 m around the base axis, above the mounting plane.",
)

ROBOTS: tuple[RobotModel, ...] = (NEXTAGE_OPEN, ADEPT_VIPER_S850, KUKA_KR)


def find_robot(name: str) -> RobotModel:
    """The robot named ``name`` or one of its aliases; KeyError lists what exists."""
    for robot in ROBOTS:
        if name == robot.name or name in robot.aliases:
            return robot
    known = ", ".join(sorted(n for r in ROBOTS for n in (r.name, *r.aliases)))
    raise KeyError(f"unknown robot {name!r} (known: {known})")
