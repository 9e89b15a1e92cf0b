"""The speed override of a whole run: the engine's parameter and commands reach the bridge, which scales
the running motion on its path; every change is recorded with its source and time, and the status says
so.  A Nextage cell in-process (collision check on), measured from ``joint_states``; and the parameter
through the fake rclpy (``ros2 param set``)."""
from __future__ import annotations

import asyncio
import math
from typing import Any

import numpy as np
import pytest
import ros_fake_parameters
from app_builder import make_app
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.speed import HOLDING
from node_transport import typed
from node_transport.clock import Clock, real_clock, run_with_clock, simulated_clock
from node_transport.msgs import JointState
from node_transport.qos import LATCHED, SENSOR
from node_transport.ros import RosTransport
from node_transport.wire import ENGINE_STATUS, JOINT_STATES, EngineStatus
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend
from speed_override_checks import Samples, assert_within_limits, settle_time

LEFT = NEXTAGE_OPEN.group("left_arm").joint_names
INITIAL = [math.radians(v) for v in (0.6, 0.0, -100.0, -15.2, 9.4, -3.2)]


def joints(first: float) -> str:
    return ",".join(f"{v:.6f}" for v in [first, *INITIAL[1:]])


APP = make_app([{"left_arm": ("move_joints", joints(-1.3))}, {"left_arm": ("move_joints", joints(0.8))}])  # clear of the torso


async def when(clock: Clock, condition: Any, bound: float = 30.0) -> None:
    deadline = clock.now() + bound
    while not condition():
        assert clock.now() < deadline, "condition not met in time"
        await clock.sleep(0.01)


def test_the_parameter_and_the_terminal_scale_a_running_motion_on_its_path_and_every_change_is_recorded() -> None:
    async def main(clock: Clock) -> tuple[Any, Samples, list[EngineStatus], float, float, float]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, bridge_parameters={"state_period": 0.02})
        watcher = deployment.transport.create_node("watcher")
        times: list[float] = []
        rows: list[list[float]] = []
        statuses: list[EngineStatus] = []

        def on_joints(msg: JointState) -> None:
            index = dict(zip(msg.name, msg.position))
            times.append(clock.now())
            rows.append([index[n] for n in LEFT])

        watcher.create_subscription(JointState, JOINT_STATES, on_joints, SENSOR)
        watcher.create_subscription(typed.EngineStatusMsg, ENGINE_STATUS, lambda m: statuses.append(typed.from_msg(EngineStatus, m, clock)), LATCHED)
        engine = deployment.engine
        try:
            running = asyncio.ensure_future(engine.run(APP))
            await when(clock, lambda: engine._operation is not None and engine._operation.id == "2")
            await when(clock, lambda: rows and rows[-1][0] > -1.0)  # cruising at 1 rad/s towards +0.8
            halved = clock.now() + 0.3
            await clock.sleep(halved - clock.now())
            assert engine.node.set_parameter("speed_override", 50.0) == ""  # as `ros2 param set` does
            await clock.sleep(1.5)
            stopped = clock.now()
            ok, answer = engine.speed.set(0, "terminal console (key '0')")
            assert ok and "holding on the path" in answer
            await clock.sleep(2.0)
            assert engine.state == "running"  # not a pause: the machine waits for its motion as ever
            assert engine.speed.set(100, "studio")[0]
            report = await clock.wait_for(running, 60.0)
            names, values = backend.joint_state()
            end = values[names.index("LARM_JOINT0")]
        finally:
            await deployment.close()
        return report, Samples(np.array(times), np.array(rows)), statuses, halved, stopped, end

    report, samples, statuses, halved, stopped, end = run_with_clock(main, simulated_clock())
    assert report.outcome == "finished", (report.message, report.errors)
    acceleration = np.full(6, 1.5)
    before = samples.window(halved - 0.4, halved).speed()[0]
    settle = settle_time(0.5, np.array([1.0]), acceleration[:1])
    after = samples.window(halved + settle + 0.05, halved + settle + 0.75).speed()[0]
    assert before == pytest.approx(1.0, rel=0.03)
    assert after == pytest.approx(0.5 * before, rel=0.03)
    stop_bound = settle_time(0.5, np.array([1.0]), acceleration[:1])
    held = samples.window(stopped + stop_bound + 0.05, stopped + 2.0)
    assert np.ptp(held.q[:, 0]) < 1e-9  # held on the path
    assert end == pytest.approx(0.8, abs=1e-9)  # and finished the same motion
    assert_within_limits(samples.window(halved - 0.5, samples.t[-1]), np.full(6, 1.0), acceleration, slack=0.1)
    changes = [(a.command, a.source, a.accepted, a.answer, a.target) for a in report.operator_actions if a.command == "speed_override"]
    assert changes == [
        ("speed_override", "parameter /execution_engine/speed_override", True, "speed override 50 % (was 100 %)", "50"),
        ("speed_override", "terminal console (key '0')", True, "speed override 0 % (was 50 %); holding on the path", "0"),
        ("speed_override", "studio", True, "speed override 100 % (was 0 %)", "100"),
    ]
    assert any(s.speed_override == 0.0 and HOLDING in s.message for s in statuses)
    assert statuses[-1].speed_override == 100.0 and HOLDING not in statuses[-1].message


def test_a_value_out_of_range_changes_nothing_and_says_why() -> None:
    async def main(clock: Clock) -> None:
        backend = await create_backend("nextage-sim", clock, BackendOptions(NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend)
        try:
            engine = deployment.engine
            assert engine.node.set_parameter("speed_override", 150.0) == "parameter 'speed_override' must be a number in [0, 100] %, got 150"
            assert engine.speed.set(-5, "studio") == (False, "parameter 'speed_override' must be a number in [0, 100] %, got -5")
            assert engine.speed.set(float("nan"), "studio")[0] is False
            assert engine.speed.percent == 100.0 and engine.node.get_parameter("speed_override") == 100.0
            assert backend.speed_override == 1.0
        finally:
            await deployment.close()

    run_with_clock(main, simulated_clock())


def test_ros2_param_set_on_the_engine_node_through_rclpy(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> None:
        transport = RosTransport(clock, ["execution_engine"])
        try:
            node = transport.create_node("execution_engine")
            engine = ExecutionEngine(node, full_catalog())
            described = node.ros_node.describe_parameter("speed_override").description
            assert "changeable while the engine runs" in described and "[0, 100] %" in described
            taken = node.ros_node.set_parameters([ros_fake_parameters.Parameter("speed_override", value=50.0)])[0]
            assert taken.successful
            for _ in range(100):
                if engine.speed.percent == 50.0:
                    break
                await asyncio.sleep(0.01)
            assert engine.speed.percent == 50.0
            assert engine.speed.changes[-1].source == "parameter /execution_engine/speed_override"
            refused = node.ros_node.set_parameters([ros_fake_parameters.Parameter("speed_override", value=150.0)])[0]
            assert not refused.successful and refused.reason == "Parameter speed_override out of range Min: 0.0, Max: 100.0, value: 150.0"  # rclpy's own range check
            frozen = node.ros_node.set_parameters([ros_fake_parameters.Parameter("service_timeout", value=1.0)])[0]
            assert not frozen.successful and "read at start-up" in frozen.reason
            engine.speed.set(25.0, "studio")  # another way: `ros2 param get` shows it too
            assert node.ros_node.get_parameter("speed_override").value == 25.0
            await asyncio.sleep(0.05)
            assert engine.speed.percent == 25.0 and len(engine.speed.changes) == 2  # the echo was not a change
        finally:
            await transport.shutdown()

    run_with_clock(main, real_clock())
