"""The cell model: the paper's fixture and element information, as one tree of named frames.

Herrero et al. keep what changes between scenarios -- where the holes of a part are, which rivet
goes where -- out of the skills, in XML files extracted from CAD; skills take names and look the
poses up.  A :class:`Cell` is that lookup: frames composed down the tree into the world frame
(the robot base), the elements (references) and named joint poses.  An optional ``<actual>`` per
frame says where the thing really is, so the simulated vision has something to find.

A cell can be loaded before the robot is known; :func:`check_joint_poses` checks its joint poses
once an application names the robot.  Reading the XML is :mod:`execution_engine.app_model.cell_reader`.
"""
from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core_functions.cell_index import CellFrame, FrameLookup
from core_functions.cell_robots import CellRobot
from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from core_functions.suggest import NameIndex
from execution_engine.app_model.diagnostics import Diagnostic, Location
from execution_engine.app_model.frame_tree import WORLD, order_frames
from execution_engine.app_model.zones import ZONE_KIND, Zone, zone_frame
from node_transport.wire import CellSnapshot


@dataclass(frozen=True)
class Frame:
    """A named frame: its pose in its parent (SI units), its kind and free attributes."""

    name: str
    parent: str = WORLD
    local: Pose = Pose()
    kind: str = "frame"
    attributes: Mapping[str, str] = field(default_factory=dict)
    actual: Pose | None = None  # the true pose relative to the nominal one (simulated vision)
    location: Location | None = None


@dataclass(frozen=True)
class Element:
    """A reference (a rivet type, a part) with its free attributes, as written."""

    name: str
    kind: str = "element"
    attributes: Mapping[str, str] = field(default_factory=dict)
    location: Location | None = None


@dataclass(frozen=True)
class JointPose:
    """Named joint values (rad) for one group, or for the whole robot in RobotModel.joint_names order."""

    name: str
    values: tuple[float, ...]
    group: str | None = None
    location: Location | None = None
    joints_location: Location | None = None
    group_location: Location | None = None


@dataclass(frozen=True)
class Cell(FrameLookup):
    """A cell model; implements core_functions.catalog.CellView.  ``robot`` is set by :meth:`bind`."""

    name: str
    frames: Mapping[str, Frame] = field(default_factory=dict)
    elements: Mapping[str, Element] = field(default_factory=dict)
    joint_poses: Mapping[str, JointPose] = field(default_factory=dict)
    path: Path | None = None
    zones: Mapping[str, Zone] = field(default_factory=dict)  # interference zones (app_model/zones.py)
    robot: RobotModel | None = None
    robots: tuple[CellRobot, ...] = ()  # <robot> elements: the robots of a mixed cell (core_functions/cell_robots.py)
    # Caches, filled on demand: world poses cost a matrix product each, and a cell too large to
    # run is refused having composed only the frames that fit in a message (app_model.wire_fit).
    _world: dict[str, Pose] = field(default_factory=dict, init=False, repr=False, compare=False)
    _truth: dict[str, Pose | None] = field(default_factory=dict, init=False, repr=False, compare=False)
    _names: NameIndex = field(default_factory=lambda: NameIndex(()), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_tree(self.frames)
        object.__setattr__(self, "_names", NameIndex(self.frames))  # sorted on the first unknown name

    # ------------------------------------------------------------------ CellView (frames: FrameLookup)
    @property
    def frame_map(self) -> Mapping[str, Frame]:
        return self.frames

    def has_element(self, name: str) -> bool:
        return name in self.elements

    def element_kind(self, name: str) -> str:
        return self.elements[name].kind

    def joint_pose_group(self, name: str) -> str | None:
        """The group a joint pose was made for, or None for a whole-robot pose."""
        return self.joint_poses[name].group

    def has_joint_pose(self, name: str) -> bool:
        return name in self.joint_poses

    # ------------------------------------------------------------------ look-ups
    def frame(self, name: str) -> Frame:
        return self.frames[name]

    def element(self, name: str) -> Element:
        return self.elements[name]

    def joint_pose(self, name: str) -> JointPose:
        return self.joint_poses[name]

    def pose(self, name: str) -> Pose:
        """The nominal pose of frame ``name`` in the world frame (KeyError if unknown).

        Composed down the chain from the nearest frame already known, so every frame is composed
        once however the frames are asked for; iterative, for chains of any length."""
        if name == WORLD:
            return Pose()
        known = self._world.get(name)
        if known is not None:
            return known
        chain = self._unknown_chain(name, self._world)
        base = self._world[self.frames[chain[-1]].parent] if self.frames[chain[-1]].parent != WORLD else Pose()
        for frame_name in reversed(chain):
            base = base.compose(self.frames[frame_name].local)
            self._world[frame_name] = base
        return base

    def true_pose(self, name: str) -> Pose:
        """Where frame ``name`` really is: its nominal pose corrected by every ``<actual>`` up the chain."""
        return self._true(name) or self.pose(name)

    def _true(self, name: str) -> Pose | None:
        """The true pose where an ``<actual>`` at or above ``name`` moves it; None where none does."""
        if name == WORLD:
            return None
        if name in self._truth:
            return self._truth[name]
        chain = self._unknown_chain(name, self._truth)
        top_parent = self.frames[chain[-1]].parent
        parent_true = self._truth[top_parent] if top_parent != WORLD else None
        for frame_name in reversed(chain):
            frame = self.frames[frame_name]
            true: Pose | None = None
            if frame.actual is not None or parent_true is not None:
                base = (parent_true or self.pose(frame.parent)).compose(frame.local)
                true = base.compose(frame.actual) if frame.actual is not None else base
            self._truth[frame_name] = true
            parent_true = true
        return parent_true

    def _unknown_chain(self, name: str, known: Mapping[str, object]) -> list[str]:
        """``name`` and its ancestors up to (not including) the first in ``known`` or the world."""
        chain = [name]
        parent = self.frames[name].parent
        while parent != WORLD and parent not in known:
            chain.append(parent)
            parent = self.frames[parent].parent
        return chain

    def bind(self, robot: RobotModel) -> Cell:
        """This cell for ``robot`` (joint poses can then be given by joint name); shares the poses
        composed so far instead of composing them again."""
        bound = copy.copy(self)
        object.__setattr__(bound, "robot", robot)
        return bound

    def joint_values(self, name: str, robot: RobotModel | None = None) -> dict[str, float]:
        """The named joint pose as ``{joint name: rad}`` for ``robot`` (default: the bound robot)."""
        robot = robot or self.robot
        if robot is None:
            raise ValueError(f"cell {self.name}: joint pose {name!r} needs a robot to name its joints")
        pose = self.joint_poses[name]
        names = robot.group(pose.group).joint_names if pose.group else robot.joint_names
        if len(names) != len(pose.values):
            raise ValueError(f"joint pose {name!r} has {len(pose.values)} values; {robot.name} needs {len(names)}")
        return dict(zip(names, pose.values))

    def to_snapshot(self, robot: RobotModel | None = None) -> CellSnapshot:
        """The cell as the engine publishes it: frames in the world, elements, joint poses, truth."""
        parts = self.snapshot_parts(robot)
        return CellSnapshot(
            name=self.name,
            frames=tuple(parts["frames"]),
            elements=dict(parts["elements"]),
            joint_poses=dict(parts["joint_poses"]),
            truth=dict(parts["truth"]),
            joint_pose_groups=dict(parts["joint_pose_groups"]),
        )

    def snapshot_parts(self, robot: RobotModel | None = None) -> dict[str, Iterator[Any]]:
        """The snapshot's collections, made one item at a time: frames as CellFrames, the maps as
        (key, value) pairs.  :meth:`to_snapshot` collects them; the validator sizes them one by one
        and stops at the message limit (app_model.wire_fit) without building a snapshot too big
        to send."""
        frames = itertools.chain(
            (CellFrame(name=f.name, pose=self.pose(f.name), kind=f.kind, parent=f.parent, attributes=dict(f.attributes)) for f in self.frames.values()),
            (_zone_frame_of(self, z) for z in self.zones.values()),  # for the machines' zone gates
        )
        elements = ((e.name, {"kind": e.kind, **e.attributes}) for e in self.elements.values())
        joint_poses = ((name, self.joint_values(name, robot)) for name in self.joint_poses)
        groups = ((name, pose.group) for name, pose in self.joint_poses.items() if pose.group)
        return {"frames": frames, "elements": elements, "joint_poses": joint_poses, "truth": ((n, t) for n in self.frames if (t := self._true(n)) is not None), "joint_pose_groups": groups}


def _zone_frame_of(cell: Cell, zone: Zone) -> CellFrame:
    pose, attributes = zone_frame(zone, cell.pose(zone.parent))
    return CellFrame(name=zone.name, pose=pose, kind=ZONE_KIND, parent=zone.parent, attributes=attributes)


def _check_tree(frames: Mapping[str, Frame]) -> None:
    """Every chain reaches the world: no unknown parent, no cycle (frame_tree, linear time)."""
    ordered = order_frames({name: frame.parent for name, frame in frames.items()})
    if ordered.unknown:
        name, parent = next(iter(ordered.unknown.items()))
        raise ValueError(f"frame {name!r} has an unknown parent {parent!r}")
    if ordered.cycles:
        raise ValueError(f"frames {' -> '.join(ordered.cycles[0])} -> {ordered.cycles[0][0]} form a cycle")


def check_joint_poses(cell: Cell, robot: RobotModel) -> list[Diagnostic]:
    """Each joint pose fits ``robot``: a known group, one value per joint, inside the limits."""
    out: list[Diagnostic] = []
    for pose in cell.joint_poses.values():
        where = pose.joints_location or pose.location or Location(str(cell.path or cell.name), 1, 1)
        if pose.name in robot.poses:
            out.append(Diagnostic.at(pose.location or where, (
                f"joint pose {pose.name!r} has the name of a pose of {robot.name}; the name is ambiguous, rename it"
            ), "warning"))
        if pose.group is not None and pose.group not in robot.group_names:
            group_where = pose.group_location or pose.location or where
            out.append(Diagnostic.at(group_where, f"joint pose {pose.name!r}: {pose.group!r} is not a group of {robot.name} ({', '.join(robot.group_names)})"))
            continue
        joints = robot.group(pose.group).joints if pose.group else robot.joints
        owner = pose.group or robot.name
        if len(pose.values) != len(joints):
            out.append(Diagnostic.at(where, (
                f"joint pose {pose.name!r} has {len(pose.values)} values; {owner} has {len(joints)} joints, "
                f"in this order: {' '.join(j.name for j in joints)}"
            )))
            continue
        for joint, value in zip(joints, pose.values):
            if not joint.contains(value):
                out.append(Diagnostic.at(where, (
                    f"joint pose {pose.name!r}: {joint.name} = {math.degrees(value):.2f} deg is outside its limits "
                    f"[{math.degrees(joint.lower):.1f}, {math.degrees(joint.upper):.1f}] deg"
                )))
    return out
