"""The speed override on the Nextage simulator: a running motion slows on its path, 0 % holds it there.

Measured from the simulator's joint states on simulated time; the bounds come from the joints'
acceleration limits (speed_override_checks.py)."""
from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from core_functions.primitives import MoveJoints, RecordTrajectory
from core_functions.cell_robots import CellRobot
from core_functions.geometry import Pose
from core_functions.robots import NEXTAGE_OPEN
from node_transport.clock import Clock
from robot_bridges.cell_backend import CellBackend, Part
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.placed import PlacedBackend
from speed_override_checks import Samples, assert_within_limits, distance_to_path, sample, settle_time

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, None]]], None]
LEFT = NEXTAGE_OPEN.group("left_arm").joint_names
START = MoveJoints((-1.3,), joint_names=("LARM_JOINT0",))
GOAL = MoveJoints((1.3,), joint_names=("LARM_JOINT0",))  # 2.6 rad: 1 rad/s from 0.67 s to 2.6 s, ends at 3.27 s
PERIOD = 0.02  # s between samples; the simulator steps every 0.01 s
OFFSET = 0.005  # samples fall between two steps


def probe(backend: NextageSimBackend) -> Callable[[], np.ndarray]:
    def read() -> np.ndarray:
        names, values = backend.joint_state()
        return np.array([values[names.index(n)] for n in LEFT])
    return read


async def reference(clock: Clock) -> np.ndarray:
    backend = NextageSimBackend(clock)
    await backend.execute("left_arm", START)
    _, samples = await sample(clock, backend.execute("left_arm", GOAL), probe(backend), PERIOD / 4, offset=OFFSET / 4)
    return samples.q


async def overridden(clock: Clock, changes: dict[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any, Samples]:
    """The path without an override; the left arm's limits; the same motion's result and samples with the
    override set to each rate at its run time (s after the motion's start)."""
    path = await reference(clock)
    backend = NextageSimBackend(clock)
    await backend.execute("left_arm", START)
    idx = backend.model.indices(LEFT)
    actions = {at: (lambda rate=rate: backend.set_speed_override(rate)) for at, rate in changes.items()}
    result, samples = await sample(clock, backend.execute("left_arm", GOAL), probe(backend), PERIOD, actions, OFFSET)
    return path, backend.model.velocity[idx], backend.model.acceleration[idx], result, samples


def test_half_speed_mid_motion_halves_the_joint_velocities_on_the_same_path(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        change_at = 1.0  # cruising at 1 rad/s
        path, velocity, acceleration, result, samples = await overridden(clock, {change_at: 0.5})
        before = samples.window(0.75, change_at).speed()
        settle = settle_time(0.5, before, acceleration)
        after = samples.window(change_at + settle + PERIOD, change_at + settle + 0.8).speed()
        assert before[0] == pytest.approx(1.0, rel=1e-3)
        assert after[0] == pytest.approx(0.5 * before[0], rel=0.01)  # halved, once the rate has changed within the limits
        assert distance_to_path(samples.q, path) < 1e-3  # the planned path, not a new one
        assert_within_limits(samples, velocity, acceleration)
        assert result.positions[0] == pytest.approx(1.3, abs=1e-9)
        assert samples.t[-1] > 3.27 + 0.5  # it took longer: the rest of the way at half speed

    run_sim(main)


def test_zero_stops_on_the_path_within_the_deceleration_bound_holds_and_resumes_to_the_same_end(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        stop_at, resume_at = 1.0, 3.0
        path, velocity, acceleration, result, samples = await overridden(clock, {stop_at: 0.0, resume_at: 1.0})
        bound = settle_time(1.0, np.array([1.0]), acceleration[:1])  # 1 rad/s to rest at 1.5 rad/s^2 at most: 0.67 s
        held = samples.window(stop_at + bound + PERIOD, resume_at)
        assert np.ptp(held.q[:, 0]) < 1e-12  # at rest, held on the path
        stopping = samples.window(stop_at, stop_at + bound + PERIOD)
        assert np.ptp(stopping.q[:, 0]) <= 1.0 * bound  # no farther than the speed it had over the bound
        assert -1.3 < held.q[0, 0] < 1.3  # it stopped part-way
        assert result.positions[0] == pytest.approx(1.3, abs=1e-9)  # and finished the same motion
        assert distance_to_path(samples.q, path) < 1e-3
        assert_within_limits(samples, velocity, acceleration)

    run_sim(main)


def test_a_motion_started_under_an_override_runs_at_it_and_never_above_the_programs_speed(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        await backend.execute("left_arm", START)
        backend.set_speed_override(0.25)
        _, samples = await sample(clock, backend.execute("left_arm", GOAL), probe(backend), PERIOD, offset=OFFSET)
        assert samples.t[-1] == pytest.approx(3.267 / 0.25, abs=0.05)  # every planned time at the override
        assert np.abs(samples.velocities()[:, 0]).max() <= 0.25 + 1e-6
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            backend.set_speed_override(1.5)

    run_sim(main)


def test_a_taught_recording_keeps_the_persons_time_at_any_override(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        backend.set_speed_override(0.0)  # the robot's motions held: the hand that guides the arm is not
        start = clock.now()
        teach = RecordTrajectory("taught", "teach", duration=1.0, sample_period=0.25)
        result = await clock.wait_for(backend.execute("right_arm", teach), 5.0)  # bounded: a held teach would never end
        assert clock.now() - start == pytest.approx(1.0, abs=1e-6) and result.times == (0.0, 0.25, 0.5, 0.75, 1.0)

    run_sim(main)


def test_a_robot_placed_in_a_mixed_cell_takes_the_cells_override(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        inner = NextageSimBackend(clock)
        placed = PlacedBackend(inner, Pose(1.0, 0.0, 0.0), "nextage")
        cell = CellBackend((Part(CellRobot("nextage", NEXTAGE_OPEN, Pose(1.0, 0.0, 0.0), "nextage-sim"), placed),))
        cell.set_speed_override(0.5)  # as the dry run's registry and each robot's bridge give it
        assert (cell.speed_override, placed.speed_override, inner.speed_override) == (0.5, 0.5, 0.5)
        await inner.execute("left_arm", START)
        start = clock.now()
        await placed.execute("left_arm", GOAL)
        assert clock.now() - start == pytest.approx(2 * (2.6 + 1 / 1.5), abs=0.02)  # the move at half its speed

    run_sim(main)
