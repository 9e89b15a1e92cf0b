"""A FollowJointTrajectory goal checked against one group's limits and turned into what the arm will do.

control_msgs/action/FollowJointTrajectory is how MoveIt 2 and every ROS 2 motion stack moves an arm;
:mod:`robot_bridges.trajectory_server` serves it on each bridge.  This module holds what a goal
means, without any transport: :func:`plan_goal` checks a goal and gives a :class:`FollowPlan` (the
path from where the arm is, every joint of the group at every point, the tolerances), or raises
:class:`Refused` with the action's error code and a one-line reason naming the joint and the point.

What is checked, before anything moves (the back end checks its primitives again on its own):

* the joint names: each one of the group's, none twice (INVALID_JOINTS); joints the goal leaves out
  hold where they are, as joint_trajectory_controller's ``allow_partial_joints_goal``;
* the points: at least one; positions for every named joint, velocities and accelerations empty or
  one per joint, no efforts, times strictly increasing, the last point at rest (INVALID_GOAL);
  no multi-DOF trajectory (the bridges drive joints);
* the robot's limits: every position within the joint's range, every given velocity and acceleration
  within the joint's, and the path as the bridge plays it -- straight lines between the points, as
  joint_trajectory_controller interpolates a positions-only trajectory, starting from where the arm
  is now -- never faster than a joint can go, nor changing speed faster than it can accelerate
  between two segments (from rest at the start, to rest at the end) (INVALID_GOAL);
* the header's stamp: a trajectory whose start is set and whose end is already past is refused
  (OLD_HEADER_TIMESTAMP); one that starts later waits for its start (at most :data:`MAX_START_DELAY`).

Tolerances follow control_msgs/JointTolerance: 0 takes the server's default, a negative value
checks nothing, a positive one is the bound.  Path tolerances bound the distance between where the
arm is and where the path says it should be while it moves; goal tolerances where it ends and how
fast it still moves there; ``goal_time_tolerance`` how long after the path's end the arm may take to
get within them.  Accelerations are not measured (the back ends report positions), so acceleration
tolerances are taken and not checked, as joint_trajectory_controller does without acceleration states.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from node_transport import mirrors
from robot_bridges.backend import JointLimits

ACTION_TYPE = "control_msgs/action/FollowJointTrajectory"
FollowJointTrajectory = mirrors.action(ACTION_TYPE)
Goal, Result, Feedback = FollowJointTrajectory.Goal, FollowJointTrajectory.Result, FollowJointTrajectory.Feedback
JointTrajectoryPoint = mirrors.mirror("trajectory_msgs/msg/JointTrajectoryPoint")
Duration = mirrors.mirror("builtin_interfaces/msg/Duration")

SUCCESSFUL: int = Result.SUCCESSFUL
INVALID_GOAL: int = Result.INVALID_GOAL
INVALID_JOINTS: int = Result.INVALID_JOINTS
OLD_HEADER_TIMESTAMP: int = Result.OLD_HEADER_TIMESTAMP
PATH_TOLERANCE_VIOLATED: int = Result.PATH_TOLERANCE_VIOLATED
GOAL_TOLERANCE_VIOLATED: int = Result.GOAL_TOLERANCE_VIOLATED

#: rad: a first point at time 0 may lie this far from where the arm is (the back end moves it there first,
#: within its limits); MoveIt puts the start state there, measured a moment before.
START_TOLERANCE = 0.01
#: s: the latest start a header stamp may ask for; later is refused rather than waited for.
MAX_START_DELAY = 60.0
_SLACK = 1e-6  # relative: rounding of the goal's own numbers, not a margin on the limits
_TIME_EPS = 1e-9


class Refused(Exception):
    """A goal this group will not follow: ``code`` is the action's error code, the message says why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Tolerances:
    """Per joint of the group (its order): the bound, or ``inf`` where nothing is checked."""

    position: NDArray[np.float64]
    velocity: NDArray[np.float64]


@dataclass(frozen=True)
class FollowPlan:
    """What the group will do for one goal: ``points[k]`` (every joint of the group) at ``times[k]`` s
    after the start; ``points[0]`` at time 0 is where the arm was when the goal was planned."""

    group: str
    joint_names: tuple[str, ...]
    times: NDArray[np.float64]
    points: NDArray[np.float64]
    path: Tolerances
    goal: Tolerances
    goal_time: float  # s after the end the goal tolerances may take to be met (0: at the end)
    start_delay: float = 0.0  # s to wait for the header's start time

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Where the path says the joints are ``t`` s after the start, and how fast they move there."""
        times, points = self.times, self.points
        if t <= 0.0:
            return points[0].copy(), np.zeros(points.shape[1])
        if t >= times[-1]:
            return points[-1].copy(), np.zeros(points.shape[1])
        k = int(np.searchsorted(times, t, side="right")) - 1
        span = times[k + 1] - times[k]
        rate = (points[k + 1] - points[k]) / span
        return points[k] + rate * (t - times[k]), rate


@dataclass(frozen=True)
class DefaultTolerances:
    """The server's own tolerances, for a goal that gives 0 (per joint, rad and rad/s; ``inf``: unchecked)."""

    path_position: float = math.inf
    goal_position: float = math.inf
    goal_velocity: float = math.inf
    goal_time: float = 0.0


def seconds(duration: Any) -> float:
    return float(duration.sec) + float(duration.nanosec) * 1e-9


def plan_goal(
    group: str, goal: Any, limits: JointLimits, current: Sequence[float], now: float,
    defaults: DefaultTolerances = DefaultTolerances(),
) -> FollowPlan:
    """Check ``goal`` for ``group`` whose joints are at ``current`` (the group's order) at ROS time ``now``
    (s since 1970, or of ``/clock``); the plan, or :class:`Refused`."""
    trajectory = goal.trajectory
    names = tuple(trajectory.joint_names)
    if goal.multi_dof_trajectory.joint_names or goal.multi_dof_trajectory.points:
        raise Refused(INVALID_GOAL, f"{group}: multi-DOF trajectories are not followed here (the group has joints {', '.join(limits.joint_names)})")
    order = _joint_order(group, names, limits)
    count = len(trajectory.points)
    if count == 0:
        raise Refused(INVALID_GOAL, f"{group}: the trajectory has no points")
    here = np.array(current, dtype=float)
    times = np.array([seconds(p.time_from_start) for p in trajectory.points])
    goal_points = np.repeat(here[None, :], count, axis=0)
    for k, point in enumerate(trajectory.points):
        _check_point(group, k, point, names, count)
        if not math.isfinite(times[k]) or times[k] < 0.0 or (k and times[k] <= times[k - 1]):
            earlier = f" (point {k - 1} is at {times[k - 1]:g} s)" if k else ""
            raise Refused(INVALID_GOAL, f"{group}: point {k} is at {times[k]:g} s: times from start must increase strictly from 0{earlier}")
        goal_points[k, order] = point.positions
        _within(group, k, names, point.velocities, [limits.velocity[i] for i in order], "velocity", "rad/s")
        _within(group, k, names, point.accelerations, [limits.acceleration[i] for i in order], "acceleration", "rad/s^2")
    last = trajectory.points[-1]
    moving = [n for n, v in zip(names, last.velocities) if abs(v) > 1e-6]
    if moving:
        raise Refused(INVALID_GOAL, f"{group}: the last point (point {count - 1}) must be at rest, but {moving[0]} moves at {last.velocities[names.index(moving[0])]:g} rad/s there")
    _within_range(group, goal_points, limits)
    delay = _start_delay(group, trajectory.header.stamp, times[-1], now)
    if times[0] <= _TIME_EPS:
        far = np.abs(goal_points[0] - here)
        j = int(np.argmax(far))
        if far[j] > START_TOLERANCE:
            raise Refused(INVALID_GOAL, (
                f"{group}: point 0 is at time 0 but {limits.joint_names[j]} is at {here[j]:.4f} rad, not {goal_points[0, j]:.4f} rad "
                f"(more than {START_TOLERANCE:g} rad away): give the first point a time to get there"
            ))
        goal_points[0] = here  # where the arm is: the back end has nothing to move before the path
        points, path_times, first = goal_points, times - times[0], 0
    else:
        points, path_times, first = np.vstack([here, goal_points]), np.concatenate([[0.0], times]), 1
    _check_path(group, path_times, points, limits, first)
    path, final, goal_time = _tolerances(group, goal, limits, defaults)
    return FollowPlan(group, limits.joint_names, path_times, points, path, final, goal_time, delay)


def _joint_order(group: str, names: tuple[str, ...], limits: JointLimits) -> list[int]:
    own = limits.joint_names
    if not names:
        raise Refused(INVALID_JOINTS, f"{group}: the trajectory names no joints (the group's: {', '.join(own)})")
    for name in names:
        if name not in own:
            raise Refused(INVALID_JOINTS, f"{group}: joint {name!r} is not one of the group's joints ({', '.join(own)})")
        if names.count(name) > 1:
            raise Refused(INVALID_JOINTS, f"{group}: joint {name!r} is named {names.count(name)} times")
    return [own.index(n) for n in names]


def _check_point(group: str, k: int, point: Any, names: tuple[str, ...], count: int) -> None:
    width = len(names)
    if len(point.positions) != width:
        raise Refused(INVALID_GOAL, f"{group}: point {k} has {len(point.positions)} positions for {width} joints (positions are required)")
    for field in ("velocities", "accelerations"):
        size = len(getattr(point, field))
        if size not in (0, width):
            raise Refused(INVALID_GOAL, f"{group}: point {k} has {size} {field} for {width} joints (give none or one per joint)")
    if point.effort:
        raise Refused(INVALID_GOAL, f"{group}: point {k} gives efforts: the bridge commands positions only")
    for field in ("positions", "velocities", "accelerations"):
        for name, value in zip(names, getattr(point, field)):
            if not math.isfinite(value):
                raise Refused(INVALID_GOAL, f"{group}: point {k}: {field} of {name} is {value}")


def _within(group: str, k: int, names: Sequence[str], values: Sequence[float], bounds: Sequence[float], what: str, unit: str) -> None:
    for name, value, bound in zip(names, values, bounds):
        if abs(value) > bound * (1.0 + _SLACK):
            raise Refused(INVALID_GOAL, f"{group}: point {k}: {name} {what} {value:g} {unit} is beyond its limit {bound:g} {unit}")


def _within_range(group: str, points: NDArray[np.float64], limits: JointLimits) -> None:
    lower, upper = np.array(limits.lower), np.array(limits.upper)
    for k, point in enumerate(points):
        outside = np.nonzero((point < lower - 1e-9) | (point > upper + 1e-9))[0]
        if len(outside):
            j = int(outside[0])
            raise Refused(INVALID_GOAL, (
                f"{group}: point {k}: {limits.joint_names[j]} at {point[j]:.4f} rad is outside its limits "
                f"[{lower[j]:.4f}, {upper[j]:.4f}] rad"
            ))


def _check_path(group: str, times: NDArray[np.float64], points: NDArray[np.float64], limits: JointLimits, first: int) -> None:
    """Straight segments between the points: each within the joints' speeds, and the change of speed
    from one to the next (from rest before the first, to rest after the last) within their accelerations.
    ``points[first]`` is the goal's point 0 (1: the path starts where the arm is)."""
    names = limits.joint_names
    vmax, amax = np.array(limits.velocity), np.array(limits.acceleration)
    spans = np.diff(times)
    if not len(spans):
        return
    rates = np.diff(points, axis=0) / spans[:, None]
    over = np.abs(rates) > vmax * (1.0 + _SLACK)
    if over.any():
        k, j = (int(v) for v in np.argwhere(over)[0])
        where = "from where the arm is to point 0" if k < first else f"between points {k - first} and {k - first + 1}"
        raise Refused(INVALID_GOAL, (
            f"{group}: {names[j]} would move at {abs(rates[k, j]):.4f} rad/s {where} "
            f"({times[k]:g}..{times[k + 1]:g} s), above its limit {vmax[j]:.4f} rad/s"
        ))
    zero = np.zeros((1, points.shape[1]))
    speeds = np.vstack([zero, rates, zero])
    halves = np.concatenate([[0.0], spans, [0.0]])
    windows = (halves[:-1] + halves[1:]) / 2.0
    changes = np.abs(np.diff(speeds, axis=0)) / windows[:, None]
    over = changes > amax * (1.0 + _SLACK)
    if over.any():
        k, j = (int(v) for v in np.argwhere(over)[0])
        raise Refused(INVALID_GOAL, (
            f"{group}: {names[j]} would change speed by {abs(speeds[k + 1, j] - speeds[k, j]):.4f} rad/s within "
            f"{windows[k]:.4g} s at {times[k]:g} s ({changes[k, j]:.4f} rad/s^2), above its acceleration limit {amax[j]:.4f} rad/s^2"
        ))


def _start_delay(group: str, stamp: Any, duration: float, now: float) -> float:
    start = float(stamp.sec) + float(stamp.nanosec) * 1e-9
    if start == 0.0:
        return 0.0
    if start + duration < now:
        raise Refused(OLD_HEADER_TIMESTAMP, (
            f"{group}: the trajectory starts at {start:.3f} s and ends at {start + duration:.3f} s (header stamp + last time), "
            f"before now ({now:.3f} s)"
        ))
    delay = start - now
    if delay > MAX_START_DELAY:
        raise Refused(INVALID_GOAL, f"{group}: the trajectory starts {delay:.1f} s from now (header stamp): more than {MAX_START_DELAY:g} s ahead")
    return max(0.0, delay)


def _tolerances(group: str, goal: Any, limits: JointLimits, defaults: DefaultTolerances) -> tuple[Tolerances, Tolerances, float]:
    own = limits.joint_names
    count = len(own)
    path = Tolerances(np.full(count, defaults.path_position), np.full(count, math.inf))
    final = Tolerances(np.full(count, defaults.goal_position), np.full(count, defaults.goal_velocity))
    for entries, target in ((goal.path_tolerance, path), (goal.goal_tolerance, final)):
        for entry in entries:
            if entry.name not in own:
                raise Refused(INVALID_JOINTS, f"{group}: a tolerance names joint {entry.name!r}, not one of the group's ({', '.join(own)})")
            j = own.index(entry.name)
            for value, array in ((entry.position, target.position), (entry.velocity, target.velocity)):
                if not math.isfinite(value):
                    raise Refused(INVALID_GOAL, f"{group}: the tolerance of {entry.name} is {value}")
                if value > 0.0:
                    array[j] = value
                elif value < 0.0:
                    array[j] = math.inf
    if goal.component_path_tolerance or goal.component_goal_tolerance:
        raise Refused(INVALID_GOAL, f"{group}: component tolerances are for multi-DOF joints, which the group has none of")
    goal_time = seconds(goal.goal_time_tolerance)
    if not math.isfinite(goal_time) or goal_time < 0.0:
        raise Refused(INVALID_GOAL, f"{group}: goal_time_tolerance {goal_time:g} s must be 0 or more")
    return path, final, goal_time if goal_time > 0.0 else defaults.goal_time


def point_message(positions: Sequence[float], velocities: Sequence[float] = (), at: float = 0.0) -> Any:
    """A trajectory_msgs/JointTrajectoryPoint of plain floats (feedback and the controller's state)."""
    whole = math.floor(at)
    return JointTrajectoryPoint(
        positions=tuple(float(v) for v in positions), velocities=tuple(float(v) for v in velocities),
        time_from_start=Duration(int(whole), min(999_999_999, int(round((at - whole) * 1e9)))),
    )


#: s added to the first segment of a path continued after a hold, tried in turn until the path keeps to the limits.
RAMPS = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)


def path_time_near(plan: FollowPlan, q: NDArray[np.float64], start: float, stop: float) -> float:
    """The time in [start, stop] at which the path passes closest to ``q`` (where a held arm is on its path);
    the earliest of equally close ones."""
    best, best_t = math.inf, start
    for k in range(len(plan.times) - 1):
        t0, t1 = float(plan.times[k]), float(plan.times[k + 1])
        if t1 < start or t0 > stop:
            continue
        a, b = plan.points[k], plan.points[k + 1]
        span = b - a
        length = float(span @ span)
        s = 0.0 if length == 0.0 else min(1.0, max(0.0, float((q - a) @ span) / length))
        t = min(stop, max(start, t0 + s * (t1 - t0)))
        distance = float(np.linalg.norm(plan.at(t)[0] - q))
        if distance < best:
            best, best_t = distance, t
    return best_t


def continued(plan: FollowPlan, at: float, here: Sequence[float], limits: JointLimits) -> FollowPlan | None:
    """The rest of ``plan`` after path time ``at``, from ``here`` (where the arm stands after a hold): its first
    segment stretched by the shortest of :data:`RAMPS` that keeps the whole to the limits; None when nothing is
    left.  :class:`Refused` when no ramp does (it cannot happen for a path that kept to them before)."""
    later = np.nonzero(plan.times > at + _TIME_EPS)[0]
    start = np.array(here, dtype=float)
    if not len(later) or (len(later) == 1 and float(np.max(np.abs(plan.points[-1] - start))) <= 1e-9):
        return None
    rest_times, rest_points = plan.times[later] - at, plan.points[later]
    last: Refused | None = None
    for ramp in RAMPS:
        times = np.concatenate([[0.0], rest_times + ramp])
        points = np.vstack([start, rest_points])
        try:
            _check_path(plan.group, times, points, limits, 1)
        except Refused as refused:
            last = refused
            continue
        return replace(plan, times=times, points=points, start_delay=0.0)
    assert last is not None
    raise Refused(INVALID_GOAL, f"{plan.group}: the path cannot go on from where the arm was held: {last}")
