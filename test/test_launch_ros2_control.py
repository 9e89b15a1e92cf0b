"""``launch`` of a cell whose robot is driven by its own ROS 2 driver (the ``ros2-control`` back end), over DDS.

``python -m execution_engine launch APP --robot ros2-control --backend-option arm.controller=...`` starts the
ros2_control_bridge process (cell_runner/bridge_nodes/ros2_control.py) beside the machine and the engine; the
driver is the joint_trajectory_controller stand-in (fake_fjt_server.FakeDriver) serving in the same DDS domain, as
a ros2_control driver shares the graph with the cell.  The run is checked from the driver's /joint_states on the
ros2-control back end's model with the bridge's options (the engine's plan is that dry run's, no RSI simulator in the
engine), goes to FINISHED and every goal the driver received stayed within the URDF's speeds.  On one graph the bridge must not
publish the driver's joints under the driver's names again (the back end would take its copy for the driver's
word): checked in-process on the model transport, with and without a cell's renaming.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from dds_domain import domain_env, stop_group
from fake_fjt_server import FakeDriver, moved_too_fast, urdf_limits
from fjt_dds import base_env, driver_on_dds

from app_functions.registry import full_catalog
from cell_runner.bridge_nodes.ros2_control import driver_joints
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.start import measured, plan_start
from core_functions.cell_robots import CellNames
from core_functions.geometry import Pose
from core_functions.robots import KUKA_KR
from execution_engine.app_model import load_application
from execution_engine.run_plan import PLAN_TOPIC
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import JointState
from node_transport.port import Node
from node_transport.qos import JOINT_STATES, LATCHED
from node_transport.typed import RunPlanMsg
from robot_bridges.backend import BackendOptions
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.placed import PlacedBackend
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
URDF_FILE = ROOT / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf"
URDF = URDF_FILE.read_text()
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"
GRIPPER = "/gripper_controller/gripper_cmd"
BOUND = 150.0  # s: five processes' start-up, the check, then some 6 s of motion, on a loaded machine
#: the demonstrator cut to three operations: a joint move, a Cartesian pick with the gripper, home
SHORT_APP = """<?xml version="1.0" encoding="UTF-8"?>
<application name="short_pick" robot="kuka" cell="cells/kuka_rsi_cell.xml">
  <error_policy retries="0" action="abort"/>
  <operation id="1"><arm><function name="move_joints"><params><param value="0 -80 85 0 35 0 deg"/></params></function></arm></operation>
  <operation id="2"><arm><function name="pick"><params><param value="part_slot"/><param value="60 mm"/></params></function></arm></operation>
  <operation id="3"><arm><function name="move_to_joint_pose"><params><param value="home"/></params></function></arm></operation>
</application>
"""


#: the same as a cell of one robot named by the cell: the KUKA on ros2-control, its group and joints prefixed kuka_
CELL = """<?xml version="1.0" encoding="UTF-8"?>
<cell name="driven" length_unit="m" angle_unit="rad">
  <robot name="loader" model="kuka" backend="ros2-control" xyz="0 0 0" rpy="0 0 0" prefix="kuka_">
    <option name="arm.controller" value="/joint_trajectory_controller/follow_joint_trajectory"/>
    <option name="arm.gripper" value="/gripper_controller/gripper_cmd"/>
  </robot>
  <frame name="tray" xyz="0.50 -0.15 0.10" kind="fixture">
    <frame name="part_slot" xyz="0.0 0.0 0.02" rpy="3.14159265 0 0" kind="pick"/>
  </frame>
</cell>
"""
CELL_APP = SHORT_APP.replace('robot="kuka" cell="cells/kuka_rsi_cell.xml"', 'robot="cell" cell="driven_cell.xml"').replace("<arm>", "<kuka_arm>").replace("</arm>", "</kuka_arm>")


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:
        yield claimed


def launch_against_the_driver(
    env: dict[str, str], tmp_path: Path, app: Path, *options: str, plans: list[Any] | None = None,
) -> tuple[subprocess.Popen[str], str, FakeDriver]:
    """``launch APP --transport dds OPTIONS`` to its end while the stand-in driver serves in the same domain;
    ``plans`` gets every RunPlan the engine publishes (its latched plan topic, heard from the driver's node)."""

    def build(node: Node, clock: Clock) -> FakeDriver:
        if plans is not None:
            node.create_subscription(RunPlanMsg, f"/{PLAN_TOPIC}", plans.append, LATCHED)
        return FakeDriver(node, clock, URDF, {CONTROLLER: KUKA_KR.group("arm").joint_names}, KUKA_KR.poses["home"], gripper=GRIPPER)

    with driver_on_dds(env, build, BOUND) as driver:
        command = [sys.executable, "-m", "execution_engine", "launch", str(app), "--transport", "dds", *options]
        process = subprocess.Popen(
            command, cwd=tmp_path, env={**base_env(), **env, "PYTHONPATH": str(ROOT), "XDG_DATA_HOME": str(tmp_path / "data")},
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
        )
        try:
            output, _ = process.communicate(timeout=BOUND)
        finally:
            stop_group(process)
    return process, output, driver


def test_launch_with_the_ros2_control_back_end_finishes_against_a_driver_on_the_same_dds_graph(env: dict[str, str], tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    shutil.copy(ROOT / "apps_xml" / "cells" / "kuka_rsi_cell.xml", tmp_path / "cells" / "kuka_rsi_cell.xml")
    app = tmp_path / "short_pick.xml"
    app.write_text(SHORT_APP)
    plans: list[Any] = []
    process, output, driver = launch_against_the_driver(
        env, tmp_path, app, "--robot", "ros2-control", "--backend-option", f"arm.controller={CONTROLLER}", "--backend-option", f"arm.gripper={GRIPPER}",
        plans=plans,
    )
    assert process.returncode == 0, output
    # the engine checked the run on the ros2-control model with the bridge's options, as run --robot ros2-control does:
    # its plan is that dry run's from where the driver says the arm is (the URDF here from a file, the engine's from
    # /robot_description: the same text), not the KUKA's RSI simulator's (4.33 s), which ran no RSI loop in the engine
    checked = plan_start(load_application(app, full_catalog()), setup_for("ros2-control", BackendOptions(robot=KUKA_KR, extra={
        "arm.controller": CONTROLLER, "arm.gripper": GRIPPER, "urdf": str(URDF_FILE),
    })), measured(KUKA_KR, KUKA_KR.joint_names, [KUKA_KR.poses["home"][j] for j in KUKA_KR.joint_names], "home"))
    assert [(p.app, p.basis) for p in plans] == [("short_pick", "measured")], plans
    assert plans[0].cycle_time == pytest.approx(checked.report.cycle_time, abs=1e-6)
    assert "checked on the dry run of the ros2-control back end (arm.controller=" in output, output
    assert "RSI loop" not in output and "kuka_rsi" not in output, output
    assert "[execution_engine] application short_pick: FINISHED" in output, output
    for node in ("ros2_control_bridge", "arm_machine"):
        assert f"[launch] {node} stopped (exit code 0)" in output, output
    assert len(driver.goals) >= 3 and all(g.outcome == "succeeded" for g in driver.goals), driver.goals
    assert [bad for g in driver.goals for bad in moved_too_fast(g, urdf_limits(URDF))] == []
    assert driver.grips == [0.08, 0.0]  # the pick: opened, then closed on the part


def test_launch_of_a_cell_whose_robot_is_on_ros2_control_finishes_under_the_cells_names(env: dict[str, str], tmp_path: Path) -> None:
    """The cell form: the robot's back end and options in its <robot>; the bridge (loader_bridge) gets them as parameters
    with the cell's names, publishes kuka_A1..kuka_A6 on /joint_states beside the driver's A1..A6 (the engine checks the
    run from those), and turns the kuka_arm group's motions into the driver's goals on A1..A6."""
    (tmp_path / "driven_cell.xml").write_text(CELL)
    app = tmp_path / "driven.xml"
    app.write_text(CELL_APP)
    process, output, driver = launch_against_the_driver(env, tmp_path, app)
    assert process.returncode == 0, output
    assert "[execution_engine] application short_pick: FINISHED" in output, output
    for node in ("loader_bridge", "kuka_arm_machine"):
        assert f"[launch] {node} stopped (exit code 0)" in output, output
    assert len(driver.goals) >= 3 and all(g.outcome == "succeeded" and g.joints == tuple(KUKA_KR.group("arm").joint_names) for g in driver.goals)
    assert driver.grips == [0.08, 0.0]


def test_the_bridge_leaves_the_drivers_own_joints_out_of_its_joint_states(run_sim: Any) -> None:
    """Names the driver publishes itself are not published again; a cell's prefix (or a joints mapping) makes the
    cell's names the driver's no longer, and those the bridge does publish -- /joint_states then has both."""

    async def main(clock: Clock) -> dict[str, Any]:
        options = BackendOptions(robot=KUKA_KR, extra={"transport": "model", "urdf": str(URDF_FILE)})
        own = await create_backend("ros2-control", clock, options)
        prefixed = PlacedBackend(await create_backend("ros2-control", clock, options), Pose(), "loader", CellNames("kuka_"))
        bus = LocalTransport(clock)
        seen: list[JointState] = []
        bus.create_node("viewer").create_subscription(JointState, "/joint_states", seen.append, JOINT_STATES)
        found = {}
        for name, backend in (("own", own), ("prefixed", prefixed)):
            bridge = BridgeNode(bus.create_node(f"{name}_bridge"), backend)
            bridge.graph_joints = driver_joints(backend)
            await bridge.start()
            seen.clear()
            await clock.sleep(0.3)  # six state periods
            found[name] = (bridge.graph_joints, {n for s in seen for n in s.name}, len(seen))
            await bridge.close()
            await backend.close()
        return found

    found = run_sim(main)
    names = set(KUKA_KR.group("arm").joint_names)
    assert found["own"][0] == names and found["own"][1] == set() and found["own"][2] == 0  # nothing of the driver's again
    assert found["prefixed"][0] == frozenset() and found["prefixed"][1] == {f"kuka_{n}" for n in names}
