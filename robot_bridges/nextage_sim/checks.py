"""The simulator's checks: joint limits, collisions, a camera's working range, and the faults injected on purpose.

A real Nextage stops at a limit switch or when two bodies touch, and a camera does not see a feature beyond its
range; the simulator must fail in the same places with the same one-line findings, or error handling is tested
against a robot that does not exist.  Kept apart from the primitives (robot_bridges/nextage_sim/backend.py) so
that what is refused, and how it is said, can be read in one place.  Every check takes the robot's joints ``q``
(the full 15-vector, in the model's order) as they are now.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import Vision, describe
from core_functions.robots import NEXTAGE_OPEN
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.camera.spec import CameraSpec
from robot_bridges.nextage_sim.faults import FaultSpec
from robot_bridges.nextage_sim.guard import CollisionGuard
from robot_bridges.nextage_sim.jobs import Job
from robot_bridges.nextage_sim.model import ArmKinematics, NextageModel, describe_target
from robot_bridges.nextage_sim.trajectory import Motion


#: Where each arm's current motion starts and ends: the work its hand may touch (robot_bridges/collision).
Work = dict[str, tuple[Pose, ...]]


def limit_violation(model: NextageModel, q: np.ndarray, idx: np.ndarray, values: np.ndarray) -> str | None:
    """What is wrong with putting the joints ``idx`` at ``values``, the rest as in ``q`` (None: nothing)."""
    probe = q.copy()
    probe[idx] = values
    return model.limit_violation(probe, idx, tolerance=1e-7)


def require_within_limits(model: NextageModel, q: np.ndarray, group: str, idx: np.ndarray, values: np.ndarray, what: str) -> None:
    """JOINT_LIMIT naming the group and ``what`` is refused, before anything moves."""
    problem = limit_violation(model, q, idx, values)
    if problem:
        raise BridgeError(FaultKind.JOINT_LIMIT, f"{group}: {what}: {problem}")


def note_work(model: NextageModel, q: np.ndarray, work: Work, groups: frozenset[str], motion: Motion) -> None:
    """Record in ``work`` where each arm of ``motion`` starts (``q``) and ends."""
    end = q.copy()
    end[motion.indices] = motion.end
    for g in groups:
        arm = model.arms.get(g)
        if arm is not None:
            work[g] = (arm.tcp_pose(q), arm.tcp_pose(end))


def check_collisions(guard: CollisionGuard, now: float, q: np.ndarray, moving: Mapping[Job, Motion], work: Work, job: Job, motion: Motion, t: float) -> None:
    """Stop the motion where two bodies touch (a vision-corrected target the dry run never saw, say).

    The guard (robot_bridges/nextage_sim/guard.py) swept the running motions when they started;
    here the tick only learns whether it has reached the first touch.  The joints are put back
    where the bodies touched, and the fault says when that was.
    """
    touch = guard.check(now, job, t, q, moving, work)
    if touch is None:
        return
    back = min(max(0.0, t - (now - touch.at) * job.rate.rate), t)
    q[motion.indices] = motion.at(back)
    raise BridgeError(
        FaultKind.COLLISION,
        f"{', '.join(sorted(job.groups))}: {describe(job.primitive)} at t = {back:.3f} s: {touch.contact.describe(guard.scene.margin)}",
    )


def check_range(primitive: Vision, nominal: Pose | None, placed: Sequence[tuple[CameraSpec, Pose]]) -> None:
    """A feature beyond a camera's working range is not seen (VISION naming distance and range)."""
    if nominal is None:
        return
    for cam, pose in placed:
        distance = pose.distance_to(nominal)
        if distance > cam.max_range:
            raise BridgeError(
                FaultKind.VISION,
                f"{primitive.target or 'the feature'} is {distance:.3f} m from {cam.name}, beyond its {cam.max_range:.2f} m working range",
            )


def injected_fault_error(model: NextageModel, q: np.ndarray, job: Job, fault: FaultSpec, target: Pose | None = None) -> BridgeError:
    """The error an injected ``fault`` raises, worded as the real fault would be and marked as injected."""
    share = 0.0 if job.duration <= 0 else 100.0 * job.progress / job.duration
    where = f"{share:.0f}% into {describe(job.primitive)}"
    if fault.kind is FaultKind.UNREACHABLE:
        what = f"no IK solution for TCP target {describe_target(target)}" if target is not None else "IK failed"
        return BridgeError(FaultKind.UNREACHABLE, f"{fault.group}: {what} ({where}; injected fault)")
    if fault.kind is FaultKind.JOINT_LIMIT:
        idx = model.indices(NEXTAGE_OPEN.group(fault.group).joint_names)
        name = model.joint_names[int(idx[0])]
        value = float(q[idx[0]])
        return BridgeError(
            FaultKind.JOINT_LIMIT,
            f"{fault.group}: {name} at {value:.4f} rad ({math.degrees(value):.2f} deg) tripped its limit switch "
            f"({where}; injected fault)",
        )
    return BridgeError(fault.kind, f"{fault.group}: {fault.kind.value} fault ({where}; injected fault)")


def require_arm(model: NextageModel, group: str) -> ArmKinematics:
    """The group's arm: UNSUPPORTED for a group without a TCP (Cartesian primitives need an arm)."""
    arm = model.arms.get(group)
    if arm is None:
        raise BridgeError(FaultKind.UNSUPPORTED, f"{group} has no TCP: Cartesian primitives need left_arm or right_arm")
    return arm
