"""The speed override on KUKA RSI: the loop that makes the corrections cycle by cycle caps a move's speed at the
override's share (the braking-curve generator reaches it within the axes' accelerations, along the move's own
line) and plays a stream's path at that rate (its rate changes within the path's budget), so a running motion
halves its joint velocities on its path, 0 % brakes it to rest there and raising it goes on to the same end.

Robot time is the RSI cycle count (4 ms) of the accelerated simulated KR C4; every sample is the controller's
actual axes (AIPos) stamped with the cycle it was reported in."""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from core_functions.primitives import ExecuteTrajectory, MoveJoints, SetSpeed
from node_transport.clock import Clock
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.kuka_rsi.external import LoopSettings
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec
from speed_override_checks import Samples, assert_within_limits, distance_to_path
from test_rsi_backend import READY

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
CYCLE = 0.004
FRACTION = 0.25  # A1 at 156 deg/s x 0.25 = 0.68 rad/s, accelerating at 6 x 0.25 = 1.5 rad/s^2 (MotionLimits.joint_accel)
GOAL = tuple(np.array(READY) + np.radians([100.0, 0, 0, 0, 0, 0]))
SPEED, ACCEL = math.radians(156.0) * FRACTION, 6.0 * FRACTION


def _with_backend(run_sim: Run, body: Callable[[KukaRsiBackend], Coroutine[Any, Any, Any]]) -> Any:
    """``body`` on a back end driving the accelerated simulated KR C4 (in this process), started at READY."""
    async def main(clock: Clock) -> Any:
        simulator = SimulatorSpec(runner="thread", accelerated=True, context=RsiContext(start_deg=tuple(math.degrees(v) for v in READY)))
        backend = KukaRsiBackend(listen=("127.0.0.1", 0), simulator=simulator, runner="thread", settings=LoopSettings(silence_timeout=1.0))
        try:  # a back end that did not start closes what it began
            await backend.start()
            return await body(backend)
        finally:
            await backend.close()

    return run_sim(main)


async def sampled(b: KukaRsiBackend, work: Coroutine[Any, Any, Any], changes: dict[int, float], every: int = 5) -> tuple[Any, Samples]:
    """Run ``work`` sampling the actual axes every ``every`` cycles; ``changes``: cycles after the start -> override rate."""
    assert b.iface is not None
    start = b.iface.state(0).cycles
    task = asyncio.ensure_future(work)
    pending = sorted(changes.items())
    times, rows = [], []
    while not task.done():
        state = b.iface.state(0)
        times.append((state.cycles - start) * CYCLE)
        rows.append(state.actual_joints)
        while pending and state.cycles - start >= pending[0][0]:
            b.set_speed_override(pending.pop(0)[1])
        await b.wait_cycles(every)
    return await task, Samples(np.array(times), np.array(rows))


def test_half_speed_mid_move_halves_the_joint_velocities_on_the_line(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> tuple[Any, Samples]:
        await b.execute("arm", SetSpeed(FRACTION))
        return await sampled(b, b.execute("arm", MoveJoints(GOAL)), {250: 0.5})  # at 1 s: cruising

    result, samples = _with_backend(run_sim, body)
    settle = 0.5 * SPEED / ACCEL  # the speed cap reached at the move's acceleration: 0.23 s
    before = samples.window(0.7, 1.0).speed()[0]
    after = samples.window(1.0 + settle + 0.1, 1.0 + settle + 0.7).speed()[0]
    assert before == pytest.approx(SPEED, rel=0.02)
    assert after == pytest.approx(0.5 * before, rel=0.02)
    assert distance_to_path(samples.q, np.array([READY, GOAL])) < 1e-6  # A1 alone: the move's joint line
    assert_within_limits(samples, np.full(6, SPEED), np.full(6, ACCEL), slack=0.1)
    assert result.positions == pytest.approx(GOAL, abs=1e-4)


def test_zero_brakes_to_rest_on_the_line_and_raising_it_ends_the_same_move(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> tuple[Any, Samples]:
        await b.execute("arm", SetSpeed(FRACTION))
        return await sampled(b, b.execute("arm", MoveJoints(GOAL)), {250: 0.0, 750: 1.0})  # held from 1 s to 3 s

    result, samples = _with_backend(run_sim, body)
    bound = SPEED / ACCEL  # 0.45 s from cruise to rest
    held = samples.window(1.0 + bound + 0.1, 3.0)
    assert np.ptp(held.q[:, 0]) < 1e-6 and READY[0] < held.q[0, 0] < GOAL[0]
    assert held.q[0, 0] - samples.window(0.0, 1.0).q[-1, 0] <= SPEED * bound  # within the braking distance
    assert result.positions == pytest.approx(GOAL, abs=1e-4)
    assert distance_to_path(samples.q, np.array([READY, GOAL])) < 1e-6
    assert_within_limits(samples, np.full(6, SPEED), np.full(6, ACCEL), slack=0.1)


def test_a_streamed_trajectory_plays_at_half_its_rate_on_its_points(run_sim: Run) -> None:
    start = np.array(READY)
    points = tuple(tuple(start + np.array([0.6 * s, 0.0, 0.0, 0.0, -0.3 * s, 0.0])) for s in np.linspace(0.0, 1.0, 9))
    times = tuple(float(t) for t in np.linspace(0.0, 4.0, 9))  # 0.15 rad/s on A1 for 4 s

    async def body(b: KukaRsiBackend) -> tuple[Any, Samples]:
        return await sampled(b, b.execute("arm", ExecuteTrajectory("sweep", ("A1", "A2", "A3", "A4", "A5", "A6"), points, times)), {375: 0.5})

    result, samples = _with_backend(run_sim, body)
    before = samples.window(1.0, 1.5).speed()[0]
    after = samples.window(2.0, 2.8).speed()[0]
    assert after == pytest.approx(0.5 * before, rel=0.05)
    assert distance_to_path(samples.q, np.array(points)) < 1e-4
    assert samples.t[-1] > 4.0 + 1.5  # the rest of the path at half its rate
    assert result.positions == pytest.approx(points[-1], abs=1e-4)
