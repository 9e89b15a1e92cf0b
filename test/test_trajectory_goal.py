"""What a FollowJointTrajectory goal from anywhere may make a group do (robot_bridges/trajectory_goal.py).

A goal is input from the network: whatever it holds, checking it either refuses it with one of the
action's error codes and a message, or gives a plan that keeps to the group's limits -- every point in
range, every straight segment within every joint's speed, every change of speed within its acceleration,
starting where the arm is.  Never another exception.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from fjt_client import FJT, Duration, Header, Point, Time
from fjt_client import JointTolerance as Tolerance
from fjt_client import JointTrajectory as Trajectory
from hypothesis import strategies as st

from robot_bridges.backend import JointLimits
from robot_bridges.trajectory_goal import (
    INVALID_GOAL,
    INVALID_JOINTS,
    OLD_HEADER_TIMESTAMP,
    START_TOLERANCE,
    FollowPlan,
    Refused,
    continued,
    path_time_near,
    plan_goal,
)

NAMES = ("j1", "j2", "j3")
LIMITS = JointLimits(NAMES, (-1.0, -2.0, 0.0), (1.0, 2.0, 3.0), (1.0, 0.5, 2.0), (2.0, 1.0, 4.0))
HERE = (0.0, 0.5, 1.0)
NOW = 1_700_000_000.0

values = st.one_of(st.floats(-5, 5), st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 1e308]))
names = st.lists(st.sampled_from([*NAMES, "j4", "", "J1"]), min_size=0, max_size=4)


@st.composite
def goals(draw: Any) -> Any:
    joints = tuple(draw(names))
    count = draw(st.integers(0, 5))
    points = []
    for _ in range(count):
        width = draw(st.sampled_from([len(joints), len(joints), 0, len(joints) + 1]))
        points.append(Point(
            positions=tuple(draw(values) for _ in range(width)),
            velocities=tuple(draw(values) for _ in range(draw(st.sampled_from([0, 0, len(joints), 1])))),
            accelerations=tuple(draw(values) for _ in range(draw(st.sampled_from([0, 0, len(joints)])))),
            effort=tuple(draw(values) for _ in range(draw(st.sampled_from([0, 0, 0, 1])))),
            time_from_start=Duration(draw(st.integers(-2, 20)), draw(st.integers(0, 999_999_999))),
        ))
    stamp = draw(st.sampled_from([Time(0, 0), Time(int(NOW) - 100, 0), Time(int(NOW) + 5, 0), Time(int(NOW) + 1000, 0)]))
    tolerances = tuple(Tolerance(name=draw(st.sampled_from([*NAMES, "jx"])), position=draw(values), velocity=draw(values))
                       for _ in range(draw(st.integers(0, 2))))
    return FJT.Goal(trajectory=Trajectory(header=Header(stamp=stamp), joint_names=joints, points=tuple(points)), path_tolerance=tolerances)


@settings(max_examples=400)
@given(goals())
def test_any_goal_is_refused_with_a_code_or_planned_within_the_limits(goal: Any) -> None:
    try:
        plan = plan_goal("arm", goal, LIMITS, HERE, NOW)
    except Refused as refused:
        assert refused.code in (INVALID_GOAL, INVALID_JOINTS, OLD_HEADER_TIMESTAMP) and str(refused).startswith("arm: ")
        return
    within_limits(plan, HERE)
    assert 0.0 <= plan.start_delay <= 60.0


@settings(max_examples=200)
@given(st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(0.5, 2.5)), min_size=1, max_size=4),
       st.floats(0.0, 1.0), st.lists(st.floats(-0.003, 0.003), min_size=3, max_size=3))
def test_a_held_path_goes_on_from_where_the_arm_stands_within_the_limits(
    points: list[tuple[float, float, float]], fraction: float, off: list[float],
) -> None:
    """However a path was held (anywhere on it, the arm a few mrad off its line, as a braking axis leaves it),
    its rest starts where the arm stands and keeps to every limit, or nothing is left."""
    spaced = tuple(Point(positions=p, time_from_start=Duration(4 * (k + 1), 0)) for k, p in enumerate(points))
    plan = plan_goal("arm", FJT.Goal(trajectory=Trajectory(joint_names=NAMES, points=spaced)), LIMITS, HERE, NOW)
    at = fraction * plan.duration
    here = np.clip(plan.at(at)[0] + np.array(off), LIMITS.lower, LIMITS.upper)
    found = path_time_near(plan, here, max(0.0, at - 0.25), min(plan.duration, at + 1.0))
    assert at - 0.25 - 1e-9 <= found <= at + 1.0 + 1e-9
    assert np.linalg.norm(plan.at(found)[0] - here) <= np.linalg.norm(plan.at(at)[0] - here) + 1e-9  # the nearest
    rest = continued(plan, found, tuple(here), LIMITS)
    if rest is None:
        assert found >= plan.times[-1] - 1e-6 or np.max(np.abs(plan.points[-1] - here)) <= 1e-9
        return
    within_limits(rest, tuple(here))
    np.testing.assert_allclose(rest.points[-1], plan.points[-1])


def within_limits(plan: FollowPlan, start: tuple[float, ...]) -> None:
    lower, upper = np.array(LIMITS.lower), np.array(LIMITS.upper)
    vmax, amax = np.array(LIMITS.velocity), np.array(LIMITS.acceleration)
    assert np.all(np.isfinite(plan.points)) and np.all(plan.points >= lower - 1e-9) and np.all(plan.points <= upper + 1e-9)
    assert plan.times[0] == 0.0 and np.all(np.diff(plan.times) > 0) and np.allclose(plan.points[0], start, atol=START_TOLERANCE)
    rates = np.diff(plan.points, axis=0) / np.diff(plan.times)[:, None]
    assert np.all(np.abs(rates) <= vmax * (1 + 1e-6))
    speeds = np.vstack([np.zeros((1, 3)), rates, np.zeros((1, 3))])
    spans = np.concatenate([[0.0], np.diff(plan.times), [0.0]])
    assert np.all(np.abs(np.diff(speeds, axis=0)) <= amax * (1 + 1e-6) * ((spans[:-1] + spans[1:]) / 2)[:, None] + 1e-12)


def test_a_good_goal_plans_from_where_the_arm_is_and_leaves_out_joints_where_they_are() -> None:
    goal = FJT.Goal(trajectory=Trajectory(joint_names=("j3", "j1"), points=(
        Point(positions=(1.5, 0.25), time_from_start=Duration(1, 0)), Point(positions=(2.0, 0.5), time_from_start=Duration(2, 0)),
    )))
    plan = plan_goal("arm", goal, LIMITS, HERE, NOW)
    assert plan.times.tolist() == [0.0, 1.0, 2.0]
    assert plan.points.tolist() == [[0.0, 0.5, 1.0], [0.25, 0.5, 1.5], [0.5, 0.5, 2.0]]
    position, velocity = plan.at(1.5)
    assert position.tolist() == [0.375, 0.5, 1.75] and velocity.tolist() == [0.25, 0.0, 0.5]


@pytest.mark.parametrize(("change", "code", "words"), [
    (dict(joint_names=("j1", "j1")), INVALID_JOINTS, "joint 'j1' is named 2 times"),
    (dict(positions=(0.2, 2.5)), INVALID_GOAL, "j2 at 2.5000 rad is outside its limits [-2.0000, 2.0000] rad"),
    (dict(positions=(0.9, 0.5), seconds=0), INVALID_GOAL, "point 0 is at time 0 but j1 is at 0.0000 rad, not 0.9000 rad"),
    (dict(positions=(0.45, 0.5), seconds=0.5), INVALID_GOAL, "j1 would change speed by 0.9000 rad/s within 0.25 s at 0 s (3.6000 rad/s^2)"),
    (dict(positions=(0.6, 0.5), seconds=0.5), INVALID_GOAL, "j1 would move at 1.2000 rad/s from where the arm is to point 0 (0..0.5 s), above its limit"),
    (dict(velocities=(0.1, 0.0)), INVALID_GOAL, "the last point (point 0) must be at rest, but j1 moves at 0.1 rad/s there"),
])
def test_refusals_name_the_joint_and_the_point(change: dict[str, Any], code: int, words: str) -> None:
    point = Point(positions=change.get("positions", (0.1, 0.5)), velocities=change.get("velocities", ()),
                  time_from_start=Duration(int(change.get("seconds", 2)), int(change.get("seconds", 2) % 1 * 1e9)))
    goal = FJT.Goal(trajectory=Trajectory(joint_names=change.get("joint_names", ("j1", "j2")), points=(point,)))
    with pytest.raises(Refused) as refused:
        plan_goal("arm", goal, LIMITS, HERE, NOW)
    assert refused.value.code == code and words in str(refused.value)
