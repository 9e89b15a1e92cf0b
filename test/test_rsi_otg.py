"""The online second-order trajectory generator: limits always hold, targets are reached, retargets are smooth."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, rotation_angle
from robot_bridges.kuka_rsi.otg import CartesianOTG, VectorOTG, braking_speed, matrix_to_rotvec, rotvec_to_matrix

DT = 0.004


def _run(otg: VectorOTG, limit: int = 100_000) -> list[np.ndarray]:
    velocities = []
    for _ in range(limit):
        done = otg.step()
        velocities.append(otg.velocity.copy())
        if done:
            return velocities
    raise AssertionError("the generator did not finish")


@pytest.mark.parametrize(("distance", "vmax", "amax"), [(1.0, 2.0, 3.0), (0.01, 2.0, 3.0), (3.0, 0.5, 10.0), (1e-6, 1.0, 1.0)])
def test_from_rest_it_lands_exactly_in_about_the_time_optimal_trapezoid(distance: float, vmax: float, amax: float) -> None:
    otg = VectorOTG([1], DT)
    otg.reset([0.0])
    otg.set_target([distance], vmax, amax)
    cycles = len(_run(otg))
    assert otg.position[0] == distance and otg.velocity[0] == 0.0
    if distance >= vmax**2 / amax:
        optimal = distance / vmax + vmax / amax
    else:
        optimal = 2 * math.sqrt(distance / amax)
    assert optimal / DT - 2 <= cycles <= optimal / DT + 3


def test_braking_speed_stops_exactly_on_the_distance() -> None:
    for distance in (1e-7, 0.3e-4, 1e-3, 0.123, 2.0):
        v, covered = braking_speed(distance, 3.0, DT), 0.0
        while v > 1e-15:
            covered += v * DT
            v = max(0.0, v - 3.0 * DT)
        assert covered == pytest.approx(distance, rel=1e-9, abs=1e-15)


limits = st.tuples(st.floats(0.05, 3.0), st.floats(0.1, 10.0))
targets = st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3)


@given(st.lists(st.tuples(st.integers(1, 400), targets), min_size=1, max_size=5), limits)
def test_retargets_keep_velocity_continuous_and_within_the_limits(plan, lim) -> None:  # type: ignore[no-untyped-def]
    vmax, amax = lim
    otg = VectorOTG([3], DT)
    otg.reset(np.zeros(3))
    # Every cycle's velocity, checked in bulk below (the same bounds on every cycle, without a numpy call per cycle):
    # while retargeting, within vmax and changing by at most amax * DT a cycle; then, to the last target, smooth.
    retargeting = [np.zeros(3)]
    for after_cycles, target in plan:
        otg.set_target(target, vmax, amax)
        for _ in range(after_cycles):
            otg.step()
            retargeting.append(otg.velocity.copy())
    moving = np.array(retargeting)
    assert (np.linalg.norm(moving[1:], axis=1) <= vmax * (1 + 1e-9)).all()
    final = np.array(plan[-1][1])
    landing = [moving[-1]]
    for _ in range(200_000):
        if otg.step():
            break
        landing.append(otg.velocity.copy())
    steps = np.diff(np.concatenate([moving, np.array(landing[1:]).reshape(-1, 3)]), axis=0)
    assert (np.linalg.norm(steps, axis=1) <= amax * DT * (1 + 1e-9)).all()
    assert otg.done and np.array_equal(otg.position, final)


def test_joint_moves_from_rest_are_synchronised_and_respect_each_axis() -> None:
    vmax = np.radians([156, 156, 156, 343, 362, 659])
    otg = VectorOTG([1] * 6, DT)
    start = np.radians([0, -90, 90, 0, 0, 0])
    target = np.radians([90, -30, 20, 180, 45, 300])
    otg.reset(start)
    otg.set_target(target, vmax, np.radians(300))
    positions = []
    while not otg.step():
        positions.append(otg.position.copy())
        assert np.all(np.abs(otg.velocity) <= vmax * (1 + 1e-9))
    # every axis is the same fraction of the way at every cycle: a straight line in joint space
    progress = (np.array(positions) - start) / (target - start)
    assert np.allclose(progress, progress[:, :1], atol=1e-9)


def test_a_linear_cartesian_move_is_a_straight_line_with_a_synchronised_slerp() -> None:
    otg = CartesianOTG(DT)
    p0, r0 = np.array([0.5, 0.0, 0.9]), abc_to_matrix(0.0, math.pi / 2, 0.0)
    p1, r1 = np.array([0.6, 0.2, 0.6]), abc_to_matrix(0.7, 1.2, -0.3)
    otg.reset(p0, r0)
    otg.set_target(p1, r1, (0.5, 2.0, 1.0, 4.0))
    total_turn = rotation_angle(r1 @ r0.T)
    while not otg.step():
        s = np.linalg.norm(otg.position - p0) / np.linalg.norm(p1 - p0)
        assert np.linalg.norm(np.cross(otg.position - p0, p1 - p0)) < 1e-9  # on the line
        assert rotation_angle(otg.rotation @ r0.T) == pytest.approx(s * total_turn, abs=1e-7)  # slerp in step
        assert np.linalg.norm(otg.velocity[:3]) <= 0.5 * (1 + 1e-9) and np.linalg.norm(otg.velocity[3:]) <= 1.0 * (1 + 1e-9)
    assert np.array_equal(otg.position, p1) and np.allclose(otg.rotation, r1)


def test_halt_brakes_at_the_maximum_deceleration_and_stays() -> None:
    otg = VectorOTG([1], DT)
    otg.reset([0.0])
    otg.set_target([10.0], 2.0, 4.0)
    for _ in range(300):
        otg.step()
    speed = otg.velocity[0]
    assert speed == pytest.approx(2.0)
    otg.halt()
    cycles = 0
    while not otg.step():
        cycles += 1
    assert cycles == pytest.approx(speed / (4.0 * DT), abs=1)
    here = otg.position.copy()
    otg.step()
    assert np.array_equal(otg.position, here) and otg.velocity[0] == 0.0


def test_bad_limits_are_refused() -> None:
    otg = VectorOTG([1], DT)
    with pytest.raises(ValueError, match="limits"):
        otg.set_target([1.0], 0.0, 1.0)
    with pytest.raises(ValueError, match="limits"):
        CartesianOTG(DT).set_target([0, 0, 0], np.eye(3), (1.0, math.inf, 1.0, 1.0))


@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), st.floats(0.0, math.pi - 1e-9))
def test_rotation_vectors_round_trip_up_to_a_half_turn(axis, angle) -> None:  # type: ignore[no-untyped-def]
    a = np.array(axis)
    if np.linalg.norm(a) < 1e-3:
        return
    v = a / np.linalg.norm(a) * angle
    back = matrix_to_rotvec(rotvec_to_matrix(v))
    assert np.allclose(rotvec_to_matrix(back), rotvec_to_matrix(v), atol=1e-9)
