"""A recorded trajectory paused by the operator over KUKA RSI and resumed: the rest of its path from where the arm stands.

The loop streams a trajectory one set point per RSI cycle; a pause brakes the arm at its limits wherever that
ends.  Sending the same stream again on resume would start it at its first point -- far from the arm, refused as
"more than one cycle's motion away", and the motion already made would be made again.  These tests pause a
trajectory that goes out and comes back over the same points (so "the nearest point" alone would send it back to
its first half) on the lockstep simulated controller and check what the controller was commanded, cycle by cycle.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from app_builder import make_app

from cell_runner.deployment import deploy_local
from core_functions.primitives import ExecuteTrajectory, SetSpeed, TrajectoryResult
from core_functions.robots import KUKA_KR
from core_functions.trajectory_store import TrajectoryStore
from node_transport.clock import Clock
from node_transport.msgs import Trigger
from node_transport.wire import engine_service
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.replay import remainder
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec

READY = np.radians([0.0, -80.0, 85.0, 0.0, 30.0, 0.0])
NAMES = ("A1", "A2", "A3", "A4", "A5", "A6")
Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
#: Out and back: A1 0 -> 0.6 -> 0 rad, A5 0 -> -0.3 -> 0 rad from READY, over 2 s.
SHAPE = (0.0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0.0)
POINTS = tuple(tuple(READY + np.array([0.6 * s, 0.0, 0.0, 0.0, -0.3 * s, 0.0])) for s in SHAPE)
TIMES = tuple(0.25 * k for k in range(len(SHAPE)))


def _backend() -> KukaRsiBackend:
    return KukaRsiBackend(
        listen=("127.0.0.1", 0),
        simulator=SimulatorSpec(runner="thread", accelerated=True, context=RsiContext(start_deg=tuple(np.degrees(READY)))),
        runner="thread",
        settings=LoopSettings(silence_timeout=1.0),
    )


async def _watch(b: KukaRsiBackend, task: asyncio.Task[Any], record: list[tuple[int, np.ndarray]]) -> None:
    """The commanded set point at every cycle the event loop sees, until the primitive ends."""
    assert b.iface is not None
    while not task.done():
        state = b.iface.state(0)
        record.append((state.cycles, np.array(state.commanded_joints)))
        await b.wait_cycles(1)


def _check_the_path(b: KukaRsiBackend, record: list[tuple[int, np.ndarray]]) -> None:
    limits = np.array(b.link.max_joint_speed) * b.link.cycle_ms / 1000.0
    a1 = np.array([q[0] for _, q in record])
    for (c0, q0), (c1, q1) in zip(record, record[1:]):  # never a jump: within the axes' speeds, cycle for cycle
        assert np.all(np.abs(q1 - q0) <= limits * max(1, c1 - c0) * (1 + 1e-9)), (c0, c1, q1 - q0)
    steps = np.diff(a1)
    moving = steps[np.abs(steps) > 1e-9]
    assert np.count_nonzero(np.diff(np.sign(moving))) == 1  # out, then back: never back over what was made
    assert math.isclose(float(np.sum(np.abs(steps))), 1.2, abs_tol=2e-3)  # 0.6 rad out and 0.6 back, nothing twice
    assert b.iface is not None and b.iface.state(0).clamped == 0  # no step the limiter had to hold back


@pytest.mark.parametrize("speed", [1.0, 0.5])
def test_a_paused_trajectory_resumes_along_the_rest_of_its_path(run_sim: Run, speed: float) -> None:
    """Paused on its way out and again on its way back (over points it passed going out), each time resumed."""
    async def main(clock: Clock) -> None:
        b = _backend()
        await b.start()
        try:
            await b.execute("arm", SetSpeed(speed))
            record: list[tuple[int, np.ndarray]] = []
            task = asyncio.get_running_loop().create_task(b.execute("arm", ExecuteTrajectory("out_and_back", NAMES, POINTS, TIMES)))
            watcher = asyncio.get_running_loop().create_task(_watch(b, task, record))
            assert b.iface is not None
            far = False
            for going_out, a1 in ((True, 0.2), (False, 0.3)):  # rad from READY: on the way out, then back over the same points
                for _ in range(5000):  # cycles: the trajectory lasts 500 / speed
                    q = b.iface.state(0).commanded_joints[0] - READY[0]
                    far = far or q > 0.59
                    if (going_out and q >= a1) or (far and q <= a1) or task.done():
                        break
                    await b.wait_cycles(1)
                await b.pause("arm")
                await b.wait_cycles(100)
                held = b.iface.state(0).commanded_joints
                await b.wait_cycles(50)
                assert b.iface.state(0).commanded_joints == held and not task.done()  # standing, still executing
                await b.resume("arm")
            result = await task
            await watcher
            assert np.allclose(result.positions, POINTS[-1], atol=1e-4)
            _check_the_path(b, record)
        finally:
            await b.close()

    run_sim(main)


def test_the_rest_of_a_trajectory_is_searched_on_from_what_was_passed() -> None:
    """The arm at a point the trajectory passes twice: the rest is what follows its second passage."""
    times, points = np.array(TIMES), np.array(POINTS)
    here = points[2] + np.array([0.01, 0, 0, 0, -0.005, 0])  # a little past A1 = 0.3 going out, or before it coming back
    rest_times, rest = remainder(times, points, here, 5)
    assert np.allclose(rest[0], here) and np.allclose(rest[1:], points[7:])
    assert np.allclose(rest_times, times[6:])
    rest_times, rest = remainder(times, points, here, 0)  # going out: from the passage that lies ahead
    assert np.allclose(rest[1:], points[3:]) and np.allclose(rest_times, times[2:])
    rest_times, rest = remainder(times, points, points[-1], 8)  # at the end: nothing left but the end
    assert len(rest) == 1 and np.allclose(rest[0], points[-1])


def test_the_operator_pauses_an_application_mid_trajectory_and_it_finishes_after_resume(run_sim: Run, tmp_path: Any) -> None:
    """The engine's own path: an application replays the trajectory on the KUKA RSI back end; the operator's
    pause (the engine's pause service) holds it mid-way, the resume lets it finish, nothing made twice."""
    store = TrajectoryStore(tmp_path / "trajectories.db")
    store.save("arm", "out_and_back", TrajectoryResult(NAMES, POINTS, TIMES), "plan", 0.0)
    store.close()

    async def main(clock: Clock) -> tuple[Any, list[tuple[int, np.ndarray]], KukaRsiBackend]:
        b = _backend()
        deployment = await deploy_local(clock, KUKA_KR, b, machine_parameters={"trajectory_db": str(tmp_path / "trajectories.db")})
        node = deployment.transport.create_node("test_operator")
        pause, resume = (node.create_client(Trigger, engine_service(c)) for c in ("pause", "resume"))
        run = asyncio.get_running_loop().create_task(deployment.engine.run(make_app([{"arm": ("execute_trajectory", "out_and_back")}], robot=KUKA_KR)))
        record: list[tuple[int, np.ndarray]] = []
        try:
            assert b.iface is not None
            for _ in range(5000):  # cycles: until the arm is a third of the way out
                if b.iface.state(0).commanded_joints[0] - READY[0] >= 0.2 or run.done():
                    break
                await b.wait_cycles(1)
            watcher = asyncio.get_running_loop().create_task(_watch(b, run, record))
            assert (await pause.call(Trigger.Request(), timeout=5.0)).success
            await b.wait_cycles(150)
            assert not run.done()
            assert (await resume.call(Trigger.Request(), timeout=5.0)).success
            report = await run
            await watcher
        finally:
            await deployment.close()
        return report, record, b

    report, record, b = run_sim(main)
    assert report.outcome == "finished", report.message
    a1 = np.array([q[0] for _, q in record])
    assert abs(float(np.sum(np.abs(np.diff(a1)))) - (0.6 - (a1[0] - READY[0]) + 0.6)) < 2e-3  # the rest of the way, nothing twice
