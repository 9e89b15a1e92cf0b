"""Timing and path planning of the Nextage simulator: trapezoids, synchronised joint moves,
Cartesian-linear paths and trajectory replay (no clock involved: motions are functions of time)."""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core_functions.geometry import Pose
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.model import NextageModel
from robot_bridges.nextage_sim.trajectory import (
    CartesianLimits,
    Motion,
    Trapezoid,
    interpolate_pose,
    plan_joint_move,
    plan_linear,
    plan_replay,
    sample,
    straight_leg,
)

MODEL = NextageModel()
LEFT = MODEL.arms["left_arm"]


def _solver(q_full: np.ndarray) -> Callable[[Pose, np.ndarray], np.ndarray]:
    base = q_full.copy()

    def solve(target: Pose, seed: np.ndarray) -> np.ndarray:
        base[LEFT.indices] = seed
        return LEFT.solve(target, base, restarts=False).positions

    return solve


def _derivative(motion: Motion, step: float = 1e-3) -> np.ndarray:
    times = np.arange(0.0, motion.duration + step, step)
    positions = np.array([motion.at(float(t)) for t in times])
    return np.diff(positions, axis=0) / step


@given(st.floats(0.05, 5.0), st.floats(0.05, 5.0))
def test_trapezoid_reaches_one_within_its_bounds(v: float, a: float) -> None:
    profile = Trapezoid.fit(v, a)
    times = np.linspace(0.0, profile.duration, 400)
    s = np.array([profile.position(float(t)) for t in times])
    assert s[0] == 0.0 and s[-1] == 1.0
    assert np.all(np.diff(s) >= -1e-12)
    speeds = np.diff(s) / np.diff(times)
    assert speeds.max() <= v * (1 + 1e-6)
    # the fastest profile: either cruising at v or accelerating all the way to half distance
    assert profile.velocity == pytest.approx(v) or profile.ramp == pytest.approx(math.sqrt(1 / a))


def test_trapezoid_known_durations() -> None:
    assert Trapezoid.fit(0.5, 1.0).duration == pytest.approx(2.5)  # 0.5 s ramps, 1.5 s at 0.5/s
    assert Trapezoid.fit(2.0, 1.0).duration == pytest.approx(2.0)  # triangle: 1 s up, 1 s down


@given(
    st.lists(st.floats(-1.5, 1.5), min_size=6, max_size=6),
    st.floats(0.05, 1.0),
)
def test_joint_move_is_synchronised_and_scaled_by_the_speed_fraction(delta: list[float], speed: float) -> None:
    idx = LEFT.indices
    start = MODEL.named_pose("initial")[idx]
    goal = start + np.array(delta)
    velocity, acceleration = MODEL.velocity[idx], MODEL.acceleration[idx]
    full = plan_joint_move(idx, start, goal, velocity, acceleration, 1.0)
    slow = plan_joint_move(idx, start, goal, velocity, acceleration, speed)
    if full.duration == 0.0:
        return
    assert slow.duration == pytest.approx(full.duration / speed, rel=1e-9)
    # every joint is the same fraction of the way at every instant: they start and stop together
    moving = np.abs(goal - start) > 1e-3  # (tiny moves would only measure rounding)
    for t in np.linspace(0.0, slow.duration, 7):
        fraction = (slow.at(float(t)) - start)[moving] / (goal - start)[moving]
        assert fraction.size == 0 or np.ptp(fraction) < 1e-9
    rates = np.abs(_derivative(slow, step=slow.duration / 500))
    assert np.all(rates.max(axis=0) <= velocity * speed * (1 + 1e-3))
    np.testing.assert_allclose(slow.end, goal)


def test_joint_move_duration_follows_the_limiting_joint() -> None:
    idx = MODEL.indices(["LARM_JOINT0", "LARM_JOINT1"])
    start = np.zeros(2)
    motion = plan_joint_move(idx, start, np.array([1.0, 0.3]), np.array([1.0, 1.0]), np.array([1.5, 1.5]), 1.0)
    assert motion.duration == pytest.approx(1.0 / 1.0 + 1.0 / 1.5)  # d/v + v/a of the 1 rad joint


def test_linear_path_stays_on_the_line_and_within_joint_speeds() -> None:
    q = MODEL.named_pose("initial")
    start = LEFT.tcp_pose(q)
    end = Pose.from_xyz_rpy(start.x + 0.1, start.y - 0.12, start.z + 0.08, *start.rpy()).compose(
        Pose.from_xyz_rpy(0, 0, 0, 0.2, 0.0, 0.0)
    )
    leg = straight_leg("left_arm", q[LEFT.indices], start, end, _solver(q), LEFT.joint_names)
    velocity, acceleration = MODEL.velocity[LEFT.indices], MODEL.acceleration[LEFT.indices]
    motion = plan_linear(LEFT.indices, [leg], velocity, acceleration, CartesianLimits(), 1.0)
    p0, p1 = np.array(start.position), np.array(end.position)
    axis = (p1 - p0) / np.linalg.norm(p1 - p0)
    for t in np.linspace(0.0, motion.duration, 101):
        q[LEFT.indices] = motion.at(float(t))
        tcp = LEFT.tcp_pose(q)
        offset = np.array(tcp.position) - p0
        off_line = np.linalg.norm(offset - (offset @ axis) * axis)
        assert off_line < 2e-4
        s = float(offset @ axis) / float(np.linalg.norm(p1 - p0))
        assert tcp.angle_to(interpolate_pose(start, end, min(max(s, 0.0), 1.0))) < math.radians(0.1)
    assert LEFT.tcp_pose(q).distance_to(end) < 1e-4
    rates = np.abs(_derivative(motion, step=0.002))
    assert np.all(rates.max(axis=0) <= velocity * (1 + 1e-3))
    # the TCP is not faster than the Cartesian limit
    assert np.linalg.norm(p1 - p0) / motion.duration < CartesianLimits().linear_velocity


def test_linear_path_out_of_reach_is_unreachable_and_says_where() -> None:
    q = MODEL.named_pose("initial")
    start = LEFT.tcp_pose(q)
    end = start.translated(0.6, 0.0, 0.0)
    leg = straight_leg("left_arm", q[LEFT.indices], start, end, _solver(q), LEFT.joint_names)
    with pytest.raises(BridgeError) as info:
        plan_linear(LEFT.indices, [leg], MODEL.velocity[LEFT.indices], MODEL.acceleration[LEFT.indices], CartesianLimits(), 1.0)
    assert info.value.kind is FaultKind.UNREACHABLE
    assert "left_arm" in str(info.value) and "% of the path" in str(info.value)


def test_linear_path_refuses_a_joint_space_jump() -> None:
    """A 'solver' that flips branch half-way is caught by the continuity check."""
    q = MODEL.named_pose("initial")
    start = LEFT.tcp_pose(q)
    end = start.translated(0.0, 0.0, 0.05)
    real = _solver(q)

    def flipping(target: Pose, seed: np.ndarray) -> np.ndarray:
        solution = real(target, seed)
        if target.z > start.z + 0.025:
            solution = solution.copy()
            solution[3] += 1.0  # another configuration for the same pose (pretend)
        return solution

    leg = straight_leg("left_arm", q[LEFT.indices], start, end, flipping, LEFT.joint_names)
    with pytest.raises(BridgeError) as info:
        plan_linear(LEFT.indices, [leg], MODEL.velocity[LEFT.indices], MODEL.acceleration[LEFT.indices], CartesianLimits(), 1.0)
    assert info.value.kind is FaultKind.UNREACHABLE
    assert "LARM_JOINT3 would jump" in str(info.value)


def test_replay_scales_times_and_approaches_the_first_point() -> None:
    idx = MODEL.indices(["LARM_JOINT0"])
    names = ("LARM_JOINT0",)
    times = np.array([0.0, 1.0, 2.0])
    points = np.array([[0.2], [0.4], [0.6]])
    motion = plan_replay(idx, names, np.array([0.2]), times, points, np.array([1.0]), np.array([1.5]), 0.5)
    assert motion.duration == pytest.approx(4.0)
    assert motion.at(2.0)[0] == pytest.approx(0.4)
    approach = plan_replay(idx, names, np.array([0.0]), times, points, np.array([1.0]), np.array([1.5]), 1.0)
    assert approach.at(0.0)[0] == pytest.approx(0.0) and approach.end[0] == pytest.approx(0.6)
    assert approach.duration > 2.0


def test_replay_faster_than_the_joint_can_go_is_a_joint_limit_error() -> None:
    idx = MODEL.indices(["LARM_JOINT0"])
    with pytest.raises(BridgeError) as info:
        plan_replay(idx, ("LARM_JOINT0",), np.zeros(1), np.array([0.0, 0.1]), np.array([[0.0], [0.5]]), np.ones(1), np.ones(1), 1.0)
    assert info.value.kind is FaultKind.JOINT_LIMIT
    assert "LARM_JOINT0 would move at 5.000 rad/s" in str(info.value)


def test_sampling_includes_the_exact_end() -> None:
    idx = LEFT.indices
    start = MODEL.named_pose("initial")[idx]
    motion = plan_joint_move(idx, start, start + 0.3, MODEL.velocity[idx], MODEL.acceleration[idx], 1.0)
    times, points = sample(motion, 0.1)
    assert times[0] == 0.0 and times[-1] == pytest.approx(motion.duration)
    assert np.all(np.diff(times) <= 0.1 + 1e-12)
    np.testing.assert_allclose(points[-1], start + 0.3)
