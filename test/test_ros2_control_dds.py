"""The ``ros2-control`` back end over Cyclone DDS (issue 23 item 2's must-show, fast suite): the command line a user
types -- ``run APP --robot ros2-control --backend-option ...`` -- against a joint_trajectory_controller stand-in that is
another DDS participant in another process's domain, known to the back end only by the wire (rcl_action's names,
control_msgs' types, ``/robot_description``, ``/joint_states``).  The dry run reads the URDF from the graph, the run
is checked from where the driver says the arm is, and the application runs to FINISHED with every goal within the
URDF's speeds.  In real time (DDS has no simulated clock): the demonstrator's 11 s.
"""
from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from dds_domain import domain_env, stop_group
from fake_fjt_server import FakeDriver, moved_too_fast, urdf_limits
from fjt_dds import base_env, driver_on_dds

from node_transport.clock import Clock
from node_transport.port import Node
from core_functions.robots import KUKA_KR

ROOT = Path(__file__).resolve().parents[1]
URDF = (ROOT / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf").read_text()
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"
GRIPPER = "/gripper_controller/gripper_cmd"
BOUND = 120.0  # s the whole run may take on a loaded machine (11 s of motion)


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:
        yield claimed


def test_run_with_the_ros2_control_back_end_finishes_against_a_dds_controller(env: dict[str, str], tmp_path: Path) -> None:
    def build(node: Node, clock: Clock) -> FakeDriver:
        return FakeDriver(node, clock, URDF, {CONTROLLER: KUKA_KR.group("arm").joint_names}, KUKA_KR.poses["home"], gripper=GRIPPER)

    with driver_on_dds(env, build, BOUND) as driver:
        command = [
            sys.executable, "-m", "execution_engine", "run", str(ROOT / "apps_xml" / "kuka_rsi_demo.xml"), "--robot", "ros2-control",
            "--backend-option", f"arm.controller={CONTROLLER}", "--backend-option", f"arm.gripper={GRIPPER}",
            "--trajectory-db", str(tmp_path / "trajectories.sqlite"),
        ]
        process = subprocess.Popen(command, cwd=tmp_path, env={**base_env(), **env, "PYTHONPATH": str(ROOT)}, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   start_new_session=True)
        try:
            output, _ = process.communicate(timeout=BOUND)
        finally:
            stop_group(process)
    assert process.returncode == 0, output
    assert "dry run of kuka_rsi_demo on ros2-control: no problems found" in output
    assert "application kuka_rsi_demo: FINISHED" in output and "operations: 8/8" in output
    assert len(driver.goals) == 9 and all(g.outcome == "succeeded" for g in driver.goals)
    assert [bad for g in driver.goals for bad in moved_too_fast(g, urdf_limits(URDF))] == []
    assert driver.grips == [0.08, 0.0, 0.08]  # the default open and closed positions

