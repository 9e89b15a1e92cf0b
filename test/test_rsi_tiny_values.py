"""KUKA RSI: every cycle's correction is a number, whatever finite target the loop is given.

A joint move to READY plus 1e-300 rad on A1 stopped RSI: the other axes landed exactly while A1
kept a subnormal remainder, the generator's ``1 / size`` overflowed to inf, ``0 * inf`` made the
set point NaN, the simulated KR C4 refused every reply as malformed and stopped after 100 late
packets.  Here the generator is measured for such remainders and for huge errors, the move is
replayed packet for packet (the :class:`Bench` of test_rsi_limiter: no sockets, no clock), and a
NaN injected into the generator is shown never to reach a reply.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from test_rsi_limiter import AMAX, DT, LINK, READY, VMAX, Bench

from core_functions.geometry import Pose
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.otg import GroupNorm, braking_speed, next_velocity
from robot_bridges.kuka_rsi.slots import CommandKind

#: The failing example of test_rsi_linear_recording: A1's offset is 1e-300 rad.
TINY_OFFSET = (-5.804531882152867e-300, 0.2698048978668572, 0.15, 0.0, -0.20300858567564029, 0.2956864655483475)
JOINTS = GroupNorm([1] * 6)
POSE = GroupNorm((3, 3))

finite = st.floats(allow_nan=False, allow_infinity=False)  # subnormals included
speeds = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6)


def test_a_subnormal_remainder_on_one_axis_gives_a_finite_step_no_bigger_than_the_remainder() -> None:
    """The cycle that broke: A1 6.6e-316 rad from its target, the other axes on theirs, still
    braking; the law asks for no more than what stays, not for ``error * inf``."""
    error = np.array([6.63123685e-316, 0.0, 0.0, 0.0, 0.0, 0.0])
    velocity = np.array([-5.66621566e-304, 2.63375716e-05, 1.46425649e-05, 0.0, -1.98171093e-05, 2.88640551e-05])
    amax = np.full(6, 6.0)
    got = next_velocity(error, velocity, VMAX, amax, DT, JOINTS)
    at_rest = next_velocity(np.zeros(6), velocity, VMAX, amax, DT, JOINTS)
    assert np.all(np.isfinite(got))
    assert np.array_equal(got[1:], at_rest[1:])  # the landed axes brake as they would with no error at all
    assert abs(got[0]) * DT <= 1e-300  # A1's wanted step is sub-picometre: nothing a robot could move


@given(st.lists(finite, min_size=6, max_size=6), speeds)
@example([6.63123685e-316, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0] * 6)
@example([5e-324, -5e-324, 0.0, 0.0, 0.0, 0.0], [0.0] * 6)
@example([1.7e308, -1.7e308, 1e-310, 0.0, 0.0, 0.0], [0.0] * 6)
def test_any_finite_joint_error_gives_a_finite_velocity_within_the_limits(error: list[float], velocity: list[float]) -> None:
    v0 = np.array(velocity) * VMAX
    got = next_velocity(np.array(error), v0, VMAX, AMAX, DT, JOINTS)
    assert np.all(np.isfinite(got))
    assert np.all(np.abs(got) <= VMAX * (1 + 1e-9))
    assert np.all(np.abs(got - v0) <= AMAX * DT * (1 + 1e-9))


@given(st.lists(finite, min_size=6, max_size=6))
@example([1e-320, 0.0, 0.0, 0.0, 0.0, 3e-310])
def test_any_finite_pose_error_gives_a_finite_velocity_within_the_limits(error: list[float]) -> None:
    vmax, amax = np.array([0.5, 1.0]), np.array([2.0, 4.0])
    got = next_velocity(np.array(error), np.zeros(6), vmax, amax, DT, POSE)
    assert np.all(np.isfinite(got))
    assert np.linalg.norm(got[:3]) <= vmax[0] * (1 + 1e-9) and np.linalg.norm(got[3:]) <= vmax[1] * (1 + 1e-9)


@pytest.mark.parametrize("distance", [5e-324, 1e-300, 1e300, 1.7e308])
def test_braking_speed_is_finite_or_beyond_any_limit_for_any_distance(distance: float) -> None:
    speed = braking_speed(distance, 6.0, DT)
    assert speed >= 0.0 and not math.isnan(speed)
    if distance >= 1.0:
        assert speed > 1e6  # the speed limit decides there


@pytest.mark.parametrize("accel", [1.0, 6.0, 20.0])
def test_a_joint_move_to_a_target_1e_300_off_on_one_axis_is_answered_every_cycle_and_lands(accel: float) -> None:
    """The move of the failing example, at the back end's joint acceleration (6 rad/s^2) and two others."""
    bench = Bench()
    try:
        target = np.radians(READY) + np.array(TINY_OFFSET)
        cmd = bench.command(CommandKind.JOINT, *target, 0.0, 1e9, accel, 1.0, 0.0)
        event = bench.until_done(cmd)  # every reply accepted by the controller: it asserts so each cycle
        assert event[3] is True, event
        assert bench.model.stats.late == 0 and bench.model.stats.invalid_replies == 0
        assert np.all(np.isfinite(bench.model.trace))
        assert np.allclose(bench.model.trace[-1], target, atol=1e-7)  # type: ignore[index]
        assert np.all(np.abs(bench.steps()) <= VMAX * DT * (1 + 1e-9))
        assert bench.channel.motion.clamped == 0
    finally:
        bench.logger.close()


def test_a_nan_in_the_generator_is_never_sent_the_robot_brakes_and_the_move_fails_saying_why() -> None:
    """Whatever computed it, a correction that is not a number passes every comparison of the
    limiter; it is caught before the reply, the robot brakes within its limits, and the command
    ends in a failure the application sees."""
    bench = Bench()
    try:
        cmd = bench.command(CommandKind.JOINT, *np.radians([40, -80, 85, 0, 30, 0]), 0.0, 1.0, 5.0, 0.0, 0.0)
        bench.cycles(60)
        moving = bench.steps()[-1].copy()
        assert abs(moving[0]) > 0
        bench.channel.motion.joint.position[0] = math.nan  # the upstream defect
        event = bench.until_done(cmd)
        assert event[3] is False and event[5] == "internal"
        assert "A1 nan" in str(event[4]) and "not a number" in str(event[4]) and "brakes" in str(event[4])
        assert any("not a number" in w for w in bench.warnings())
        bench.cycles(200)  # braked to rest, and stays there
        steps = bench.steps()
        assert np.all(np.isfinite(steps))
        assert np.all(np.abs(steps) <= VMAX * DT * (1 + 1e-9))
        assert np.all(np.abs(np.diff(steps, axis=0)) <= AMAX * DT * DT * (1 + 1e-6) + 1e-12)
        assert np.all(steps[-1] == 0.0)
    finally:
        bench.logger.close()


def test_a_nan_in_the_cartesian_generator_is_never_sent_the_tcp_brakes_and_the_move_fails() -> None:
    bench = Bench()
    try:
        here = Pose.from_matrix(KukaArm().fk(np.radians(READY)))
        goal = here.translated(0.0, 0.1, 0.0)
        cmd = bench.command(CommandKind.CART, goal.x, goal.y, goal.z, goal.qx, goal.qy, goal.qz, goal.qw, 0.3, 2.0, 1.0, 2.0)
        bench.cycles(40)
        motion = bench.channel.motion
        assert motion.mode == "cart"
        motion.cart.position = motion.cart.position + np.array([0.0, math.nan, 0.0])  # the upstream defect
        event = bench.until_done(cmd)
        assert event[3] is False and event[5] == "internal"
        assert "Cartesian correction" in str(event[4]) and "Y nan" in str(event[4])
        bench.cycles(200)
        tcp = np.array([KukaArm().fk(q)[:3, 3] for q in bench.model.trace])  # type: ignore[union-attr]
        shifts = np.diff(tcp, axis=0)
        assert np.all(np.isfinite(shifts))
        assert np.all(np.linalg.norm(shifts, axis=1) <= LINK.max_linear_speed * DT * (1 + 1e-6))
        assert np.all(np.linalg.norm(np.diff(shifts, axis=0), axis=1) <= LINK.max_linear_accel * DT * DT * (1 + 1e-6))
        assert np.linalg.norm(shifts[-1]) == 0.0  # at rest short of the goal: the move was not finished blindly
        assert np.linalg.norm(tcp[-1] - np.array(goal.position)) > 1e-3
    finally:
        bench.logger.close()
