"""The speed override on a V+ controller: the back end sets the monitor speed over a link of its own, and the
simulated controller scales the motion under way on its path (0 % holds it there, for longer than any ack
allowance, and it goes on to its goal).  Measured from the controller's joints on simulated time."""
from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from core_functions.primitives import MoveJoints, SetSpeed
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.vplus.backend import VPlusBackend
from robot_bridges.vplus.codec import Skill, monitor_speed
from robot_bridges.vplus.measurement import SimulatedFocusCamera
from robot_bridges.vplus.simulator import VPlusSimulator
from speed_override_checks import Samples, assert_within_limits, distance_to_path, sample, settle_time

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
HOME = np.radians([0.0, -90.0, 180.0, 0.0, 90.0, 0.0])
GOAL = tuple(np.radians([150.0, -60.0, 150.0, 0.0, 60.0, 0.0]))  # joint_1 150 deg: 2.3 s at 20 % of 328 deg/s
SPEED = 0.2


@contextlib.asynccontextmanager
async def rig(clock: Clock) -> AsyncIterator[tuple[VPlusSimulator, VPlusBackend]]:
    async with VPlusSimulator(clock) as sim:
        backend = VPlusBackend(clock, "127.0.0.1", sim.port, ack_timeout=2.0, measurement=SimulatedFocusCamera(noise=0.0))
        await backend.start()
        try:
            await backend.execute("arm", SetSpeed(SPEED))
            yield sim, backend
        finally:
            await backend.close()


async def overridden(clock: Clock, changes: dict[float, float]) -> tuple[VPlusSimulator, Any, Samples]:
    async with rig(clock) as (sim, backend):
        actions = {at: (lambda rate=rate: backend.set_speed_override(rate)) for at, rate in changes.items()}
        result, samples = await sample(clock, backend.execute("arm", MoveJoints(GOAL)), sim.arm.joints, 0.02, actions, 0.001)
        return sim, result, samples


def test_half_speed_mid_motion_halves_the_controllers_joint_velocities_on_the_same_path(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        sim, result, samples = await overridden(clock, {1.0: 0.5})
        peak = np.abs(np.array(GOAL) - HOME) / 2.3  # about the planned cruise speeds
        limits = sim.arm.kin.max_velocity / sim.arm.ramp
        settle = settle_time(0.5, peak, limits)
        before = samples.window(0.5, 1.0).speed()
        after = samples.window(1.0 + settle + 0.05, 1.0 + settle + 0.6).speed()
        assert before[0] == pytest.approx(math.radians(328.0) * SPEED, rel=1e-3)
        assert after[0] == pytest.approx(0.5 * before[0], rel=0.01)
        assert distance_to_path(samples.q, np.array([HOME, GOAL])) < 1e-9  # JMOVE's joint line, unchanged
        assert_within_limits(samples, sim.arm.kin.max_velocity * SPEED, limits)
        assert result.positions == pytest.approx(GOAL, abs=1e-9)
        assert Skill.MONITOR_SPEED in [m.command.skill for m in sim.received]

    run_sim(main)


def test_zero_holds_on_the_path_beyond_every_ack_allowance_and_goes_on_to_the_goal(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        sim, result, samples = await overridden(clock, {1.0: 0.0, 9.0: 1.0})  # held 8 s: the acks allow 2 s + 2 x the motion
        limits = sim.arm.kin.max_velocity / sim.arm.ramp
        bound = settle_time(1.0, np.array([math.radians(328.0) * SPEED]), limits[:1])
        held = samples.window(1.0 + bound + 0.02, 9.0)
        assert np.ptp(held.q, axis=0).max() < 1e-12 and 0.0 < held.q[0, 0] < GOAL[0]
        assert result.positions == pytest.approx(GOAL, abs=1e-9)
        assert distance_to_path(samples.q, np.array([HOME, GOAL])) < 1e-9
        assert_within_limits(samples, sim.arm.kin.max_velocity * SPEED, limits)

    run_sim(main)


def test_an_override_the_controller_did_not_take_refuses_the_next_motion(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            sim.skills = frozenset(sim.skills - {Skill.MONITOR_SPEED})  # an AdeptServer without the skill: no ack
            backend.set_speed_override(0.5)
            await clock.sleep(5.0)
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", MoveJoints(GOAL))
            assert caught.value.kind is FaultKind.CONTROLLER and "speed override 50 % did not reach the controller" in str(caught.value)
            assert not sim.arm.moving

    run_sim(main)
    with pytest.raises(ValueError, match=r"\[0, 100\]"):
        monitor_speed(101)


def test_a_monitor_speed_reaches_the_controller_while_its_motion_link_waits_for_a_break(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            motion = asyncio.ensure_future(backend.execute("arm", MoveJoints(GOAL)))
            await clock.sleep(0.5)
            backend.set_speed_override(0.25)
            await clock.sleep(0.2)
            assert sim.arm.monitor.target == 0.25 and not motion.done()  # taken beside the break, not after it
            await motion

    run_sim(main)


def test_a_motion_right_after_a_change_waits_until_the_controller_has_the_monitor_speed(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            backend.set_speed_override(0.5)
            await backend.execute("arm", MoveJoints(GOAL))  # sent at once: its messages wait for the monitor speed's ack
            order = [m.command.skill for m in sim.received]
            assert order.index(Skill.MONITOR_SPEED) < order.index(Skill.MOVE_JOINTS)
            assert sim.arm.monitor.target == 0.5

    run_sim(main)
