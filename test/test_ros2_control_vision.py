"""The ros2-control back end's cameras and tool (issue 23), in simulated time against fake_fjt_server.py's Nextage.

What a user relies on: with ``camera_source=ros`` a vision call takes the next image on the camera's topic
(remappable per camera), stamped after it asked, and fails with a VISION fault naming the topic within
``camera_timeout`` when none comes; the dry run renders the cell instead, so the rivet demonstrator passes
``validate --simulate`` only with both its cameras and its tool configured; ``tool_on``/``tool_off`` are one
std_srvs/SetBool call each, the driver's refusal a fault in its words; bad options are one line naming them.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

from numpy.typing import NDArray

import numpy as np
import pytest
from fake_fjt_server import FakeDriver, urdf_limits

from app_functions.registry import full_catalog
from cell_runner.dry_run.runner import dry_run
from core_functions.geometry import Pose
from core_functions.primitives import EndEffector, Vision
from core_functions.robots import KUKA_KR, NEXTAGE_OPEN
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import CameraInfo, Header, Image, JointState, Time
from node_transport.qos import JOINT_STATES, SENSOR
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.camera.render import MAX_BLUR, render
from robot_bridges.camera.ros_camera import RosCamera, to_messages
from robot_bridges.camera.scene import build_scene
from robot_bridges.camera.sources import Frame
from robot_bridges.camera.spec import CameraSpec
from robot_bridges.registry import check_options
from robot_bridges.ros2_control.backend import SETTLE_TIME, Ros2ControlBackend
from robot_bridges.ros2_control.link import GraphLink
from robot_bridges.ros2_control.options import parse_options

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
ROOT = Path(__file__).resolve().parents[1]
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
URDF_FILE = ROOT / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf"
CONTROLLERS = {f"/{g}_controller/follow_joint_trajectory": NEXTAGE_OPEN.group(g).joint_names for g in NEXTAGE_OPEN.group_names}
TCP = "0 0 0 0 -1.5707963267948966 0"
HANDS = {"left_arm.gripper": "/left_hand/gripper_cmd", "right_arm.gripper": "/right_hand/gripper_cmd", "left_arm.tool": TCP, "right_arm.tool": TCP}


async def nextage(clock: Clock, extra: dict[str, str], tools: tuple[str, ...] = ()) -> tuple[LocalTransport, FakeDriver, Ros2ControlBackend]:
    """The fake Nextage driver and a back end wired as the factory wires it on a graph (RosCamera, fresh images only)."""
    graph = LocalTransport(clock)
    driver = FakeDriver(graph.create_node("controller_manager"), clock, URDF_FILE.read_text(), CONTROLLERS, NEXTAGE_OPEN.poses["initial"], tools=tools)
    settings = parse_options(BackendOptions(robot=NEXTAGE_OPEN, extra=extra))
    link = GraphLink(graph.create_node("ros2_control_client"), settings)
    backend = Ros2ControlBackend(clock, NEXTAGE_OPEN, settings, link)
    if settings.camera_source == "ros":
        backend.use_cameras(RosCamera(link.node, settings.camera_topics, settings.camera_timeout, fresh=True))
    await backend.start()
    app = load_application(RIVET, full_catalog())
    assert app.cell is not None
    backend.set_cell(app.cell.to_snapshot(app.robot))
    return graph, driver, backend


def test_no_image_on_the_camera_topic_is_a_vision_fault_naming_the_topic_after_camera_timeout(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[BridgeError, float]:
        graph, driver, backend = await nextage(clock, {"camera_source": "ros", "camera_timeout": "0.5", "left_hand_camera.topic": "/cell/left_cam"})
        try:
            begin = clock.now()
            with pytest.raises(BridgeError) as caught:
                await backend.execute("left_arm", Vision("locate", "drill_1"))
            return caught.value, clock.now() - begin
        finally:
            await driver.close()
            await graph.shutdown()

    error, waited = run_sim(main)
    assert error.kind is FaultKind.VISION and "no image on /cell/left_cam/image_raw within 0.5 s" in str(error)
    assert 0.5 <= waited - SETTLE_TIME < 0.6  # the arm kept still for SETTLE_TIME first, then camera_timeout


def test_an_image_taken_before_the_request_is_skipped_and_the_next_one_is_used(run_sim: Run) -> None:
    """A frame exposed while the arm was still on its way (stamped before the capture) must not place a hole."""
    async def main(clock: Clock) -> tuple[BridgeError, list[float], float]:
        graph, driver, backend = await nextage(clock, {"camera_source": "ros", "camera_timeout": "0.5"})
        spec = backend.settings.cameras.specs["left_hand_camera"]  # type: ignore[union-attr]
        node = graph.create_node("camera")
        image_pub = node.create_publisher(Image, "left_hand_camera/image_raw", SENSOR)
        info_pub = node.create_publisher(CameraInfo, "left_hand_camera/camera_info", SENSOR)
        seen: list[float] = []
        backend.cameras.on_capture = lambda s, p, frame: seen.append(frame.stamp)  # type: ignore[union-attr]
        asked = clock.epoch_now()

        async def camera() -> None:
            await clock.sleep(SETTLE_TIME + 0.2)  # the back end waits for the arm to keep still, then asks
            for stamp in (asked - 1.0, clock.epoch_now()):  # an old frame first, then one taken now
                image, info = to_messages("left_hand_camera", Frame(blank(spec), spec.intrinsics, stamp))
                info_pub.publish(info)
                image_pub.publish(image)
                await clock.sleep(0.05)

        task = asyncio.ensure_future(camera())
        try:
            with pytest.raises(BridgeError) as caught:  # a blank image: no hole in it, but it is the fresh one
                await backend.execute("left_arm", Vision("locate", "drill_1"))
            await task
            return caught.value, seen, asked
        finally:
            await driver.close()
            await graph.shutdown()

    error, seen, asked = run_sim(main)
    assert error.kind is FaultKind.VISION and "no image" not in str(error)
    assert len(seen) == 1 and seen[0] >= asked  # the old frame was not taken


def blank(spec: CameraSpec) -> NDArray[np.uint8]:
    return np.full((spec.intrinsics.height, spec.intrinsics.width), 128, np.uint8)


def test_the_tool_is_one_setbool_call_and_a_refusal_is_a_fault_in_the_drivers_words(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[str, bool]], BridgeError]:
        graph, driver, backend = await nextage(clock, {"left_arm.tool_service": "/left_tool/set"}, tools=("/left_tool/set",))
        try:
            await backend.execute("left_arm", EndEffector("tool_on"))
            await backend.execute("left_arm", EndEffector("tool_off"))
            driver.tool_refusal = "spindle interlock open"
            with pytest.raises(BridgeError) as caught:
                await backend.execute("left_arm", EndEffector("tool_on"))
            return list(driver.tool_calls), caught.value
        finally:
            await driver.close()
            await graph.shutdown()

    calls, error = run_sim(main)
    assert calls == [("/left_tool/set", True), ("/left_tool/set", False), ("/left_tool/set", True)]
    assert error.kind is FaultKind.CONTROLLER and str(error) == "controller: left_arm: /left_tool/set refused the tool on: spindle interlock open"


def test_the_dry_run_renders_the_cameras_and_needs_the_tool_service() -> None:
    app = load_application(RIVET, full_catalog())
    base = {"urdf": str(URDF_FILE), "transport": "model", **HANDS}
    without = dry_run(app, "ros2-control", BackendOptions(robot=NEXTAGE_OPEN, extra={**base, "camera_source": "ros"}))
    assert {f.kind for f in without.findings} == {"unsupported"}
    assert all("tool_on" in f.message or "tool_off" in f.message for f in without.findings)
    assert any("left_arm.tool_service=NAME" in f.message for f in without.findings)
    blind = dry_run(app, "ros2-control", BackendOptions(robot=NEXTAGE_OPEN, extra={**base, "left_arm.tool_service": "/left_tool/set"}))
    assert any("vision(locate drill_1) is not available on this robot: no cameras" in f.message for f in blind.findings)
    full = dry_run(app, "ros2-control", BackendOptions(robot=NEXTAGE_OPEN, extra={**base, "camera_source": "ros", "left_arm.tool_service": "/left_tool/set"}))
    assert list(full.findings) == [] and full.cycle_time > 10.0


@pytest.mark.parametrize(("robot", "extra", "message"), [
    (NEXTAGE_OPEN, {"camera_source": "usb"}, "ros2-control: camera_source='usb' must be ros"),
    (NEXTAGE_OPEN, {"left_hand_camera.topic": "/cam"}, "ros2-control: left_hand_camera.topic needs camera_source=ros"),
    (NEXTAGE_OPEN, {"camera_source": "ros", "left_hand_camera.topic": "/cam/"}, "ros2-control: left_hand_camera.topic='/cam/' is not a topic prefix"),
    (NEXTAGE_OPEN, {"camera_source": "ros", "left_hand_camera.mount": "1 2 3"}, "ros2-control: left_hand_camera.mount: six numbers x y z roll pitch yaw"),
    (NEXTAGE_OPEN, {"camera_source": "ros", "camera_timeout": "0"}, "ros2-control: camera_timeout must be a number in [0.01, 600] s, got '0'"),
    (NEXTAGE_OPEN, {"left_arm.tool_service": "/left tool"}, "ros2-control: left_arm.tool_service='/left tool' is not a service name"),
    (KUKA_KR, {"camera_source": "ros"}, "ros2-control: camera_source=ros: no camera model of robot kuka_kr"),
])
def test_a_bad_camera_or_tool_option_is_one_line_naming_it(robot: Any, extra: dict[str, str], message: str) -> None:
    with pytest.raises(ValueError) as caught:
        check_options("ros2-control", BackendOptions(robot=robot, extra=extra), 1.0)
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)


def test_a_camera_swept_against_the_part_draws_its_image_with_a_bounded_blur() -> None:
    """camera-sim draws the hand cameras at every pose of a motion: 10 um above a part asked the renderer for a blur of
    millions of pixels (a kernel of gigabytes, minutes); the blur is capped where the image is a uniform grey anyway."""
    app = load_application(RIVET, full_catalog())
    assert app.cell is not None
    cell = app.cell.to_snapshot(app.robot)
    spec = parse_options(BackendOptions(robot=NEXTAGE_OPEN, extra={"camera_source": "ros"})).cameras.specs["left_hand_camera"]  # type: ignore[union-attr]
    assert float(spec.optics.blur_sigma(spec.intrinsics, 1e-9)) == MAX_BLUR
    touching = cell.truth["drill_1"].compose(Pose.from_xyz_rpy(0.0, 0.0, -1e-5, 0.0, 0.0, 0.0))
    image = render(build_scene(cell.frames, cell.elements, cell.truth), spec.intrinsics, touching.matrix(), spec.optics, np.random.default_rng(0))
    assert image.shape == (480, 640)


def test_a_backlog_of_joint_states_is_read_whole_not_as_a_jump(run_sim: Run) -> None:
    """A process that falls behind (a loaded machine, images decoded beside the states) gets half a second of
    joint_state_broadcaster's 100 Hz at once: every sample must come through, or two far apart look like a jump."""
    async def main(clock: Clock) -> tuple[str | None, int]:
        graph, driver, backend = await nextage(clock, {})
        driver.states_on = False
        publisher = graph.create_node("broadcaster").create_publisher(JointState, "/joint_states", JOINT_STATES)
        names = tuple(driver.positions)
        start, counted = clock.epoch_now(), backend.link.feed.count
        speed = urdf_limits(URDF_FILE.read_text())["RARM_JOINT2"][2]
        for k in range(1, 51):  # 0.5 s of samples published while the back end's loop does not run
            at = {**driver.positions, "RARM_JOINT2": driver.positions["RARM_JOINT2"] - 0.9 * speed * 0.01 * k}
            publisher.publish(JointState(Header(stamp=Time.from_seconds(start + 0.01 * k)), names, tuple(at[n] for n in names)))
        await clock.sleep(0.05)
        try:
            return backend.link.feed.fault, backend.link.feed.count - counted
        finally:
            await driver.close()
            await graph.shutdown()

    fault, samples = run_sim(main)
    assert fault is None and samples == 50
