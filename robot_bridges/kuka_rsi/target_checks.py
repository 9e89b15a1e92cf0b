"""The KUKA RSI back end's checks of a primitive's target, before anything is sent to the robot.

A KR C4 stops RSI on a software limit switch, on a correction it cannot follow, or when a straight line leaves the
workspace; the back end refuses such a target first, with a one-line finding naming the axis or the line, so that
a bad request fails before anything moves and RSI need not be restarted.  Every check starts from the set point
the loop commands, never from what the controller reports.
"""
from __future__ import annotations

import math

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import MoveJoints
from core_functions.robots import GroupSpec
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.kinematics import KukaArm


def joint_target(name: str, spec: GroupSpec, primitive: MoveJoints, commanded: np.ndarray) -> np.ndarray:
    """The six axes a joint move aims at, from the commanded set point; refused beyond a joint's limits.

    Axes the primitive does not name stay where they are: no change (relative) or the current set point.
    """
    names = spec.joint_names
    values = np.array(primitive.positions, dtype=float)
    if primitive.joint_names:
        unknown = [n for n in primitive.joint_names if n not in names]
        if unknown or len(set(primitive.joint_names)) != len(primitive.joint_names):
            raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: joints {list(primitive.joint_names)} are not the axes {list(names)}")
        order = {n: i for i, n in enumerate(primitive.joint_names)}
        values = np.array(
            [values[order[n]] if n in order else (0.0 if primitive.relative else commanded[i]) for i, n in enumerate(names)]
        )
    elif len(values) != 6:
        raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: a joint move needs 6 values (A1..A6), got {len(values)}")
    target = values + commanded if primitive.relative else values
    for joint, value in zip(spec.joints, target):
        if not joint.contains(float(value)):
            raise BridgeError(
                FaultKind.JOINT_LIMIT,
                f"{name}: {joint.name} target {math.degrees(value):.3f} deg is outside "
                f"[{math.degrees(joint.lower):.1f}, {math.degrees(joint.upper):.1f}] deg",
            )
    return target


def reach(name: str, arm: KukaArm, target: Pose, reference: np.ndarray, what: str) -> np.ndarray:
    """The axes that put the TCP at ``target`` nearest ``reference``; UNREACHABLE when none lies within the limits."""
    goal = arm.ik(target.matrix(), reference)
    if goal is None:
        raise BridgeError(FaultKind.UNREACHABLE, f"{name}: {what} is out of reach of the arm (no IK solution within the joint limits)")
    return goal


def check_line(name: str, arm: KukaArm, start: Pose, target: Pose, reference: np.ndarray, what: str, samples: int = 50) -> None:
    """Refuse a straight line that leaves the workspace or flips the arm (the robot would stop)."""
    p0, p1 = np.array(start.position), np.array(target.position)
    q0, q1 = np.array(start.quaternion), np.array(target.quaternion)
    if float(np.dot(q0, q1)) < 0:
        q1 = -q1
    q = reference
    for k in range(1, samples + 1):
        s = k / samples
        quat = q0 + s * (q1 - q0)
        quat /= np.linalg.norm(quat)
        pose = Pose(*(p0 + s * (p1 - p0)), *quat)
        solved = arm.ik(pose.matrix(), q)
        if solved is None or float(np.max(np.abs(solved - q))) > math.radians(30):
            raise BridgeError(
                FaultKind.UNREACHABLE,
                f"{name}: the straight line to {what} leaves the workspace or passes a singularity at {100 * s:.0f}%",
            )
        q = solved
