"""The robot as its URDF describes it (``/robot_description``), on pinocchio: limits, forward and inverse kinematics.

The ros2-control back end knows nothing of a robot but its URDF: the joints' ranges and speeds
(``<limit lower upper velocity>``), the kinematic tree, and the root link, which is the frame every
Cartesian target is in.  Each group is a chain of the URDF's joints ending at a tip frame (a link,
``tool0`` by convention); inverse kinematics moves only the group's joints, the others stay where
``/joint_states`` has them (a torso is its own group, as a dual-arm controller has it).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from core_functions.geometry import Pose
from robot_bridges.backend import BridgeError, FaultKind

Vector = NDArray[np.float64]

#: IK: how close a solution must put the tip (m, rad), the damping and how many tries from other seeds.
IK_POSITION_TOLERANCE = 1e-5
IK_ANGLE_TOLERANCE = 1e-4
IK_DAMPING = 1e-6
IK_ITERATIONS = 200
IK_RESTARTS = 8
#: The longest robot description taken (a description with meshes inline is a few MB; more is not a URDF).
MAX_URDF_CHARS = 16 * 1024 * 1024


class UrdfError(ValueError):
    """The URDF cannot be read, or lacks what a group needs (a joint, a limit, the tip)."""


@dataclass(frozen=True)
class JointRange:
    name: str
    lower: float
    upper: float
    velocity: float


class UrdfModel:
    """The URDF's kinematic model: ``q`` vectors hold every movable joint in :attr:`joint_names` order."""

    def __init__(self, urdf: str) -> None:
        if len(urdf) > MAX_URDF_CHARS:
            raise UrdfError(f"the robot description is {len(urdf):,} characters, over the limit of {MAX_URDF_CHARS:,}")
        if "<!DOCTYPE" in urdf or "<!ENTITY" in urdf or "\x00" in urdf:
            raise UrdfError("the robot description declares a <!DOCTYPE> or an entity, or holds a NUL: refused (a URDF needs neither)")
        if "<robot" not in urdf:
            raise UrdfError("the robot description is not a URDF (no <robot> element)")
        try:
            self.model = pin.buildModelFromXML(urdf)
        except (RuntimeError, ValueError) as error:
            raise UrdfError(f"pinocchio cannot build a model from the URDF: {error}") from None
        self.data = self.model.createData()
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        for jid in range(1, self.model.njoints):
            if self.model.joints[jid].nq != 1:
                raise UrdfError(f"joint {self.model.names[jid]!r} is not a revolute or prismatic joint (ros2-control drives single-axis joints)")
        self.root = self.model.frames[1].name if self.model.nframes > 1 else "world"  # frame 0 is pinocchio's universe
        self.ranges = {name: self._range(name) for name in self.joint_names}

    def _range(self, name: str) -> JointRange:
        jid = self.model.getJointId(name)
        iq, iv = self.model.joints[jid].idx_q, self.model.joints[jid].idx_v
        lower, upper = float(self.model.lowerPositionLimit[iq]), float(self.model.upperPositionLimit[iq])
        velocity = float(self.model.velocityLimit[iv])
        if not (math.isfinite(lower) and math.isfinite(upper) and lower <= upper):
            raise UrdfError(f"joint {name!r} has no position limits in the URDF (a continuous joint): add <limit lower upper>")
        if not (math.isfinite(velocity) and velocity > 0):
            raise UrdfError(f"joint {name!r} has no velocity limit in the URDF: add <limit velocity=...> above 0")
        return JointRange(name, lower, upper, velocity)

    def index(self, joint: str) -> int:
        try:
            return self.joint_names.index(joint)
        except ValueError:
            raise UrdfError(f"joint {joint!r} is not a movable joint of the URDF (it has: {', '.join(self.joint_names)})") from None

    def has_frame(self, frame: str) -> bool:
        return bool(self.model.existFrame(frame))

    def frame_pose(self, q: Vector, frame: str) -> Pose:
        return _pose(self.placement(q, frame))

    def placement(self, q: Vector, frame: str) -> pin.SE3:
        fid = self.model.getFrameId(frame)
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, fid)


@dataclass(frozen=True)
class Chain:
    """One group on the model: its joints (indices into the model's ``q``) and its tip frame."""

    model: UrdfModel
    group: str
    joints: tuple[str, ...]
    tip: str
    tool: Pose = Pose()  # the TCP in the tip frame (a tool the URDF does not describe)

    def __post_init__(self) -> None:
        for joint in self.joints:
            try:
                self.model.index(joint)
            except UrdfError as error:
                raise UrdfError(f"{error} (option {self.group}.joints)") from None
        if not self.model.has_frame(self.tip):
            raise UrdfError(f"the tip frame {self.tip!r} of {self.group} is not a link of the URDF (option {self.group}.tip)")

    @property
    def indices(self) -> list[int]:
        return [self.model.index(j) for j in self.joints]

    @property
    def lower(self) -> Vector:
        return np.array([self.model.ranges[j].lower for j in self.joints])

    @property
    def upper(self) -> Vector:
        return np.array([self.model.ranges[j].upper for j in self.joints])

    @property
    def velocity(self) -> Vector:
        return np.array([self.model.ranges[j].velocity for j in self.joints])

    def tip_pose(self, q: Vector) -> Pose:
        """The TCP: the tip frame composed with the tool."""
        return _pose(self.model.placement(q, self.tip) * _se3(self.tool))

    def with_joints(self, q: Vector, values: Sequence[float]) -> Vector:
        full = np.array(q, dtype=float)
        full[self.indices] = values
        return full

    def solve(self, target: Pose, q: Vector) -> Vector:
        """The group's joints that put the tip at ``target`` (world = the URDF's root), nearest to ``q``
        first; UNREACHABLE naming the target when no solution within the joint ranges exists."""
        goal = _se3(target) * _se3(self.tool).inverse()  # where the tip frame must be
        lower, upper, idx = self.lower, self.upper, self.indices
        seeds = [np.clip(q[idx], lower, upper)]
        rng = np.random.default_rng(len(self.joints))  # deterministic restarts: the same target gives the same joints
        seeds += [lower + (upper - lower) * rng.random(len(idx)) for _ in range(IK_RESTARTS)]
        best: Vector | None = None
        for seed in seeds:
            solution = self._descend(goal, q, seed, lower, upper)
            if solution is not None and (best is None or np.max(np.abs(solution - q[idx])) < np.max(np.abs(best - q[idx]))):
                best = solution
                if seed is seeds[0]:
                    break  # the nearest: the seed was where the arm is
        if best is None:
            p = target
            raise BridgeError(FaultKind.UNREACHABLE, f"{self.group}: no joint solution within the joint limits puts the TCP ({self.tip} and its tool) at "
                              f"({p.x:.4f}, {p.y:.4f}, {p.z:.4f}) m in {self.model.root}")
        return best

    def _descend(self, goal: pin.SE3, q: Vector, seed: Vector, lower: Vector, upper: Vector) -> Vector | None:
        model, data, idx = self.model.model, self.model.data, self.indices
        fid = model.getFrameId(self.tip)
        full = np.array(q, dtype=float)
        full[idx] = seed
        for _ in range(IK_ITERATIONS):
            pin.forwardKinematics(model, data, full)
            current = pin.updateFramePlacement(model, data, fid)
            error = pin.log6(current.actInv(goal)).vector
            if np.linalg.norm(error[:3]) < IK_POSITION_TOLERANCE and np.linalg.norm(error[3:]) < IK_ANGLE_TOLERANCE:
                return full[idx].copy()
            jacobian = pin.computeFrameJacobian(model, data, full, fid, pin.LOCAL)[:, [model.joints[model.getJointId(j)].idx_v for j in self.joints]]
            step = jacobian.T @ np.linalg.solve(jacobian @ jacobian.T + IK_DAMPING * np.eye(6), error)
            full[idx] = np.clip(full[idx] + step, lower, upper)
        return None


def _se3(pose: Pose) -> pin.SE3:
    x, y, z, w = pose.quaternion
    return pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), np.array([pose.x, pose.y, pose.z]))


def _pose(placement: pin.SE3) -> Pose:
    quaternion = pin.Quaternion(placement.rotation)
    t = placement.translation
    return Pose(float(t[0]), float(t[1]), float(t[2]), float(quaternion.x), float(quaternion.y), float(quaternion.z), float(quaternion.w))
