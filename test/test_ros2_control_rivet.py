"""The rivet demonstrator on the ``ros2-control`` back end over Cyclone DDS (issue 23's must-show, fast suite).

What a user types -- ``run apps_xml/rivet_installation.xml --robot ros2-control`` with the hands' gripper actions,
the deburring tool's SetBool service and ``camera_source=ros`` -- against a Nextage known only by the wire: the
joint_trajectory_controller stand-in of fake_fjt_server.py (the Nextage URDF on ``/robot_description``, three
controllers, a GripperCommand server per hand, the tool's std_srvs/SetBool) in another DDS participant, and
``camera-sim`` in another process rendering the hand cameras from ``/joint_states``.  The dry run reads the URDF
from the graph and renders the cell; the run finds every hole in the images camera-sim published (the trace's
vision reports: the plane fit, the hand camera, the true hole within 0.05 mm), every goal succeeds within the
URDF's ranges and speeds, the tool goes on and off around each deburring, and the application is FINISHED.
In real time (DDS has no simulated clock): the demonstrator's 49 s.
"""
from __future__ import annotations

import json
import math
import re
import signal
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
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from node_transport.port import Node

ROOT = Path(__file__).resolve().parents[1]
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
URDF = (ROOT / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf").read_text()
CONTROLLERS = {f"/{g}_controller/follow_joint_trajectory": NEXTAGE_OPEN.group(g).joint_names for g in NEXTAGE_OPEN.group_names}
GRIPPERS = {"left_arm": "/left_hand/gripper_cmd", "right_arm": "/right_hand/gripper_cmd"}
TOOL = "/left_tool/set"
TCP = "0 0 0 0 -1.5707963267948966 0"  # the Nextage simulator's TCP in the wrist link: the hand's axis
OPTIONS = [
    *(f"{g}.gripper={a}" for g, a in GRIPPERS.items()), *(f"{g}.tool={TCP}" for g in GRIPPERS),
    f"left_arm.tool_service={TOOL}", "camera_source=ros",
    "state_timeout=2",  # the machine the suite runs on is shared: a process may stall half a second (the check itself: test_ros2_control)
    "camera_timeout=5",  # an image comes within camera-sim's period (1 s) of the capture; the rest: a shared machine's stalls
]
BOUND = 240.0  # s the whole run may take on a loaded machine (49 s of motion, the dry run, the start)


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:
        yield claimed


def python(*args: str, env: dict[str, str], cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "execution_engine", *args], cwd=cwd, env={**base_env(), **env, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


def test_the_rivet_demonstrator_finishes_on_ros2_control_with_the_holes_found_in_published_images(env: dict[str, str], tmp_path: Path) -> None:
    def build(node: Node, clock: Clock) -> FakeDriver:
        return FakeDriver(node, clock, URDF, CONTROLLERS, NEXTAGE_OPEN.poses["initial"], grippers=tuple(GRIPPERS.values()), tools=(TOOL,))

    trace = tmp_path / "trace.jsonl"
    with driver_on_dds(env, build, BOUND) as driver:
        cameras = python("camera-sim", str(RIVET), "--camera", "left_hand_camera", "--camera", "right_hand_camera", "--rate", "1", env=env, cwd=tmp_path)
        try:
            options = [a for o in OPTIONS for a in ("--backend-option", o)]
            run = python("run", str(RIVET), "--robot", "ros2-control", *options, "--trace", str(trace),
                         "--trajectory-db", str(tmp_path / "trajectories.sqlite"), env=env, cwd=tmp_path)
            try:
                output, _ = run.communicate(timeout=BOUND)
            finally:
                stop_group(run)
        finally:
            cameras.send_signal(signal.SIGTERM)
            try:
                camera_output, _ = cameras.communicate(timeout=10.0)
            finally:
                stop_group(cameras)
    assert run.returncode == 0, output
    assert "dry run of rivet_installation on ros2-control: no problems found" in output
    assert "application rivet_installation: FINISHED" in output and "operations: 10/10" in output
    assert cameras.returncode == 0, camera_output  # a SIGTERM is an orderly stop
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    located = [e for e in events if e["event"] == "primitive_end" and e.get("result") and e["result"].get("kind") == "vision"]
    assert len(located) == 8  # each hole: before deburring and before inserting
    cell = load_application(RIVET, full_catalog()).cell
    assert cell is not None
    for event in located:
        report: dict[str, Any] = event["result"]["report"]
        assert report["method"] == "plane" and report["image_size"] == [640, 480]
        assert report["camera"] == {"left_arm": "left_hand_camera", "right_arm": "right_hand_camera"}[event["group"]]
        hole = re.search(r"locate (drill_\d)", event["primitive"]).group(1)  # type: ignore[union-attr]
        measured = report["measured"]
        assert math.dist((measured["x"], measured["y"], measured["z"]), cell.true_pose(hole).position) < 0.05e-3, hole
    limits = urdf_limits(URDF)
    assert driver.goals and all(g.outcome == "succeeded" for g in driver.goals)
    assert [bad for g in driver.goals for bad in moved_too_fast(g, limits)] == []
    assert all(limits[n][0] - 1e-9 <= v <= limits[n][1] + 1e-9 for g in driver.goals for p in g.points for n, v in zip(g.joints, p))
    assert driver.tool_calls == [(TOOL, True), (TOOL, False)] * 4
    assert len(driver.grips) == 1 + 4 * 3  # open at the start; per rivet: open, close, open to release

