"""Camera images on ROS topics: the simulator publishes when asked, a ROS camera back end locates from the topic.

The two back ends talk over the transport port exactly as over ROS 2 (the local transport here;
the message conversion through rosidl-shaped classes is checked below with the fake interface
packages): a locate fed from the image topic must give the very pose the in-process locate gives.
"""
from __future__ import annotations

import array
import asyncio

import numpy as np
import pytest
import ros_fake_msgs
from hypothesis import given, settings
from hypothesis import strategies as st

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from core_functions.primitives import MoveCartesian, Vision, VisionResult
from core_functions.vision.camera import Intrinsics
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import ByteBuffer, CameraInfo, Header, Image, Time
from node_transport.qos import SENSOR
from node_transport.ros_convert import MessageConverter
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.camera.ros_camera import attach_cameras, from_messages, to_messages
from robot_bridges.camera.sources import Frame
from robot_bridges.nextage_sim.backend import HAND_TOOL, NextageSimBackend
from robot_bridges.registry import create_backend
from test_vision_cameras import ROOT

APP = load_application(ROOT / "apps_xml" / "rivet_installation.xml", full_catalog())
CELL = APP.cell
assert CELL is not None


async def simulator(clock: Clock) -> NextageSimBackend:
    backend = NextageSimBackend(clock, tools={"left_arm": HAND_TOOL, "right_arm": HAND_TOOL})
    backend.set_cell(CELL.to_snapshot())
    await backend.execute("left_arm", MoveCartesian(CELL.pose("drill_1").offset_local(dz=-0.05), "ptp"))
    return backend


def locate() -> Vision:
    return Vision("locate", "drill_1", nominal=CELL.pose("drill_1"))


def test_a_locate_fed_from_the_image_topic_equals_the_in_process_one(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[VisionResult, VisionResult, list[Image], list[CameraInfo]]:
        transport = LocalTransport(clock)
        camera_node = transport.create_node("nextage_sim_bridge", parameters={"publish_images": True})
        robot_node = transport.create_node("cell_bridge", parameters={"camera_source": "ros"})
        spy = transport.create_node("spy")
        images: list[Image] = []
        infos: list[CameraInfo] = []
        spy.create_subscription(Image, "/left_hand_camera/image_raw", images.append, SENSOR)
        spy.create_subscription(CameraInfo, "/left_hand_camera/camera_info", infos.append, SENSOR)
        renderer, fed = await simulator(clock), await simulator(clock)
        assert attach_cameras(camera_node, renderer) is None
        assert attach_cameras(robot_node, fed) is not None
        waiting = asyncio.ensure_future(fed.execute("left_arm", locate()))
        await clock.sleep(0.01)
        in_process = await renderer.execute("left_arm", locate())
        from_topic = await waiting
        return in_process, from_topic, images, infos

    in_process, from_topic, images, infos = run_sim(main)
    assert from_topic.pose == in_process.pose and from_topic.score == in_process.score
    assert in_process.pose is not None and in_process.pose.distance_to(CELL.true_pose("drill_1")) < 0.05e-3
    assert len(images) == 1 and len(infos) == 1
    image, info = images[0], infos[0]
    assert (image.width, image.height, image.encoding, image.step, len(image.data)) == (640, 480, "mono8", 640, 640 * 480)
    assert image.header.frame_id == info.header.frame_id == "left_hand_camera_optical_frame"
    assert image.header.stamp == info.header.stamp and image.header.stamp.to_seconds() > 0
    assert info.k[0] == info.k[4] and info.k[8] == 1.0 and info.distortion_model == "plumb_bob"


def test_images_stay_in_the_process_unless_asked(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[int, int]:
        transport = LocalTransport(clock)
        node = transport.create_node("nextage_sim_bridge")
        images: list[Image] = []
        spy = transport.create_node("spy").create_subscription(Image, "/left_hand_camera/image_raw", images.append, SENSOR)
        backend = await simulator(clock)
        attach_cameras(node, backend)
        await backend.execute("left_arm", locate())
        return len(images), spy.get_publisher_count()

    assert run_sim(main) == (0, 0)


@pytest.mark.parametrize("setting", [{"camera_source": "ros"}, {"publish_images": True}])
def test_a_camera_setting_for_a_back_end_without_cameras_is_refused(setting: dict[str, object], run_sim) -> None:  # type: ignore[no-untyped-def]
    """Every bridge declares the camera parameters (one config for all); a back end without cameras refuses them."""

    async def main(clock: Clock) -> str:
        node = LocalTransport(clock).create_node("vplus_bridge", parameters=setting)
        with pytest.raises(ValueError) as refused:
            attach_cameras(node, object())
        return str(refused.value)

    assert run_sim(main) == "/vplus_bridge: this back end has no cameras; leave publish_images false and camera_source ''"


def test_no_image_on_the_topic_is_a_vision_fault_after_the_timeout(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[str, float]:
        transport = LocalTransport(clock)
        node = transport.create_node("cell_bridge", parameters={"camera_source": "ros", "camera_timeout": 0.5})
        backend = await simulator(clock)
        attach_cameras(node, backend)
        start = clock.now()
        with pytest.raises(BridgeError) as error:
            await backend.execute("left_arm", locate())
        assert error.value.kind is FaultKind.VISION
        return str(error.value), clock.now() - start

    message, waited = run_sim(main)
    assert "left_hand_camera: no image: no image on /left_hand_camera/image_raw within 0.5 s" in message
    assert 0.5 <= waited < 1.0


FRAME = Frame(np.arange(12 * 7, dtype=np.uint8).reshape(7, 12), Intrinsics(12, 7, 20.0, 21.0, 5.5, 3.0), 12.25)


def test_image_and_camera_info_cross_the_rosidl_conversion_unchanged() -> None:
    converter = MessageConverter(ros_fake_msgs.resolve)
    image, info = to_messages("cam", FRAME)
    ros_image, ros_info = converter.to_ros(image), converter.to_ros(info)
    assert isinstance(ros_image.data, array.array) and ros_image.data.typecode == "B"
    ros_info.k = np.array(ros_info.k, dtype=np.float64)  # rclpy holds fixed-size arrays as numpy arrays
    back_image, back_info = converter.from_ros(Image, ros_image), converter.from_ros(CameraInfo, ros_info)
    assert back_image == image and back_info == info and isinstance(back_image.data, ByteBuffer)
    frame = from_messages(back_image, back_info)
    assert np.array_equal(frame.image, FRAME.image) and frame.intrinsics == FRAME.intrinsics and frame.stamp == 12.25


@pytest.mark.parametrize(("encoding", "channels", "dtype"), [("bgr8", 3, np.uint8), ("rgba8", 4, np.uint8), ("mono16", 1, np.uint16)])
def test_colour_and_16_bit_images_become_mono(encoding: str, channels: int, dtype: type) -> None:
    _, info = to_messages("cam", FRAME)
    scale = 257 if dtype is np.uint16 else 1
    pixels = np.repeat((FRAME.image.astype(np.uint32) * scale).astype(dtype)[:, :, None], channels, axis=2)
    padded = np.zeros((7, 12 * channels * np.dtype(dtype).itemsize + 8), np.uint8)  # rows padded: step > width
    padded[:, : 12 * channels * np.dtype(dtype).itemsize] = pixels.reshape(7, -1).view(np.uint8)
    msg = Image(Header(Time(1, 0)), 7, 12, encoding, 0, padded.shape[1], ByteBuffer(padded.tobytes()))
    assert np.array_equal(from_messages(msg, info).image, FRAME.image)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"encoding": "yuv422"}, "image encoding 'yuv422' is not supported"),
        ({"data": ByteBuffer(b"\0" * 10)}, "step 12 and 10 bytes of data do not hold it"),
        ({"width": 11, "step": 11}, "camera_info is for 12x7 images, the image is 11x7"),
        ({"height": 0}, "image size 12x0 is empty"),
    ],
)
def test_images_that_do_not_make_an_image_are_refused_in_one_line(change: dict[str, object], message: str) -> None:
    image, info = to_messages("cam", FRAME)
    fields = {**image.__dict__, **change}
    with pytest.raises(ValueError, match=message):
        from_messages(Image(**fields), info)  # type: ignore[arg-type]


def test_a_distorted_camera_info_asks_for_the_rectified_image() -> None:
    image, info = to_messages("cam", FRAME)
    with pytest.raises(ValueError, match="subscribe to the rectified image"):
        from_messages(image, CameraInfo(**{**info.__dict__, "d": (0.1, 0.0, 0.0, 0.0, 0.0)}))  # type: ignore[arg-type]


@settings(max_examples=60, deadline=None)
@given(
    height=st.integers(0, 40), width=st.integers(0, 40), step=st.integers(0, 200), size=st.integers(0, 3000),
    encoding=st.sampled_from(["mono8", "bgr8", "mono16", "rgba8", "x"]), big=st.integers(0, 1),
)
def test_random_image_messages_give_an_image_or_a_value_error(height: int, width: int, step: int, size: int, encoding: str, big: int) -> None:
    msg = Image(Header(), height, width, encoding, big, step, ByteBuffer(bytes(size)))
    info = CameraInfo(Header(), height, width, "plumb_bob", (), (10.0, 0.0, 1.0, 0.0, 10.0, 1.0, 0.0, 0.0, 1.0))
    try:
        frame = from_messages(msg, info)
    except ValueError:
        return
    assert frame.image.shape == (height, width) and frame.image.dtype == np.uint8


def test_the_bridge_publishes_every_image_of_the_demonstrator_when_asked(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[bool, dict[str, int]]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=APP.robot))
        deployment = await deploy_local(clock, APP.robot, backend, machine_parameters={"trajectory_db": ":memory:"}, bridge_parameters={"publish_images": True})
        counts = {"left_hand_camera": 0, "right_hand_camera": 0}
        spy = deployment.transport.create_node("spy")
        for camera in counts:
            spy.create_subscription(Image, f"/{camera}/image_raw", lambda m, c=camera: counts.__setitem__(c, counts[c] + 1), SENSOR)
        try:
            report = await deployment.engine.run(APP)
        finally:
            await deployment.close()
        return report.ok, counts

    ok, counts = run_sim(main)
    assert ok and counts == {"left_hand_camera": 4, "right_hand_camera": 4}  # one image per locate
