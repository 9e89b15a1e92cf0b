"""A robot's cameras carry its cell prefix, as its joints do (issue 23 item 4): the side_by_side cell's KUKA and Viper
both call their camera ``tool_camera``; the cell lists ``kuka_tool_camera`` and ``viper_tool_camera``, a vision call
names the one it means, the robot's back end is asked for its own, and its images go out on the cell's name.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app_functions.registry import full_catalog
from core_functions.cell_robots import CellNames
from core_functions.geometry import Pose
from core_functions.primitives import MoveCartesian, Vision, VisionResult
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import load_application, validate_application
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import Image
from node_transport.qos import SENSOR
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.camera.ros_camera import attach_cameras
from robot_bridges.nextage_sim.backend import HAND_TOOL, NextageSimBackend
from robot_bridges.placed import PlacedBackend

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "apps_xml" / "examples" / "side_by_side.xml"
CELL_FILE = ROOT / "apps_xml" / "examples" / "cells" / "side_by_side_cell.xml"
RIVETS = load_application(ROOT / "apps_xml" / "rivet_installation.xml", full_catalog()).cell
assert RIVETS is not None


def test_the_side_by_side_cell_lists_each_robot_s_camera_under_its_prefix() -> None:
    robot = load_application(EXAMPLE, full_catalog()).robot
    assert robot.cameras == ("kuka_tool_camera", "viper_tool_camera")
    assert robot.group("kuka_arm").camera == "kuka_tool_camera" and robot.group("inspector").camera == "viper_tool_camera"


def _locate(tmp_path: Path, camera: str) -> list[str]:
    app = tmp_path / "look.xml"
    app.write_text(f'<?xml version="1.0"?>\n<application name="look" robot="cell" cell="{CELL_FILE}">\n'
                   '  <operation id="1"><inspector><function name="locate"><params><param value="buffer_slot"/>'
                   f'<param value="{camera}"/></params></function></inspector></operation>\n</application>\n', encoding="utf-8")
    return [f"{d.line}: {d.message}" for d in validate_application(app, full_catalog())]


def test_a_vision_call_names_a_camera_by_the_cell_s_name(tmp_path: Path) -> None:
    assert _locate(tmp_path, "viper_tool_camera") == []
    assert _locate(tmp_path, "auto") == []
    refused = _locate(tmp_path, "tool_camera")
    assert len(refused) == 1 and "'tool_camera' is not a camera of" in refused[0], refused
    assert "cameras: kuka_tool_camera, viper_tool_camera, or auto" in refused[0], refused


async def _nextage(clock: Clock) -> NextageSimBackend:
    backend = NextageSimBackend(clock, tools={"left_arm": HAND_TOOL, "right_arm": HAND_TOOL})
    backend.set_cell(RIVETS.to_snapshot())
    await backend.execute("left_arm", MoveCartesian(RIVETS.pose("drill_1").offset_local(dz=-0.05), "ptp"))
    return backend


def test_each_robot_s_vision_call_takes_its_own_camera_and_publishes_under_the_cell_s_name(run_sim: Any) -> None:
    """Two Nextages (every camera name the same) prefixed w_ and e_, each bridge publishing its images: a locate on
    each robot's left arm through its placed back end, naming its camera by the cell's name, is done by that robot's
    own left_hand_camera (a camera of another robot's prefix is not one of its own: refused), reported under the
    cell's name, and its image goes out on /<prefix>left_hand_camera/image_raw, framed by the same name."""

    async def main(clock: Clock) -> dict[str, Any]:
        bus = LocalTransport(clock)
        spy = bus.create_node("spy")
        images: dict[str, list[Image]] = {}
        for topic in ("w_left_hand_camera", "e_left_hand_camera", "left_hand_camera"):
            images[topic] = []
            spy.create_subscription(Image, f"/{topic}/image_raw", images[topic].append, SENSOR)
        robots = {prefix: PlacedBackend(await _nextage(clock), Pose(), name, CellNames(prefix), NEXTAGE_OPEN.cameras)
                  for prefix, name in (("w_", "west"), ("e_", "east"))}
        for prefix, robot in robots.items():
            attach_cameras(bus.create_node(f"{prefix}bridge", parameters={"publish_images": True}), robot)
        results: dict[str, VisionResult] = {}
        for prefix, robot in robots.items():
            result = await robot.execute(f"{prefix}left_arm", Vision("locate", "drill_1", nominal=RIVETS.pose("drill_1"), camera=f"{prefix}left_hand_camera"))
            assert isinstance(result, VisionResult)
            results[prefix] = result
            await clock.sleep(0.05)
        with pytest.raises(BridgeError) as stranger:
            await robots["w_"].execute("w_left_arm", Vision("locate", "drill_1", nominal=RIVETS.pose("drill_1"), camera="e_left_hand_camera"))
        return {"results": results, "images": images, "stranger": stranger.value}

    got = run_sim(main)
    for prefix in ("w_", "e_"):
        result = got["results"][prefix]
        assert result.report is not None and result.report.camera == f"{prefix}left_hand_camera"
        assert result.pose is not None and result.pose.distance_to(RIVETS.true_pose("drill_1")) < 0.05e-3
        published = got["images"][f"{prefix}left_hand_camera"]
        assert len(published) == 1 and published[0].header.frame_id == f"{prefix}left_hand_camera_optical_frame"
    assert got["images"]["left_hand_camera"] == []  # no robot of the cell publishes under the model's own name
    stranger = got["stranger"]
    assert stranger.kind is FaultKind.VISION, stranger
    assert stranger.detail == ("no camera 'e_left_hand_camera' (cameras: w_head_camera, w_head_camera_left, w_head_camera_right, "
                               "w_left_hand_camera, w_right_hand_camera)")  # the cell's names of the robot's own cameras
