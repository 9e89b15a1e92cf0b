"""The Cartesian primitives' motions, planned completely from where the robot is before anything moves.

A bad request (out of reach, a singularity on a straight line, a jump of the joints) must fail before the arm
starts, as on the real robot, so a primitive of the simulator (robot_bridges/nextage_sim/backend.py) first asks
this module for the whole :class:`~robot_bridges.nextage_sim.trajectory.Motion` and only then plays it.  This
module ties the arm's kinematics (model.py) to the generic planners of trajectory.py: IK warm-started along a
path, the TCP pose as the line's frame, a master/slave pair's two legs, a recording's legs.  ``q`` is always the
robot's full joint vector as it is now; nothing here changes it.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from core_functions.geometry import Pose
from core_functions.linear_path import LineTolerance
from core_functions.primitives import MasterSlaveMove, RecordTrajectory
from robot_bridges.nextage_sim.model import ArmKinematics
from robot_bridges.nextage_sim.trajectory import (
    CartesianLimits,
    Chain,
    LinearLeg,
    Motion,
    plan_joint_move,
    plan_linear,
    plan_straight,
    straight_leg,
)

#: The joints' velocity and acceleration limits of the planned joints (rad/s, rad/s²).
Limits = tuple[np.ndarray, np.ndarray]


def path_solver(arm: ArmKinematics, q: np.ndarray) -> Callable[[Pose, np.ndarray], np.ndarray]:
    """IK along a path: warm-started from the previous sample, no restarts (no branch hopping)."""
    base = q.copy()

    def solve(target: Pose, seed: np.ndarray) -> np.ndarray:
        base[arm.indices] = seed
        return arm.solve(target, base, restarts=False).positions

    return solve


def path_forward(arm: ArmKinematics, q: np.ndarray) -> Callable[[np.ndarray], Pose]:
    """The TCP pose for the arm's joints, the rest of the robot as in ``q`` (the line's frame)."""
    base = q.copy()

    def forward(q_arm: np.ndarray) -> Pose:
        base[arm.indices] = q_arm
        return arm.tcp_pose(base)

    return forward


def plan_cartesian(
    group: str,
    arm: ArmKinematics,
    q: np.ndarray,
    start: Pose,
    target: Pose,
    interpolation: str,
    limits: Limits,
    cartesian: CartesianLimits,
    speed: float,
) -> Motion:
    """MoveCartesian / MoveRelative from the TCP pose ``start`` (the arm's at ``q``): a straight TCP line
    (``linear``) or a joint move onto the IK solution."""
    velocity, acceleration = limits
    if interpolation == "linear":
        leg = straight_leg(group, q[arm.indices], start, target, path_solver(arm, q), arm.joint_names)
        return plan_straight(arm.indices, leg, path_forward(arm, q), velocity, acceleration, cartesian, cartesian.tolerance, speed)
    solution = arm.solve(target, q)
    return plan_joint_move(arm.indices, q[arm.indices], solution.positions, velocity, acceleration, speed)


def plan_recording(
    group: str, arm: ArmKinematics, q: np.ndarray, primitive: RecordTrajectory, limits: Limits, cartesian: CartesianLimits
) -> Chain:
    """A planned RecordTrajectory: the legs through its waypoints at full speed, each as its interpolation says.

    Straight legs keep to the recording's own tolerance; the samples are taken from the result
    (:func:`~robot_bridges.nextage_sim.trajectory.sample`).
    """
    velocity, acceleration = limits
    segments: list[Motion] = []
    pose = arm.tcp_pose(q)
    current = q[arm.indices]
    tolerance = LineTolerance(primitive.tolerance, primitive.angle_tolerance)
    for waypoint in primitive.waypoints:
        if primitive.interpolation == "linear":
            leg = straight_leg(group, current, pose, waypoint, path_solver(arm, q), arm.joint_names)
            segments.append(plan_straight(arm.indices, leg, path_forward(arm, q), velocity, acceleration, cartesian, tolerance, 1.0))
        else:
            base = q.copy()
            base[arm.indices] = current
            goal = arm.solve(waypoint, base).positions
            segments.append(plan_joint_move(arm.indices, current, goal, velocity, acceleration, 1.0))
        current, pose = segments[-1].end, waypoint
    return Chain(segments)


def plan_master_slave(
    primitive: MasterSlaveMove, master: ArmKinematics, slave: ArmKinematics, q: np.ndarray, limits: Limits, cartesian: CartesianLimits, speed: float
) -> Motion:
    """Both TCPs along straight segments, the slave rigidly at ``offset`` from the master.

    Without an explicit offset the TCPs keep the one they have at the start (a part held by
    both hands stays held).  If the slave does not hold the offset at the start, its first
    segment is its own straight line onto ``slave_path[0]``; from then on it follows
    ``master * offset``.  ``limits`` are those of the master's joints then the slave's.
    """
    indices = np.concatenate([master.indices, slave.indices])
    velocity, acceleration = limits
    m_pose, s_pose = master.tcp_pose(q), slave.tcp_pose(q)
    offset = primitive.offset or m_pose.inverse().compose(s_pose)
    m_q, s_q = q[master.indices], q[slave.indices]
    rigid = s_pose.distance_to(m_pose.compose(offset)) < 1e-3 and s_pose.angle_to(m_pose.compose(offset)) < math.radians(0.5)
    lever = float(np.linalg.norm(offset.position))
    segments: list[Motion] = []
    for k, (m_target, s_target) in enumerate(zip(primitive.master_path, primitive.slave_path(offset))):
        m_leg = straight_leg(primitive.master, m_q, m_pose, m_target, path_solver(master, q), master.joint_names)
        if rigid or k > 0:
            s_leg = LinearLeg(
                primitive.slave, s_q, lambda s, leg=m_leg: leg.pose_at(s).compose(offset), path_solver(slave, q),
                slave.joint_names, m_leg.length + lever * m_leg.angle, m_leg.angle,
            )
        else:
            s_leg = straight_leg(primitive.slave, s_q, s_pose, s_target, path_solver(slave, q), slave.joint_names)
        segment = plan_linear(indices, [m_leg, s_leg], velocity, acceleration, cartesian, speed)
        segments.append(segment)
        m_q, s_q = segment.end[:6], segment.end[6:]
        m_pose, s_pose = m_target, s_target
    return Chain(segments)
