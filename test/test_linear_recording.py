"""Recorded 'linear' trajectories stay on their straight line when replayed, within the stated tolerance.

A replay interpolates joints between the stored samples, so the TCP between two samples follows
a joint-space chord.  These tests record random straight sweeps, store them, replay them through
each back end's own execution path on simulated time and measure every executed TCP pose against
the straight line (:mod:`line_measure`, a computation independent of the sampler).  With samples
every 0.1 s, as recordings had before, the chords bow well past 0.1 mm.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from line_measure import LineMeasure

from core_functions.geometry import Pose
from core_functions.primitives import ExecuteTrajectory, MoveJoints, RecordTrajectory, SetSpeed, TrajectoryResult
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN
from core_functions.trajectory_store import TrajectoryStore
from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.backend import HAND_TOOL, NextageSimBackend
from robot_bridges.vplus.backend import VPlusBackend
from robot_bridges.vplus.kinematics import ViperKinematics
from robot_bridges.vplus.sim_arm import Segment, SimulatedArm
from robot_bridges.vplus.simulator import VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
TOLERANCE = 1e-4  # m: the documented default
ANGLE_TOLERANCE = math.radians(0.1)  # rad: the documented default
ARM = NEXTAGE_OPEN.group("left_arm")
ARM_VELOCITY = np.array([j.max_velocity for j in ARM.joints])
VIPER = ADEPT_VIPER_S850.group("arm")
VIPER_VELOCITY = np.array([j.max_velocity for j in VIPER.joints])
READY = np.radians([0.0, -60.0, 150.0, 0.0, 60.0, 0.0])  # the Viper over its table, wrist bent

offsets = st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6)
sweeps = st.lists(st.floats(-0.4, 0.4), min_size=6, max_size=6)


def stored(trajectory: TrajectoryResult) -> TrajectoryResult:
    """The trajectory as ``execute_trajectory`` gets it back: through the SQLite store."""
    store = TrajectoryStore(":memory:")
    store.save("g", "sweep", trajectory, "plan", 0.0)
    loaded = store.load("g", "sweep").trajectory
    store.close()
    return loaded


def mean_speeds(trajectory: TrajectoryResult) -> np.ndarray:
    """|dq/dt| of every joint between consecutive samples (what a replay runs at, at speed 1)."""
    points, times = np.array(trajectory.points), np.array(trajectory.times)
    spans = np.diff(times)
    steps = np.abs(np.diff(points, axis=0))
    assert np.all(spans[steps.max(axis=1) > 1e-12] > 0), "a sample with motion but no time"
    return steps[spans > 0] / spans[spans > 0, None]


# --------------------------------------------------------------------- Nextage simulator
def nextage_arm_joints(backend: NextageSimBackend) -> np.ndarray:
    names, values = backend.joint_state()
    return np.array([values[names.index(n)] for n in ARM.joint_names])


async def nextage_sweep(clock: Clock, start_offset: list[float], sweep: list[float]) -> tuple[NextageSimBackend, Pose, Pose]:
    """A backend with the left arm at a random pose, and a reachable straight sweep from there."""
    backend = NextageSimBackend(clock, tools={"left_arm": HAND_TOOL})
    arm = backend.model.arms["left_arm"]
    start = np.clip(nextage_arm_joints(backend) + np.array(start_offset), arm.lower + 0.1, arm.upper - 0.1)
    end = np.clip(start + np.array(sweep), arm.lower + 0.1, arm.upper - 0.1)
    await backend.execute("left_arm", MoveJoints(tuple(start)))
    q = backend.model.named_pose("initial")
    q[arm.indices] = end
    start_pose = backend.tcp_pose("left_arm")
    assert start_pose is not None
    return backend, start_pose, arm.tcp_pose(q)


@settings(max_examples=12, deadline=None)
@given(offsets, sweeps)
def test_a_recorded_linear_sweep_replays_within_tolerance_of_the_line_on_the_nextage(start_offset: list[float], sweep: list[float]) -> None:
    async def main(clock: Clock) -> None:
        backend, start, end = await nextage_sweep(clock, start_offset, sweep)
        plan = stored(await backend.execute("left_arm", RecordTrajectory("sweep", "plan", (end,), "linear")))
        replay = asyncio.ensure_future(backend.execute("left_arm", ExecuteTrajectory("sweep", plan.joint_names, plan.points, plan.times)))
        executed = []
        while not replay.done():  # every control step's pose (the probe runs five times per step)
            executed.append(backend.tcp_pose("left_arm"))
            await clock.sleep(backend.control_period / 5)
        result = await replay
        executed.append(result.tcp)
        measure = LineMeasure(start, end, TOLERANCE, ANGLE_TOLERANCE)
        worst = measure.worst(executed)
        assert worst.ratio <= 1.0 and worst.off_segment <= TOLERANCE, measure.describe(worst)
        assert result.tcp.distance_to(end) < 2e-5 and result.tcp.angle_to(end) < math.radians(0.01)
        # timing: within the joint speeds, at the TCP speed of a live linear move, no gap above sample_period
        assert np.all(mean_speeds(plan) <= ARM_VELOCITY * (1 + 1e-9))
        assert np.max(np.diff(plan.times)) <= 0.1 + 1e-9
        tcp = np.array([backend.model.arms["left_arm"].tcp_pose(_with_arm(backend, p)).position for p in plan.points])
        spans = np.diff(plan.times)
        moves = np.linalg.norm(np.diff(tcp, axis=0), axis=1)[spans > 0]
        # 0.25 m/s is the TCP limit; along a joint-space chord the TCP's progress is not quite
        # proportional to the path parameter, hence the 1 % allowance on the mean speeds
        assert np.all(moves / spans[spans > 0] <= 0.25 * 1.01)

    run_with_clock(main, simulated_clock())


def _with_arm(backend: NextageSimBackend, arm_joints: tuple[float, ...]) -> np.ndarray:
    q = backend.model.named_pose("initial")
    q[backend.model.arms["left_arm"].indices] = arm_joints
    return q


def test_the_tolerance_is_a_parameter_of_the_recording(run_sim: Run) -> None:
    """A coarser tolerance needs fewer samples and keeps to itself; one finer than the IK is refused, saying why."""

    async def main(clock: Clock) -> None:
        backend, start, end = await nextage_sweep(clock, [0.2, -0.2, 0.1, 0.2, 0.2, -0.2], [0.3, 0.3, -0.3, 0.3, -0.3, 0.3])
        assert RecordTrajectory("x", waypoints=(end,)).tolerance == TOLERANCE
        assert RecordTrajectory("x", waypoints=(end,)).angle_tolerance == pytest.approx(ANGLE_TOLERANCE)
        fine = await backend.execute("left_arm", RecordTrajectory("fine", "plan", (end,), "linear", sample_period=10.0))
        coarse = await backend.execute(
            "left_arm", RecordTrajectory("coarse", "plan", (end,), "linear", sample_period=10.0, tolerance=1e-3, angle_tolerance=math.radians(1))
        )
        assert len(coarse.points) < len(fine.points)
        measure = LineMeasure(start, end, 1e-3, math.radians(1))
        arm = backend.model.arms["left_arm"]
        chords = [arm.tcp_pose(_with_arm(backend, a + (b - a) * u)) for a, b in zip(np.array(coarse.points), np.array(coarse.points)[1:]) for u in np.linspace(0, 1, 21)]
        assert measure.worst(chords).ratio <= 1.0
        with pytest.raises(ValueError, match="tolerance"):
            RecordTrajectory("bad", waypoints=(end,), tolerance=0.0)

    run_sim(main)


def test_a_line_the_recording_cannot_keep_fails_it_saying_where_and_why(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend, start, end = await nextage_sweep(clock, [0.2, -0.2, 0.1, 0.2, 0.2, -0.2], [0.3, 0.3, -0.3, 0.3, -0.3, 0.3])
        before = backend.joint_state(), clock.now()
        with pytest.raises(BridgeError) as too_fine:  # finer than the IK's own 0.01 mm
            await backend.execute("left_arm", RecordTrajectory("too_fine", "plan", (end,), "linear", tolerance=1e-7))
        assert too_fine.value.kind is FaultKind.UNREACHABLE
        assert "left_arm" in str(too_fine.value) and "tolerance" in str(too_fine.value) and "% of its length" in str(too_fine.value)
        with pytest.raises(BridgeError) as far:
            await backend.execute("left_arm", RecordTrajectory("far", "plan", (start.translated(0.6, 0.0, 0.0),), "linear"))
        assert far.value.kind is FaultKind.UNREACHABLE and "leaves the reachable workspace" in str(far.value)
        assert (backend.joint_state(), clock.now()) == before  # a failed recording moved nothing

    run_sim(main)


# ---------------------------------------------------------------------------- V+ (AdeptServer)
class RecordingArm(SimulatedArm):
    """The simulated Viper, keeping every joint-interpolated motion it starts (its executed path)."""

    def __init__(self, clock: Clock) -> None:
        super().__init__(clock)
        self.segments: list[Segment] = []

    def _start(self, goal: np.ndarray) -> None:
        super()._start(goal)
        if self._segment is not None:  # None: a motion of zero length
            self.segments.append(self._segment)


async def viper_at(clock: Clock, sim: VPlusSimulator, joints: np.ndarray) -> VPlusBackend:
    backend = VPlusBackend(clock, "127.0.0.1", sim.port)
    await backend.start()
    await backend.execute("arm", MoveJoints(tuple(joints)))
    return backend


@settings(max_examples=6, deadline=None)
@given(offsets, sweeps, st.sampled_from([1.0, 0.4]))
def test_a_recorded_linear_sweep_replays_within_tolerance_of_the_line_on_v_plus(
    start_offset: list[float], sweep: list[float], speed: float
) -> None:
    """AdeptServer moves joint-interpolated only; a linear recording replayed as JMOVEs still keeps the line."""
    kin = ViperKinematics()
    start_q = READY + np.array(start_offset)
    end = Pose.from_matrix(kin.forward(start_q + np.array(sweep)))

    async def main(clock: Clock) -> None:
        arm = RecordingArm(clock)
        async with VPlusSimulator(clock, arm=arm) as sim:
            backend = await viper_at(clock, sim, start_q)
            start = backend.tcp_pose("arm")
            assert start is not None
            before = clock.now()
            plan = stored(await backend.execute("arm", RecordTrajectory("sweep", "plan", (end,), "linear")))
            assert clock.now() == before  # planning moves nothing
            assert np.all(mean_speeds(plan) <= VIPER_VELOCITY * (1 + 1e-9))
            await backend.execute("arm", SetSpeed(speed))
            arm.segments.clear()
            started = clock.now()
            result = await backend.execute("arm", ExecuteTrajectory("sweep", plan.joint_names, plan.points, plan.times))
            executed = [
                Pose.from_matrix(kin.forward(segment.at(t)))
                for segment in arm.segments
                for t in np.arange(segment.t0, segment.t_end + 2e-3, 2e-3)  # the controller's path, every 2 ms
            ]
            measure = LineMeasure(start, end, TOLERANCE, ANGLE_TOLERANCE)
            worst = measure.worst(executed)
            assert worst.ratio <= 1.0 and worst.off_segment <= TOLERANCE, measure.describe(worst)
            assert result.tcp is not None and result.tcp.distance_to(end) < 2e-5
            for segment in arm.segments:  # every JMOVE within the joint speeds, none faster than recorded
                rates = np.abs(segment.goal - segment.start) * segment.velocity
                assert np.all(rates <= VIPER_VELOCITY * speed * (1 + 1e-6))
            assert clock.now() - started >= plan.times[-1] / speed
            await backend.close()

    run_with_clock(main, simulated_clock())


def test_a_sweep_past_the_shoulder_singularity_fails_the_recording_clearly(run_sim: Run) -> None:
    """0.1 mm beside the Viper's base axis the arm would have to swing half a turn at once: no line exists."""
    kin = ViperKinematics()
    out = Pose.from_xyz_rpy(0.0, 0.0, 0.0, 0.0, math.pi / 2, 0.0).quaternion  # the flange pointing along +x
    # the wrist centre is 80 mm behind the flange, so this line takes it 0.1 mm past the base axis
    start, end = Pose(0.0801, -0.05, 0.7, *out), Pose(0.0801, 0.05, 0.7, *out)

    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            backend = await viper_at(clock, sim, kin.inverse(start.matrix(), kin.home))
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", RecordTrajectory("flip", "plan", (end,), "linear"))
            assert caught.value.kind is FaultKind.UNREACHABLE
            assert "no continuous motion follows the line" in str(caught.value) and "singularity" in str(caught.value)
            assert "% of its length" in str(caught.value)
            await backend.close()

    run_sim(main)


def test_v_plus_refuses_what_adeptserver_cannot_record(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            backend = await viper_at(clock, sim, READY)
            start = backend.tcp_pose("arm")
            assert start is not None
            with pytest.raises(BridgeError) as far:
                await backend.execute("arm", RecordTrajectory("far", "plan", (start.translated(0.8, 0.0, 0.0),), "linear"))
            assert far.value.kind is FaultKind.UNREACHABLE and "leaves the reachable workspace" in str(far.value)
            with pytest.raises(BridgeError) as teach:
                await backend.execute("arm", RecordTrajectory("taught", "teach", duration=1.0))
            assert teach.value.kind is FaultKind.UNSUPPORTED
            too_fast = ExecuteTrajectory("fast", VIPER.joint_names, (tuple(READY), tuple(READY + 0.5)), (0.0, 0.01))
            with pytest.raises(BridgeError) as fast:
                await backend.execute("arm", too_fast)
            assert fast.value.kind is FaultKind.JOINT_LIMIT and "joint_" in str(fast.value)
            await backend.close()

    run_sim(main)
