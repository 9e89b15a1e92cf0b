"""The shared line sampling (core_functions.linear_path) and profile timing (core_functions.motion_profile).

The end-to-end guarantee -- a replayed linear recording stays on its line -- is tested per back
end in test_linear_recording.py; here are the pieces a back end (KUKA RSI's included) builds on.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from line_measure import LineMeasure

from core_functions.geometry import Pose
from core_functions.linear_path import LineSamplingError, LineTolerance, NoSolution, SamplingBounds, StraightLine, sample_line
from core_functions.motion_profile import Trapezoid, sample_times
from robot_bridges.vplus.kinematics import IKError, ViperKinematics

KIN = ViperKinematics()
READY = np.radians([0.0, -60.0, 150.0, 0.0, 60.0, 0.0])
unit = st.floats(-1.0, 1.0)


def pose_from(values: list[float]) -> Pose:
    x, y, z, r, p, w = values
    return Pose.from_xyz_rpy(x, y, z, 2 * r, p, 2 * w)


def viper_forward(q: np.ndarray) -> Pose:
    return Pose.from_matrix(KIN.forward(q))


def viper_solve(target: Pose, seed: np.ndarray) -> np.ndarray:
    try:
        return KIN.inverse(target.matrix(), seed)
    except IKError as error:
        raise NoSolution(str(error)) from None


@settings(max_examples=60, deadline=None)
@given(st.lists(unit, min_size=6, max_size=6), st.lists(unit, min_size=6, max_size=6), st.lists(st.floats(-0.002, 0.002), min_size=6, max_size=6), st.floats(0.0, 1.0))
def test_the_deviation_is_the_distance_to_the_nearest_pose_of_the_line_in_tolerance_units(
    a: list[float], b: list[float], nudge: list[float], s: float
) -> None:
    """What "within 0.1 mm and 0.1 deg of the line" means, against a brute-force search."""
    start, end = pose_from(a), pose_from(b)
    line = StraightLine(start, end)
    on_line = line.at(s)
    turned = on_line.compose(Pose.from_xyz_rpy(0.0, 0.0, 0.0, *nudge[3:]))
    pose = Pose(on_line.x + nudge[0], on_line.y + nudge[1], on_line.z + nudge[2], *turned.quaternion)
    tolerance = LineTolerance(1e-4, math.radians(0.1))
    found = line.deviation(pose, tolerance)
    ratio, _, _ = LineMeasure(start, end, tolerance.position, tolerance.orientation).nearest(pose)
    assert found.ratio == pytest.approx(ratio, rel=1e-3, abs=1e-3)
    assert line.at(found.fraction).distance_to(pose) == pytest.approx(found.position, abs=1e-9)
    assert line.deviation(line.at(s), tolerance).ratio < 1e-3  # every pose of the line is on it


def test_a_sampled_line_is_a_chain_of_chords_within_tolerance_and_no_denser_than_it_needs() -> None:
    start_q = READY.copy()
    start = viper_forward(start_q)
    end = Pose.from_matrix(KIN.forward(start_q + np.array([0.3, 0.3, -0.3, 0.3, -0.3, 0.3])))
    line = StraightLine(start, end)
    tight = sample_line(line, start_q, viper_solve, viper_forward, LineTolerance(1e-5, math.radians(0.01)))
    loose = sample_line(line, start_q, viper_solve, viper_forward, LineTolerance(1e-3, math.radians(1.0)))
    assert len(loose.fractions) < len(tight.fractions)
    assert tight.fractions[0] == 0.0 and tight.fractions[-1] == 1.0 and np.all(np.diff(tight.fractions) > 0)
    measure = LineMeasure(start, end, 1e-5, math.radians(0.01))
    chords = [viper_forward(qa + (qb - qa) * u) for qa, qb in zip(tight.joints, tight.joints[1:]) for u in np.linspace(0, 1, 11)]
    assert measure.worst(chords).ratio <= 1.0


def test_sampling_is_bounded_and_says_where_it_gave_up() -> None:
    start = viper_forward(READY)
    end = start.translated(0.2, 0.1, -0.1)
    line = StraightLine(start, end)
    with pytest.raises(LineSamplingError, match="more than 5 samples") as many:
        sample_line(line, READY, viper_solve, viper_forward, LineTolerance(1e-6, math.radians(0.001)), SamplingBounds(max_samples=5))
    assert 0.0 <= many.value.fraction < 1.0

    axis = np.array(end.position) - np.array(start.position)

    def walled(target: Pose, seed: np.ndarray) -> np.ndarray:  # a workspace ending 37 % along the line
        if float((np.array(target.position) - np.array(start.position)) @ axis) / float(axis @ axis) > 0.37:
            raise NoSolution("behind the wall")
        return viper_solve(target, seed)

    with pytest.raises(LineSamplingError, match="leaves the reachable workspace") as wall:
        sample_line(line, READY, walled, viper_forward)
    first_step = SamplingBounds().step / line.length
    assert 0.37 < wall.value.fraction <= 0.37 + first_step / 2 ** SamplingBounds().locate + 1e-9
    assert "behind the wall" in str(wall.value)


@given(st.floats(0.05, 5.0), st.floats(0.05, 5.0), st.floats(0.0, 1.0))
def test_the_profile_names_the_instant_each_sample_is_reached(v: float, a: float, s: float) -> None:
    profile = Trapezoid.fit(v, a)
    assert profile.position(profile.time_at(s)) == pytest.approx(s, abs=1e-9)


def test_recorded_instants_keep_every_corner_of_the_path_and_the_period() -> None:
    times = sample_times(1.0, 0.25, [0.1, 0.5 + 1e-8, 0.5 + 2e-8, 0.9999999, 0.3])
    assert 0.1 in times and 0.3 in times  # corners kept
    assert np.any(np.abs(times - 0.5) < 1e-7) and np.sum(np.abs(times - 0.5) < 1e-6) == 1  # near-duplicates merged
    assert times[0] == 0.0 and times[-1] == 1.0 and np.max(np.diff(times)) <= 0.25
    assert np.min(np.diff(times)) > 1e-6
