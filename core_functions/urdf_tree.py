"""A URDF's kinematic tree on pinocchio: where each child link sits in its parent link.

This is robot_state_publisher's arithmetic.  The tree (which joint joins which links) and every
transform come from pinocchio's model of the URDF -- the same loader the Nextage simulator's
kinematics use -- so what ``tf`` shows and what the simulator computes cannot disagree, and no
URDF origin is parsed here by hand.  In pinocchio's model each link is a BODY frame whose parent
frame is its joint's frame (JOINT, or FIXED_JOINT for a fixed joint), whose parent frame in turn
is the parent link; the root link hangs from the ``universe`` frame (index 0).

Movable joints (revolute, continuous, prismatic) are placed from joint positions; fixed joints
never move, so they are computed once.  Floating and planar joints are left out, as
robot_state_publisher leaves them out: something else (localisation) owns those transforms.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from core_functions.geometry import Pose

_MOVABLE_NQ = (1, 2)  # revolute / prismatic: q; continuous (unbounded revolute): cos q, sin q


@dataclass(frozen=True)
class TreeJoint:
    """One URDF joint as tf shows it: ``child`` link placed in ``parent`` link."""

    name: str
    parent: str
    child: str
    movable: bool


class UrdfTree:
    """Link transforms of one URDF for given joint positions (rad, m)."""

    def __init__(self, urdf_xml: str) -> None:
        self.model = pin.buildModelFromXML(urdf_xml)
        self._data = self.model.createData()
        frames = self.model.frames
        self._link_frame: dict[str, int] = {}
        joints: list[TreeJoint] = []
        self._slots: dict[str, tuple[int, int]] = {}  # movable joint -> (first q index, nq)
        self.root = ""
        for fid, frame in enumerate(frames):
            if frame.type != pin.FrameType.BODY:
                continue
            self._link_frame[frame.name] = fid
            joint_frame = frames[_parent_frame(frame)]
            parent = frames[_parent_frame(joint_frame)]
            if _parent_frame(frame) == 0 or parent.type != pin.FrameType.BODY:
                # the root link: it hangs from "universe" (pinocchio 3) or from a fixed root joint
                # frame on "universe" (pinocchio 2)
                self.root = self.root or frame.name
                continue
            parent_link = parent.name
            if joint_frame.type == pin.FrameType.FIXED_JOINT:
                joints.append(TreeJoint(joint_frame.name, parent_link, frame.name, movable=False))
                continue
            joint = self.model.joints[parent_joint(frame)]
            if joint.nq not in _MOVABLE_NQ or joint.nv != 1:
                continue  # floating or planar
            joints.append(TreeJoint(joint_frame.name, parent_link, frame.name, movable=True))
            self._slots[joint_frame.name] = (joint.idx_q, joint.nq)
        self.joints: tuple[TreeJoint, ...] = tuple(joints)

    @property
    def links(self) -> tuple[str, ...]:
        return tuple(self._link_frame)

    @property
    def movable_joints(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints if j.movable)

    def fixed_transforms(self) -> list[tuple[TreeJoint, Pose]]:
        """Every fixed joint with its child's pose in the parent (the same for any joint positions)."""
        self._update(pin.neutral(self.model))
        return [(j, self._relative(j)) for j in self.joints if not j.movable]

    def movable_transforms(self, names: Sequence[str], positions: Sequence[float]) -> list[tuple[TreeJoint, Pose]]:
        """Each movable joint named in ``names`` with its child's pose for its position.

        Joints the state does not name are left out, not guessed at 0: a listener then reports
        the missing transform instead of showing the arm somewhere it is not.
        """
        given = self.positions(names, positions)
        self.place(given)
        return [(j, self._relative(j)) for j in self.joints if j.name in given]

    def place(self, given: Mapping[str, float]) -> None:
        """Forward kinematics for these joint positions (:meth:`positions`), the others at 0."""
        q = pin.neutral(self.model)
        for name, value in given.items():
            first, nq = self._slots[name]
            if nq == 1:
                q[first] = value
            else:
                q[first], q[first + 1] = math.cos(value), math.sin(value)
        self._update(q)

    def relative(self, joint: TreeJoint) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """The child link in the parent link after :meth:`place`: translation (m) and unit quaternion
        (x, y, z, w with w >= 0, as :meth:`Pose.from_matrix` gives it), straight from pinocchio --
        ``tf`` asks for every movable joint 20 times a second, without needing a checked Pose."""
        placements = self._data.oMf
        placement = placements[self._link_frame[joint.parent]].actInv(placements[self._link_frame[joint.child]])
        t, r = placement.translation, pin.Quaternion(placement.rotation)
        x, y, z, w = float(r.x), float(r.y), float(r.z), float(r.w)
        if w < 0:
            x, y, z, w = -x, -y, -z, -w
        return (float(t[0]), float(t[1]), float(t[2])), (x, y, z, w)

    def positions(self, names: Sequence[str], positions: Sequence[float]) -> Mapping[str, float]:
        """The positions of this tree's movable joints among ``names``; ValueError on a length mismatch."""
        if len(names) != len(positions):
            raise ValueError(f"joint state has {len(names)} names but {len(positions)} positions")
        return {n: float(p) for n, p in zip(names, positions) if n in self._slots}

    def _update(self, q: np.ndarray) -> None:
        pin.forwardKinematics(self.model, self._data, q)
        pin.updateFramePlacements(self.model, self._data)

    def _relative(self, joint: TreeJoint) -> Pose:
        placements = self._data.oMf
        parent = placements[self._link_frame[joint.parent]]
        child = placements[self._link_frame[joint.child]]
        return Pose.from_matrix(np.array(parent.actInv(child).homogeneous))


def _parent_frame(frame: pin.Frame) -> int:
    """The frame a frame hangs from: ``parentFrame`` since pinocchio 3, ``previousFrame`` in 2.x."""
    return int(frame.parentFrame if hasattr(frame, "parentFrame") else frame.previousFrame)


def parent_joint(frame: pin.Frame) -> int:
    """The joint that moves a frame: ``parentJoint`` since pinocchio 3, ``parent`` in 2.x."""
    return int(frame.parentJoint if hasattr(frame, "parentJoint") else frame.parent)
