"""KUKA RSI: recorded 'linear' trajectories stay on their straight lines when replayed through the loop.

As test_linear_recording.py does for the Nextage simulator and V+: random straight sweeps (one to
three legs) are recorded, stored through SQLite, replayed through the back end's own path -- the
stream the RSI loop plays one set point per cycle to the accelerated KR C4 simulator -- and every
set point the controller received, and the middle of every cycle's step, is measured against the
lines by :mod:`line_measure` (a computation independent of the sampler).  Before, legs were kept
as the Cartesian generator's pose every 0.1 s and replayed by a cubic per axis: the chords bowed
and the junctions of legs were cut, up to several times the tolerance.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from line_measure import LineMeasure
from test_linear_recording import stored  # the trajectory as execute_trajectory gets it back: through SQLite

from core_functions.geometry import Pose
from core_functions.primitives import ExecuteTrajectory, MoveJoints, RecordTrajectory, SetSpeed
from core_functions.robots import KUKA_KR
from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.kuka_rsi.external import LoopSettings
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
TOLERANCE = 1e-4  # m: the documented default
ANGLE_TOLERANCE = math.radians(0.1)  # rad
READY = (0.0, -80.0, 85.0, 0.0, 30.0, 0.0)  # deg, away from the wrist singularity of the home pose
VELOCITY = np.array([j.max_velocity for j in KUKA_KR.group("arm").joints])
ARM = KukaArm()

offsets = st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6)
legs = st.lists(st.tuples(st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3), st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3)), min_size=1, max_size=3)


def _backend() -> KukaRsiBackend:
    spec = SimulatorSpec(runner="thread", accelerated=True, context=RsiContext(start_deg=READY))
    return KukaRsiBackend(listen=("127.0.0.1", 0), simulator=spec, runner="thread", settings=LoopSettings(silence_timeout=2.0))


def _waypoints(start: Pose, moves: list[tuple[list[float], list[float]]]) -> list[Pose]:
    """Straight legs from ``start``: a shift (m) and a turn about the tool (rad, roll-pitch-yaw) each."""
    out, here = [], start
    for shift, turn in moves:
        turned = Pose.from_matrix(here.matrix() @ Pose.from_xyz_rpy(0.0, 0.0, 0.0, *turn).matrix())
        here = Pose(here.x + shift[0], here.y + shift[1], here.z + shift[2], *turned.quaternion)
        out.append(here)
    return out


def _executed(trace: list[np.ndarray]) -> list[Pose]:
    """Every set point the controller received and the middle of every cycle's step."""
    q = np.array(trace)
    between = 0.5 * (q[1:] + q[:-1])
    return [Pose.from_matrix(ARM.fk(p)) for p in np.concatenate((q, between))]


@settings(max_examples=6, deadline=None)
@given(offsets, legs, st.sampled_from([1.0, 0.4]))
# A1 1e-300 rad off READY: the generator's NaN at the end of the first move stopped RSI (test_rsi_tiny_values).
@example([-5.804531882152867e-300, 0.2698048978668572, 0.15, 0.0, -0.20300858567564029, 0.2956864655483475], [([1.773649911949672e-211, -0.07773234351870029, 0.02], [0.0, 0.0, 0.0])], 1.0)
def test_a_recorded_linear_sweep_replays_within_tolerance_of_its_lines_on_kuka_rsi(
    start_offset: list[float], moves: list[tuple[list[float], list[float]]], speed: float
) -> None:
    async def main(clock: Clock) -> None:
        backend = _backend()
        await backend.start()
        try:
            start_q = np.radians(READY) + np.array(start_offset)
            await backend.execute("arm", MoveJoints(tuple(start_q)))
            start = Pose.from_matrix(ARM.fk(start_q))
            waypoints = _waypoints(start, moves)
            try:
                plan = stored(await backend.execute("arm", RecordTrajectory("sweep", "plan", tuple(waypoints), "linear")))
            except BridgeError as error:  # a random waypoint may leave the workspace, a line cross a singularity
                assert error.kind is FaultKind.UNREACHABLE
                assert "% of its length" in str(error) or "is out of reach" in str(error), str(error)
                return
            assert np.all(np.abs(np.diff(plan.points, axis=0)) <= VELOCITY * np.diff(plan.times)[:, None] * (1 + 1e-9))
            assert np.max(np.diff(plan.times), initial=0.0) <= 0.1 + 1e-9  # no gap longer than the sample period
            sim = backend.sim_thread
            loop = backend.iface.loop if backend.iface is not None else None
            assert sim is not None and loop is not None
            await backend.execute("arm", SetSpeed(speed))
            await backend.execute("arm", MoveJoints(plan.points[0]))
            sim.model.trace = []
            before = backend.iface.state(0).cycles  # type: ignore[union-attr]
            result = await backend.execute("arm", ExecuteTrajectory("sweep", plan.joint_names, plan.points, plan.times))
            cycles = backend.iface.state(0).cycles - before  # type: ignore[union-attr]
            measures = [LineMeasure(a, b, TOLERANCE, ANGLE_TOLERANCE) for a, b in zip([start, *waypoints], waypoints)]
            worst_ratio, worst_off, where = 0.0, 0.0, ""
            for pose in _executed(sim.model.trace):  # type: ignore[arg-type]
                off = [m.off_segment(pose) for m in measures]
                worst_off = max(worst_off, min(off))
                # A leg farther than the tolerance from the pose cannot be the one it keeps to.
                near = [m for m, d in zip(measures, off) if d <= TOLERANCE] or [measures[int(np.argmin(off))]]
                ratio, position, angle = min((m.nearest(pose) for m in near), key=lambda found: found[0])
                if ratio > worst_ratio:
                    worst_ratio, where = ratio, f"{position * 1000:.4f} mm / {math.degrees(angle):.4f} deg from the nearest line pose"
            assert worst_ratio <= 1.0 and worst_off <= TOLERANCE, where
            assert result.tcp is not None and result.tcp.distance_to(waypoints[-1]) < 2e-4
            assert loop.channels[0].motion.clamped == 0  # the replay never asked the limiter for more than the axes allow
            assert cycles * 0.004 >= plan.times[-1] / speed - 0.004  # never faster than recorded (slower only at corners)
        finally:
            await backend.close()

    run_with_clock(main, simulated_clock())


def test_a_line_through_the_wrist_singularity_fails_the_recording_saying_where(run_sim: Run) -> None:
    """Through A5 = 0 the wrist would have to turn half a turn at once: no joint samples keep the
    line, and nothing moves."""

    async def main(clock: Clock) -> None:
        backend = _backend()
        await backend.start()
        try:
            start_q = np.radians([0.0, -80.0, 85.0, 0.0, 10.0, 0.0])
            await backend.execute("arm", MoveJoints(tuple(start_q)))
            through = Pose.from_matrix(ARM.fk(start_q)).translated(-0.1, 0.01, -0.1)  # A5 passes 0 beside the arm's plane
            before = backend.iface.state(0).commanded_joints  # type: ignore[union-attr]
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", RecordTrajectory("flip", "plan", (through,), "linear"))
            assert caught.value.kind is FaultKind.UNREACHABLE and "% of its length" in str(caught.value)
            assert "straight line of 'flip'" in str(caught.value) and "A4 would turn" in str(caught.value) and "singularity" in str(caught.value)
            assert backend.iface.state(0).commanded_joints == before  # type: ignore[union-attr]
        finally:
            await backend.close()

    run_sim(main)
