"""The path rate under any sequence of speed overrides: every joint stays within its acceleration limit, the rate
within [0, 1], the motion on its path and never going back along it, and it reaches the same end (property test)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot_bridges.nextage_sim.trajectory import plan_joint_move
from robot_bridges.path_rate import MAX_RATE_CHANGE, PathRate, fraction, rate_change_bounds, sampled_shape

DT = 0.002  # s per step: the acceleration from the positions is then the generator's, not the sampling's
VELOCITY = np.array([1.0, 0.5, 1.5])
ACCELERATION = np.array([1.5, 1.5, 3.0])

changes = st.lists(st.tuples(st.floats(0.0, 4.0), st.sampled_from([0.0, 0.1, 0.25, 0.5, 0.75, 1.0])), max_size=5)


@settings(max_examples=40, deadline=None)
@given(goal=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3), speed=st.sampled_from([0.3, 1.0]), overrides=changes)
def test_any_override_sequence_keeps_every_joint_within_its_limits_on_its_path(goal: list[float], speed: float,
                                                                                overrides: list[tuple[float, float]]) -> None:
    motion = plan_joint_move(np.arange(3), np.zeros(3), np.array(goal), VELOCITY, ACCELERATION, speed)
    shape = sampled_shape(motion.at, motion.duration)
    rate = PathRate()
    pending = sorted(overrides) + [(5.0, 1.0)]  # raised again in the end, so every motion ends
    tau, t, taus = 0.0, 0.0, [0.0]
    while tau < motion.duration - 1e-9:
        while pending and pending[0][0] <= t:
            rate.aim(pending.pop(0)[1])
        tau = min(motion.duration, tau + rate.advance(DT, tau, shape, ACCELERATION))
        t += DT
        taus.append(tau)
        assert 0.0 <= rate.rate <= 1.0
        assert t < 200.0, "the motion never ended"
    q = np.array([motion.at(x) for x in taus])
    v = np.diff(q, axis=0) / DT
    a = np.diff(v, axis=0) / DT
    assert np.all(np.abs(v) <= VELOCITY * speed * (1 + 1e-3) + 1e-9)  # never faster than the plan, itself within the limits
    assert np.all(np.abs(a) <= ACCELERATION * (1 + 0.05) + 0.05), np.abs(a).max(axis=0)  # the discretisation's slack
    assert np.all(np.diff(taus) >= 0.0)  # never back along the path
    assert q[-1] == pytest.approx(np.array(goal), abs=1e-9)


def test_zero_is_always_allowed_and_a_share_out_of_range_is_refused() -> None:
    low, high = rate_change_bounds(np.array([1.0, -0.5]), np.array([1.5, 0.0]), np.array([1.5, 1.5]), 1.0)
    assert low <= 0.0 <= high and low == pytest.approx(-3.0)  # braking: (-1.5 - 1.5) / 1.0; speeding up: nothing left
    assert fraction(50) == 0.5
    for bad in (-1, 101, float("nan"), "50"):
        with pytest.raises(ValueError, match=r"\[0, 100\]"):
            fraction(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        PathRate().aim(1.2)
    assert MAX_RATE_CHANGE == 2.0
