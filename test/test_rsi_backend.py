"""KukaRsiBackend end to end: primitives in, corrections out, the accelerated simulator as the robot.

The application side runs on simulated time (``run_sim``); the back end never needs the clock,
because it counts robot cycles.  Its waits end on the loop's events.
"""
from __future__ import annotations

import asyncio
import io
import json
import math
import re
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cell_runner.cli import main as cli_main
from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    ExecuteTrajectory,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    RecordTrajectory,
    SetSpeed,
    Vision,
)
from core_functions.robots import KUKA_KR, NEXTAGE_OPEN
from node_transport.clock import Clock, real_clock, run_with_clock, scaled_clock, simulated_clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.kuka_rsi.backend import KukaRsiBackend, create
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec
from robot_bridges.kuka_rsi.sim_faults import Quirks

READY = tuple(math.radians(v) for v in (0.0, -80.0, 85.0, 0.0, 30.0, 0.0))
ARM = KukaArm()
Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]


def _backend(
    context: RsiContext = RsiContext(start_deg=tuple(math.degrees(v) for v in READY)),
    settings: LoopSettings = LoopSettings(silence_timeout=1.0),
    quirks: Quirks = Quirks(),
    link: RobotLink | None = None,
) -> KukaRsiBackend:
    return KukaRsiBackend(
        listen=("127.0.0.1", 0),
        link=link,
        simulator=SimulatorSpec(runner="thread", accelerated=True, context=context, quirks=quirks),
        runner="thread",
        settings=settings,
    )


def _with_backend(run_sim: Run, body: Callable[[KukaRsiBackend], Coroutine[Any, Any, Any]], **kwargs: Any) -> Any:
    async def main(clock: Clock) -> Any:
        backend = _backend(**kwargs)
        await backend.start()
        try:
            return await body(backend)
        finally:
            await backend.close()

    return run_sim(main)


def _cycles(backend: KukaRsiBackend) -> int:
    assert backend.iface is not None
    return backend.iface.state(0).cycles


def test_joint_and_cartesian_moves_reach_their_targets(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        assert b.groups == ("arm",) and b.joint_state()[0] == ("A1", "A2", "A3", "A4", "A5", "A6")
        target = tuple(math.radians(v) for v in (20, -70, 80, 10, 40, -10))
        result = await b.execute("arm", MoveJoints(target))
        assert isinstance(result, MotionResult) and np.allclose(result.positions, target, atol=1e-4)
        assert result.tcp is not None and result.tcp.distance_to(Pose.from_matrix(ARM.fk(target))) < 1e-4
        goal = result.tcp.translated(0.05, -0.1, -0.05)
        for interpolation in ("ptp", "linear"):
            await b.execute("arm", MoveJoints(target))
            result = await b.execute("arm", MoveCartesian(goal, interpolation))
            assert result.tcp is not None and result.tcp.distance_to(goal) < 2e-4 and result.tcp.angle_to(goal) < 2e-3
        relative = await b.execute("arm", MoveJoints((0.1, 0, 0, 0, 0, -0.1), relative=True))
        assert np.allclose(np.array(relative.positions) - result.positions, (0.1, 0, 0, 0, 0, -0.1), atol=2e-4)
        named = await b.execute("arm", MoveJoints((0.3,), joint_names=("A6",)))
        assert named.positions[5] == pytest.approx(0.3, abs=1e-4) and named.positions[0] == pytest.approx(relative.positions[0], abs=2e-4)
        assert b.tcp_pose("arm") is not None

    _with_backend(run_sim, body)


def test_a_linear_move_follows_a_straight_line(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        sim = b.sim_thread
        assert sim is not None
        start = b.tcp_pose("arm")
        assert start is not None
        sim.model.trace = []
        goal = start.translated(0.1, 0.1, -0.1)
        await b.execute("arm", MoveCartesian(goal, "linear"))
        trace = list(sim.model.trace)
        assert len(trace) > 100
        line = np.array(goal.position) - start.position
        for q in trace:  # every set point the controller received lies on the segment
            p = ARM.fk(q)[:3, 3] - start.position
            assert np.linalg.norm(np.cross(p, line)) / np.linalg.norm(line) < 1e-6
            assert -1e-6 <= float(np.dot(p, line)) / float(np.dot(line, line)) <= 1 + 1e-6

    _with_backend(run_sim, body)


def test_relative_moves_in_world_and_tool_frames(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        start = b.tcp_pose("arm")
        assert start is not None
        world = await b.execute("arm", MoveRelative(Pose(0.0, 0.05, 0.0)))
        assert world.tcp is not None and world.tcp.distance_to(start.translated(0.0, 0.05, 0.0)) < 2e-4
        tool = await b.execute("arm", MoveRelative(Pose(0.0, 0.0, 0.03), reference="tool", interpolation="ptp"))
        assert tool.tcp is not None and tool.tcp.distance_to(world.tcp.offset_local(0.0, 0.0, 0.03)) < 2e-4

    _with_backend(run_sim, body)


def test_set_speed_slows_the_following_motions(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> tuple[int, int]:
        durations = []
        for fraction, target in ((1.0, (40, -80, 85, 0, 30, 0)), (0.25, (0, -80, 85, 0, 30, 0))):
            await b.execute("arm", SetSpeed(fraction))
            before = _cycles(b)
            await b.execute("arm", MoveJoints(tuple(math.radians(v) for v in target)))
            durations.append(_cycles(b) - before)
        return durations[0], durations[1]

    fast, slow = _with_backend(run_sim, body)

    def trapezoid_cycles(fraction: float) -> float:
        d, v, a = math.radians(40), fraction * math.radians(156), fraction * 6.0  # A1 max speed, MotionLimits.joint_accel
        seconds = d / v + v / a if d >= v * v / a else 2 * math.sqrt(d / a)
        return seconds / 0.004

    # Each move takes at least its time-optimal profile at the scaled limits (robot time: exact);
    # the full-speed one ends long before a quarter-speed profile could (reading the count after
    # the move adds a few cycles of scheduling, far less than the 200 between the two).
    assert fast >= trapezoid_cycles(1.0) and slow >= trapezoid_cycles(0.25)
    assert fast < trapezoid_cycles(0.25)


def test_dwell_lasts_its_time_in_robot_cycles(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> int:
        before = _cycles(b)
        await b.execute("arm", Dwell(0.2))
        return _cycles(b) - before

    # 0.2 s at 4 ms is 50 cycles, counted by the robot.  With heartbeats every 2000 cycles only
    # the dwell's own wake-up request can end it early enough (reading the count adds a few).
    cycles = _with_backend(run_sim, body, settings=LoopSettings(silence_timeout=1.0, heartbeat_cycles=2000))
    assert 50 <= cycles < 2000


def test_end_effector_actions_set_the_tool_outputs(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        result = await b.execute("arm", EndEffector("gripper_close"))
        assert result.io == {"gripper": True, "air": False, "tool": False}
        result = await b.execute("arm", EndEffector("air_on"))
        assert result.io == {"gripper": True, "air": True, "tool": False}
        assert b.sim_thread is not None and b.sim_thread.model.outputs["Tool.o2"] is True
        result = await b.execute("arm", EndEffector("gripper_open"))
        assert result.io["gripper"] is False
        with pytest.raises(BridgeError) as caught:
            await b.execute("arm", EndEffector("hand_draw_in"))
        assert caught.value.kind is FaultKind.UNSUPPORTED

    _with_backend(run_sim, body)


def test_a_recorded_trajectory_is_streamed_point_by_point(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        start = np.array(READY)
        points = tuple(tuple(start + np.array([0.3 * s, 0.0, 0.0, 0.0, -0.2 * s, 0.0])) for s in (0.0, 0.25, 0.5, 0.75, 1.0))
        trajectory = ExecuteTrajectory("sweep", ("A1", "A2", "A3", "A4", "A5", "A6"), points, (0.0, 0.25, 0.5, 0.75, 1.0))
        before = _cycles(b)
        result = await b.execute("arm", trajectory)
        assert np.allclose(result.positions, points[-1], atol=1e-4)
        assert _cycles(b) - before >= 250  # one second of points, one per 4 ms cycle

    _with_backend(run_sim, body)


@pytest.mark.parametrize(
    ("primitive", "kind", "words"),
    [
        (MoveJoints(tuple(math.radians(v) for v in (0, -80, 85, 0, 130, 0))), FaultKind.JOINT_LIMIT, "A5 target 130.000 deg"),
        (MoveJoints((0.1, 0.2)), FaultKind.UNSUPPORTED, "6 values"),
        (MoveCartesian(Pose(2.0, 0.0, 0.5)), FaultKind.UNREACHABLE, "out of reach"),
        (Vision("locate", "hole"), FaultKind.UNSUPPORTED, "vision"),
    ],
)
def test_impossible_primitives_fail_with_their_fault_kind(run_sim: Run, primitive: Any, kind: FaultKind, words: str) -> None:
    async def body(b: KukaRsiBackend) -> None:
        with pytest.raises(BridgeError) as caught:
            await b.execute("arm", primitive)
        assert caught.value.kind is kind and words in str(caught.value)
        with pytest.raises(BridgeError) as other:
            await b.execute("left_arm", MoveJoints(READY))
        assert other.value.kind is FaultKind.UNSUPPORTED
        await b.execute("arm", MoveJoints(READY))  # and the robot still works

    _with_backend(run_sim, body)


def test_pause_holds_and_resume_completes_the_same_move(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        target = tuple(math.radians(v) for v in (90, -70, 80, 0, 40, 0))
        await b.execute("arm", SetSpeed(0.2))
        task = asyncio.get_running_loop().create_task(b.execute("arm", MoveJoints(target)))
        await b.wait_cycles(60)
        await b.pause("arm")
        await b.wait_cycles(150)
        assert b.iface is not None
        held = b.iface.state(0).set_joints
        await b.wait_cycles(50)
        assert b.iface.state(0).set_joints == held and not task.done()  # standing still, still executing
        assert 0.0 < held[0] < target[0]
        await b.resume("arm")
        result = await task
        assert np.allclose(result.positions, target, atol=1e-4)

    _with_backend(run_sim, body)


def test_stop_abandons_the_move(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        await b.execute("arm", SetSpeed(0.2))
        task = asyncio.get_running_loop().create_task(b.execute("arm", MoveJoints(tuple(math.radians(v) for v in (90, -70, 80, 0, 40, 0)))))
        await b.wait_cycles(60)
        await b.stop("arm")
        with pytest.raises(BridgeError) as caught:
            await task
        assert caught.value.kind is FaultKind.STOPPED
        result = await b.execute("arm", MoveJoints(READY))  # the next primitive runs normally
        assert np.allclose(result.positions, READY, atol=1e-4)

    _with_backend(run_sim, body)


def test_an_rsi_timeout_on_the_controller_is_a_controller_fault(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        assert b.iface is not None
        await b.execute("arm", SetSpeed(0.2))
        task = asyncio.get_running_loop().create_task(b.execute("arm", MoveJoints(tuple(math.radians(v) for v in (90, -70, 80, 0, 40, 0)))))
        await b.wait_cycles(20)
        b.iface.withhold_replies(0, 5)
        with pytest.raises(BridgeError) as caught:
            await task
        assert caught.value.kind is FaultKind.CONTROLLER
        assert "RSI timeout: 5 packets late in a row" in str(caught.value)
        with pytest.raises(BridgeError) as later:
            await b.execute("arm", MoveJoints(READY))
        assert later.value is caught.value  # the robot stays stopped until RSI is restarted

    _with_backend(run_sim, body, context=RsiContext(start_deg=tuple(math.degrees(v) for v in READY), timeout=5))


def test_an_axis_correction_monitor_stop_is_a_controller_fault(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        with pytest.raises(BridgeError) as caught:
            await b.execute("arm", MoveJoints(tuple(math.radians(v) for v in (30, -80, 85, 0, 30, 0))))
        assert caught.value.kind is FaultKind.CONTROLLER and "AXISCORRMON" in str(caught.value)

    context = RsiContext(start_deg=tuple(math.degrees(v) for v in READY), axis_monitor_deg=(10.0,) * 6)
    _with_backend(run_sim, body, context=context)


def test_silence_from_the_controller_is_a_timeout(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        assert b.sim_thread is not None
        await b.execute("arm", SetSpeed(0.2))
        task = asyncio.get_running_loop().create_task(b.execute("arm", MoveJoints(tuple(math.radians(v) for v in (90, -70, 80, 0, 40, 0)))))
        await b.wait_cycles(20)
        b.sim_thread.stop()  # the controller vanishes without a word (cable pulled)
        with pytest.raises(BridgeError) as caught:
            await task
        assert caught.value.kind is FaultKind.TIMEOUT and "no packet from kuka" in str(caught.value)

    _with_backend(run_sim, body)


# ------------------------------------------------------------------------ the registry factory
def _options(**kwargs: Any) -> Any:
    return BackendOptions(robot=kwargs.pop("robot", KUKA_KR), **kwargs)


def _create(clock: Clock, options: Any) -> KukaRsiBackend:
    async def make(c: Clock) -> KukaRsiBackend:
        return await create(c, options)

    return run_with_clock(make, clock)  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("options", "words"),
    [
        ({"extra": {"bogus": "1"}}, "unknown option(s) bogus"),
        ({"extra": {"runner": "fiber"}}, "runner must be process or thread"),
        ({"extra": {"cycle": "four"}}, "kuka-rsi: cycle must be 4 or 12 ms, got 'four'"),
        ({"extra": {"cycle": "8"}}, "kuka-rsi: cycle must be 4 or 12 ms, got '8'"),
        ({"extra": {"silence": "0"}}, "kuka-rsi: silence must be a number in [0.01, 10] s, got '0'"),
        ({"extra": {"connect_timeout": "inf"}}, "kuka-rsi: connect_timeout must be a number in [0.1, 600] s, got 'inf'"),
        ({"extra": {"timeout": "2.5"}}, "kuka-rsi: timeout must be a whole number in [1, 100000], got '2.5'"),
        ({"extra": {"sim_drop": "1.5"}}, "kuka-rsi: sim_drop must be a number in [0, 1], got '1.5'"),
        ({"extra": {"config": "/nonexistent.xml"}}, "cannot read RSI configuration"),
        ({"rsi_listen": "0.0.0.0:49152"}, "give the controller's address as host"),
        ({"host": "192.168.1.10"}, "needs rsi_listen"),
        ({"rsi_listen": "0.0.0.0:99999", "host": "192.168.1.10"}, "bad port"),
        ({"faults": ("arm:joint_limit@0.5",)}, "takes no --fault"),
    ],
)
def test_the_factory_refuses_bad_options_with_a_clear_message(options: dict[str, Any], words: str) -> None:
    with pytest.raises(ValueError) as caught:
        _create(real_clock(), _options(**options))
    assert words in str(caught.value)


def test_the_factory_needs_the_robots_clock_and_a_kuka() -> None:
    for clock in (simulated_clock(), scaled_clock(10.0)):
        with pytest.raises(ValueError, match="real-time clock"):
            _create(clock, _options())
    with pytest.raises(ValueError, match="drives kuka_kr"):
        _create(real_clock(), _options(robot=NEXTAGE_OPEN))


def test_the_factory_serves_a_real_controller_without_a_simulator() -> None:
    backend = _create(real_clock(), _options(rsi_listen="127.0.0.1:0", host="10.0.0.5", extra={"mode": "relative", "cycle": "12"}))
    assert backend.simulator_spec is None and backend.iface is None  # not started: the bridge node starts it
    assert (backend.link.host, backend.link.correction_mode, backend.link.cycle_ms) == ("10.0.0.5", "relative", 12)
    assert (backend.settings.host, backend.settings.port) == ("127.0.0.1", 0)


# ------------------------------------------------------------------- through the engine and CLI
def test_the_demo_application_runs_to_finish_through_the_cli(tmp_path: Any) -> None:
    """``run FILE --robot kuka-rsi``: the engine, the group machine, the bridge node, the loop
    process, and the simulated controller (accelerated, so the robot does not take 15 s)."""
    app = Path(__file__).resolve().parents[1] / "apps_xml" / "kuka_rsi_demo.xml"
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = cli_main(["run", str(app), "--robot", "kuka-rsi", "--backend-option", "simulator=accelerated", "--trace", str(trace), "-q"], out, err)
    assert code == 0, err.getvalue() + out.getvalue()
    assert "FINISHED" in out.getvalue() and "operations: 8/8" in out.getvalue()
    states = [json.loads(line).get("state") for line in trace.read_text().splitlines()]
    assert "TrajectoryExecution" in states and "RecordTrajectory" in states and "ErrorHandling" not in states


def test_an_rsi_stop_puts_the_machine_in_error_handling(tmp_path: Any) -> None:
    app = Path(__file__).resolve().parents[1] / "apps_xml" / "kuka_rsi_demo.xml"
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    options = ["--backend-option", "simulator=accelerated", "--backend-option", "axis_monitor=5", "--no-check"]  # the dry run would refuse it
    code = cli_main(["run", str(app), "--robot", "kuka-rsi", *options, "--trace", str(trace), "-q"], out, err)
    assert code == 1, err.getvalue() + out.getvalue()
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    assert any(e.get("state") == "ErrorHandling" for e in events)
    assert "AXISCORRMON" in trace.read_text()


def test_recording_plans_through_waypoints_with_the_robots_generators(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        start = b.tcp_pose("arm")
        assert start is not None
        a, c = start.translated(0.0, -0.1, -0.05), start.translated(0.0, 0.1, -0.05)
        for interpolation in ("linear", "ptp"):
            result = await b.execute("arm", RecordTrajectory("sweep", waypoints=(a, c), interpolation=interpolation, sample_period=0.1))
            assert result.joint_names == ("A1", "A2", "A3", "A4", "A5", "A6")
            assert result.times[0] == 0.0 and all(t1 > t0 for t0, t1 in zip(result.times, result.times[1:]))
            assert Pose.from_matrix(ARM.fk(result.points[-1])).distance_to(c) < 1e-6
            if interpolation == "linear":  # every kept point lies on one of the two legs (the ones between line samples, on their chords)
                for q in result.points[1:]:
                    p = ARM.fk(q)[:3, 3]
                    first, second = np.array(a.position) - start.position, np.array(c.position) - a.position
                    on_first = np.linalg.norm(np.cross(p - start.position, first)) / np.linalg.norm(first) < 1e-4
                    on_second = np.linalg.norm(np.cross(p - np.array(a.position), second)) / np.linalg.norm(second) < 1e-4
                    assert on_first or on_second
        taught = await b.execute("arm", RecordTrajectory("still", mode="teach", duration=0.2, sample_period=0.1))
        assert taught.times == (0.0, 0.1, 0.2) and np.allclose(taught.points, [READY] * 3, atol=1e-6)
        with pytest.raises(BridgeError) as caught:
            await b.execute("arm", RecordTrajectory("far", waypoints=(Pose(2.0, 0.0, 0.5),)))
        assert caught.value.kind is FaultKind.UNREACHABLE

    _with_backend(run_sim, body)


# ------------------------------------------------------------------- peers that report otherwise
def test_a_drifting_controller_ends_the_primitive_with_a_controller_fault_naming_the_axis(run_sim: Run) -> None:
    async def body(b: KukaRsiBackend) -> None:
        with pytest.raises(BridgeError) as caught:
            await b.execute("arm", MoveJoints(tuple(math.radians(v) for v in (60, -80, 85, 0, 30, 0))))
        error = caught.value
        assert error.kind is FaultKind.CONTROLLER
        assert re.search(r"A3: commanded 85\.00\d deg, the controller reports 85\.1\d\d deg \(tolerance 0\.100 deg\)", error.detail)
        with pytest.raises(BridgeError) as later:
            await b.execute("arm", MoveJoints(READY))
        assert later.value is error  # the robot stays stopped until someone looks at the controller

    _with_backend(run_sim, body, quirks=Quirks(drift_axis=3, drift_deg=0.002))


def test_primitives_plan_from_the_commanded_set_point_not_the_reported_one(run_sim: Run) -> None:
    """The peer keeps reporting its start pose (READY) as the set point; with the cross-check
    switched off, what is planned shows: relative moves and the recorded sweep start where the
    robot was commanded to be, never back at the reported pose."""

    async def body(b: KukaRsiBackend) -> None:
        moved = tuple(math.radians(v) for v in (10, -70, 80, 0, 60, 0))
        await b.execute("arm", MoveJoints(moved))
        result = await b.execute("arm", MoveJoints((0.1, 0, 0, 0, 0, 0), relative=True))
        assert np.allclose(result.positions, np.array(moved) + (0.1, 0, 0, 0, 0, 0), atol=1e-4)
        here = np.array(result.positions)
        start = Pose.from_matrix(ARM.fk(here))
        sweep = await b.execute("arm", RecordTrajectory("sweep", waypoints=(start.translated(0.0, 0.05, 0.0),), interpolation="linear"))
        assert np.allclose(sweep.points[0], here, atol=1e-4)  # not READY, which the peer reports
        sim = b.sim_thread
        assert sim is not None
        sim.model.trace = []
        await b.execute("arm", ExecuteTrajectory("sweep", sweep.joint_names, sweep.points, sweep.times))
        steps = np.abs(np.diff(np.array(sim.model.trace), axis=0))
        assert np.max(steps[:, 4]) < math.radians(0.1)  # A5 stayed near 60 deg: no trip back to 30

    off = RobotLink("kuka", "127.0.0.1", setpoint_tolerance_deg=(math.inf,) * 6)
    _with_backend(run_sim, body, quirks=Quirks(frozen_setpoint=True), link=off)
