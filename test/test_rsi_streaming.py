"""Tool paths for streaming: what is refused before a point is sent, how a trajectory becomes one
point per cycle, and how a stream re-enters its path after the controller held still."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot_bridges.kuka_rsi.link import RobotLink
from robot_bridges.kuka_rsi.replay import resample
from robot_bridges.kuka_rsi.streaming import StreamCursor, ToolPathError, check_tool_path, parse_tool_path, ramp_rate

LINK = RobotLink("kr", "127.0.0.1")
DT = 0.004
ACCEL = np.array(LINK.max_joint_accel)
SPEED = np.array(LINK.max_joint_speed)
BUDGET = ACCEL * DT * DT  # rad: how much a step may change per cycle


def _check(text: str) -> None:
    check_tool_path(parse_tool_path(text, "joint", "p.txt"), DT, max_joint_speed=np.array(LINK.max_joint_speed), max_joint_accel=ACCEL)


def test_a_path_that_changes_speed_in_one_cycle_is_refused_at_its_line() -> None:
    with pytest.raises(ToolPathError, match=r"p.txt:3: the step out of this point changes by 0\.2900 deg on an axis"):
        _check("0 0 0 0 0 0\n0.01 0 0 0 0 0\n0.02 0 0 0 0 0\n0.32 0 0 0 0 0\n0.32 0 0 0 0 0\n")


def test_a_path_that_ends_at_speed_is_refused() -> None:
    with pytest.raises(ToolPathError, match=r"p.txt:3: the robot must come to rest at the last point"):
        _check("0 0 0 0 0 0\n0.02 0 0 0 0 0\n0.05 0 0 0 0 0\n")  # 0.03 deg a cycle; A1 stops from 0.025
    _check("0 0 0 0 0 0\n0.02 0 0 0 0 0\n0.03 0 0 0 0 0\n0.03 0 0 0 0 0\n")


def test_a_trajectory_is_replayed_on_its_chords_from_rest_to_rest_within_the_axes() -> None:
    """Every set point lies on a chord between two samples (what a recording's tolerance is about);
    straight lines between the points at their own speeds would change speed in one cycle at every
    point, so the timing is smoothed -- and where the path turns a corner at speed, slowed there."""
    times = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    points = np.zeros((5, 6))
    points[:, 0] = [0.0, 0.075, 0.15, 0.225, 0.3]  # constant speed, as a sampled cruise
    points[:, 4] = [0.0, 0.2, 0.2, 0.1, 0.1]  # corners at speed: a plateau and a step back
    out = resample(times, points, DT, SPEED, ACCEL)
    assert len(out) > 251 and np.allclose(out[0], points[0]) and np.allclose(out[-1], points[-1])
    for q in out:  # on the polygon of the samples: within one chord's box, on its line
        k = min(3, int(np.searchsorted(points[:, 0], q[0], side="right")) - 1)
        a, b = points[k], points[k + 1]
        w = (q[0] - a[0]) / (b[0] - a[0])
        assert np.allclose(q, a + w * (b - a), atol=1e-12)
    steps = np.diff(out, axis=0)
    assert np.all(np.abs(steps[[0, -1]]) <= BUDGET)  # leaves and reaches rest
    assert np.all(np.abs(np.diff(steps, axis=0)) <= BUDGET * (1 + 1e-9))
    check_tool_path(parse_tool_path("\n".join(" ".join(str(math.degrees(v)) for v in p) for p in out), "joint"), DT, max_joint_accel=ACCEL)
    straight = resample(times, np.outer(times, np.full(6, 0.3)), DT, SPEED, ACCEL)
    assert len(straight) == 251  # no corner: the recorded times exactly
    with pytest.raises(ValueError, match="increase strictly"):
        resample(np.array([0.0, 0.5, 0.5]), points[:3], DT, SPEED, ACCEL)


@given(st.integers(min_value=0, max_value=10_000), st.floats(min_value=0.05, max_value=0.95))
def test_a_stream_re_enters_its_path_from_rest_within_the_acceleration(seed: int, where: float) -> None:
    rng = np.random.default_rng(seed)
    n = 300
    s = np.linspace(0.0, 1.0, n)
    profile = 3 * s**2 - 2 * s**3
    points = np.outer(profile, rng.uniform(-0.3, 0.3, 6))  # from rest to rest, within the budget
    cursor = StreamCursor(points, ramp_rate(points, BUDGET))
    cursor.hold(where * (n - 1), 0.0)  # the controller held still here
    positions = [cursor.at(cursor.position), cursor.at(cursor.position)]
    while not cursor.done:
        positions.append(cursor.advance())
    steps = np.diff(np.array(positions), axis=0)
    assert np.all(np.abs(np.diff(steps, axis=0)) <= BUDGET * (1 + 1e-9))
    assert np.allclose(positions[-1], points[-1])
