"""The speed override on a ros2_control robot: FollowJointTrajectory cannot scale a running trajectory, so a change
cancels the goal and the rest of the path goes again from where the arm came to rest, timed at the new share of
the speed (docs/ros2.md).  Measured from the joint states of the joint_trajectory_controller stand-in
(fake_fjt_server.py) on simulated time: after the change the arm moves at half the speed, on the same joint line,
within the URDF's limits; 0 % leaves it standing on its path with no goal until the override is raised."""
from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from fake_fjt_server import moved_too_fast, urdf_limits
from test_ros2_control import URDF, robot

from core_functions.primitives import MoveJoints
from core_functions.robots import KUKA_KR
from node_transport.clock import Clock
from speed_override_checks import Samples, distance_to_path, sample

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
JOINTS = KUKA_KR.group("arm").joint_names
START = np.array([KUKA_KR.poses["home"][j] for j in JOINTS])
TARGET = START + np.radians([150.0, 0, 0, 0, 0, 0])


async def overridden(clock: Clock, changes: dict[float, float]) -> tuple[Any, Any, Samples]:
    graph, driver, backend = await robot(clock)
    try:
        actions = {at: (lambda rate=rate: backend.set_speed_override(rate)) for at, rate in changes.items()}
        probe = lambda: np.array([driver.positions[j] for j in JOINTS])  # noqa: E731 - the controller's joints
        result, samples = await sample(clock, backend.execute("arm", MoveJoints(tuple(TARGET))), probe, 0.02, actions, 0.005)
        return driver, result, samples
    finally:
        await driver.close()
        await graph.shutdown()


def peak(samples: Samples) -> float:
    """A1's highest speed over two samples (the stand-in steps its positions every other sample)."""
    return float(np.max(np.abs(samples.q[2:, 0] - samples.q[:-2, 0]) / (samples.t[2:] - samples.t[:-2])))


def test_half_speed_cancels_and_the_rest_goes_on_from_where_the_arm_stands_at_half_the_speed(run_sim: Run) -> None:
    driver, result, samples = run_sim(lambda clock: overridden(clock, {0.8: 0.5}))
    first, second = driver.goals
    assert first.outcome == "canceled" and second.outcome == "succeeded"
    speed_first = float(np.max(np.abs(np.diff(first.points, axis=0)[:, 0]) / np.diff(first.times)))
    speed_second = float(np.max(np.abs(np.diff(second.points, axis=0)[:, 0]) / np.diff(second.times)))
    assert speed_second == pytest.approx(0.5 * speed_first, rel=0.02)  # the rest, timed at half the speed
    peak_before, peak_after = peak(samples.window(0.0, 0.8)), peak(samples.window(1.0, samples.t[-1]))  # from the joint states
    assert peak_before == pytest.approx(speed_first, rel=0.02) and peak_after == pytest.approx(0.5 * peak_before, rel=0.03)
    assert distance_to_path(samples.q, np.array([START, TARGET])) < 1e-9  # the same joint line
    assert moved_too_fast(first, urdf_limits(URDF)) == [] and moved_too_fast(second, urdf_limits(URDF)) == []
    np.testing.assert_allclose(result.positions, TARGET, atol=0.01)


def test_zero_holds_the_arm_on_its_path_with_no_goal_until_the_override_is_raised(run_sim: Run) -> None:
    driver, result, samples = run_sim(lambda clock: overridden(clock, {0.8: 0.0, 3.0: 1.0}))
    first, second = driver.goals
    held = samples.window(1.2, 3.0)
    assert first.outcome == "canceled" and np.ptp(held.q[:, 0]) < 1e-9 and START[0] < held.q[0, 0] < TARGET[0]
    np.testing.assert_allclose(second.points[0], held.q[-1], atol=1e-9)  # the rest from where it stood
    assert distance_to_path(samples.q, np.array([START, TARGET])) < 1e-9
    np.testing.assert_allclose(result.positions, TARGET, atol=0.01)
    assert moved_too_fast(second, urdf_limits(URDF)) == []
