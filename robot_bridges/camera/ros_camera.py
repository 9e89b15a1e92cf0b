"""Cameras on ROS topics: publishing what the simulator's cameras take, and taking images from any camera driver.

Images stay in the process that takes them unless asked: with the bridge parameter
``publish_images`` the back end's cameras publish every image they take on
``<camera>/image_raw`` (``sensor_msgs/Image``, mono8) with its ``<camera>/camera_info``
(``sensor_msgs/CameraInfo``), stamped with the capture time, frame ``<camera>_optical_frame``.
With ``camera_source:=ros`` the back end's cameras are those topics instead: a capture waits for
the next image arriving on ``<camera>/image_raw`` (remap it to a driver's rectified image, e.g.
``image_rect``), takes the intrinsics from the latest ``camera_info`` and fails with a VISION
fault when nothing comes within ``camera_timeout`` seconds.  Relative names, so namespaces and
remapping apply as usual; sensor-data QoS (best effort, as camera drivers publish).
"""
from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Iterable, Mapping
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from node_transport.clock import Clock
from node_transport.msgs import ByteBuffer, CameraInfo, Header, Image, RegionOfInterest, Time
from node_transport.bounded import declare_bounded
from node_transport.port import Node, Publisher
from node_transport.qos import SENSOR
from robot_bridges.camera.sources import CameraSource, CaptureError, Frame
from robot_bridges.camera.spec import CameraSpec
from robot_bridges.camera.vision import CameraVision

#: Encodings a ROS camera may deliver: (numpy type, channels, OpenCV conversion to mono or None).
ENCODINGS: dict[str, tuple[type, int, int | None]] = {
    "mono8": (np.uint8, 1, None),
    "8UC1": (np.uint8, 1, None),
    "mono16": (np.uint16, 1, None),
    "16UC1": (np.uint16, 1, None),
    "bgr8": (np.uint8, 3, cv2.COLOR_BGR2GRAY),
    "rgb8": (np.uint8, 3, cv2.COLOR_RGB2GRAY),
    "bgra8": (np.uint8, 4, cv2.COLOR_BGRA2GRAY),
    "rgba8": (np.uint8, 4, cv2.COLOR_RGBA2GRAY),
}
#: Largest image accepted from a topic (pixels): input from another process is bounded.
MAX_PIXELS = 64_000_000


def image_topic(camera: str) -> str:
    return f"{camera}/image_raw"


def info_topic(camera: str) -> str:
    return f"{camera}/camera_info"


def optical_frame(camera: str) -> str:
    return f"{camera}_optical_frame"


def to_messages(camera: str, frame: Frame) -> tuple[Image, CameraInfo]:
    """A mono8 image and its camera_info (undistorted: plumb_bob with zero coefficients)."""
    image = np.ascontiguousarray(frame.image, dtype=np.uint8)
    height, width = image.shape
    header = Header(Time.from_seconds(frame.stamp), optical_frame(camera))
    i = frame.intrinsics
    k = (i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0)
    p = (i.fx, 0.0, i.cx, 0.0, 0.0, i.fy, i.cy, 0.0, 0.0, 0.0, 1.0, 0.0)
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    msg = Image(header, height, width, "mono8", 0, width, ByteBuffer(image.tobytes()))
    info = CameraInfo(header, height, width, "plumb_bob", (0.0,) * 5, k, identity, p, 0, 0, RegionOfInterest())
    return msg, info


def intrinsics_of(info: CameraInfo) -> Intrinsics:
    """The pinhole parameters of a camera_info (K); ValueError naming what is wrong."""
    if len(info.k) != 9:
        raise ValueError(f"camera_info K has {len(info.k)} values, not 9")
    if any(abs(c) > 1e-9 for c in info.d):
        raise ValueError("camera_info has distortion coefficients: subscribe to the rectified image (image_rect) and its camera_info")
    return Intrinsics(int(info.width), int(info.height), float(info.k[0]), float(info.k[4]), float(info.k[2]), float(info.k[5]))


def from_messages(image: Image, info: CameraInfo) -> Frame:
    """The mono image and intrinsics of a received pair; ValueError (one line) when they do not make an image."""
    encoding = ENCODINGS.get(image.encoding)
    if encoding is None:
        raise ValueError(f"image encoding {image.encoding!r} is not supported (supported: {', '.join(ENCODINGS)})")
    dtype, channels, conversion = encoding
    height, width, step = int(image.height), int(image.width), int(image.step)
    if not (0 < height and 0 < width and height * width <= MAX_PIXELS):
        raise ValueError(f"image size {width}x{height} is empty or larger than {MAX_PIXELS} pixels")
    item = np.dtype(dtype).itemsize
    if step < width * channels * item or len(image.data) < step * height:
        raise ValueError(f"image of {width}x{height} {image.encoding}: step {step} and {len(image.data)} bytes of data do not hold it")
    if (int(info.width), int(info.height)) != (width, height):
        raise ValueError(f"camera_info is for {info.width}x{info.height} images, the image is {width}x{height}")
    rows = np.frombuffer(image.data, dtype=np.uint8, count=step * height).reshape(height, step)
    pixels = rows[:, : width * channels * item].copy().view(np.dtype(dtype).newbyteorder(">" if image.is_bigendian else "<"))
    pixels = pixels.reshape(height, width, channels) if channels > 1 else pixels.reshape(height, width)
    mono: NDArray[Any] = cv2.cvtColor(pixels, conversion) if conversion is not None else pixels
    if mono.dtype != np.uint8:
        mono = (mono.astype(np.uint32) >> 8).astype(np.uint8)
    return Frame(np.ascontiguousarray(mono), intrinsics_of(info), Time(image.header.stamp.sec, image.header.stamp.nanosec).to_seconds())


class ImagePublisher:
    """The capture hook that publishes every image taken, with its camera_info."""

    def __init__(self, node: Node, cameras: Iterable[str] | Mapping[str, str], named: Mapping[str, str] | None = None) -> None:
        topics = dict(cameras) if isinstance(cameras, Mapping) else {c: c for c in cameras}  # camera -> its topic prefix
        #: camera -> the name its images' frame_id is made of (a cell's robot: the cell's name of the camera)
        self._named = dict(named or {})
        self._pubs: dict[str, tuple[Publisher[Image], Publisher[CameraInfo]]] = {
            c: (node.create_publisher(Image, image_topic(t), SENSOR), node.create_publisher(CameraInfo, info_topic(t), SENSOR)) for c, t in topics.items()
        }

    def __call__(self, spec: CameraSpec, pose: Pose, frame: Frame) -> None:
        pubs = self._pubs.get(spec.name)
        if pubs is None:
            return
        image, info = to_messages(self._named.get(spec.name, spec.name), frame)
        pubs[1].publish(info)
        pubs[0].publish(image)


class RosCamera(CameraSource):
    """Images from ``<camera>/image_raw`` + ``<camera>/camera_info`` topics (a real camera driver, or a simulator publishing).

    ``cameras`` maps each camera to its topic prefix (default: its name).  With ``fresh`` an image
    stamped before the capture was asked for is skipped: it may have been exposed while the arm was
    still on its way (an unstamped image, stamp 0, is taken)."""

    def __init__(self, node: Node, cameras: Iterable[str] | Mapping[str, str], timeout: float = 2.0, fresh: bool = False) -> None:
        if not timeout > 0:
            raise ValueError(f"camera_timeout must be > 0 s, got {timeout}")
        self.node = node
        self.clock: Clock = node.clock
        self.timeout = timeout
        self.fresh = fresh
        self.topics = dict(cameras) if isinstance(cameras, Mapping) else {c: c for c in cameras}
        self._info: dict[str, CameraInfo] = {}
        self._waiting: dict[str, deque[tuple[asyncio.Future[Image], float]]] = {}
        self.rejected: list[str] = []
        for camera, prefix in self.topics.items():
            self._waiting[camera] = deque()
            node.create_subscription(Image, image_topic(prefix), lambda m, c=camera: self._on_image(c, m), SENSOR)
            node.create_subscription(CameraInfo, info_topic(prefix), lambda m, c=camera: self._info.__setitem__(c, m), SENSOR)

    def _on_image(self, camera: str, msg: Image) -> None:
        waiting = self._waiting[camera]
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for entry in list(waiting):
            future, not_before = entry
            if future.done() or stamp == 0.0 or stamp >= not_before:
                waiting.remove(entry)
                if not future.done():
                    future.set_result(msg)

    async def capture(self, spec: CameraSpec, pose: Pose) -> Frame:
        waiting = self._waiting.get(spec.name)
        if waiting is None:
            raise CaptureError(f"no image topic for camera {spec.name!r} (cameras: {', '.join(self._waiting)})")
        prefix = self.topics[spec.name]
        topic = self.node.resolve(image_topic(prefix))
        future: asyncio.Future[Image] = asyncio.get_running_loop().create_future()
        waiting.append((future, self.node.now_stamp().to_seconds() if self.fresh else -math.inf))
        try:
            image = await self.clock.wait_for(future, self.timeout)
        except asyncio.TimeoutError:
            raise CaptureError(f"no image on {topic} within {self.timeout:g} s{' stamped after the capture was asked for' if self.fresh else ''}") from None
        finally:
            for entry in [e for e in waiting if e[0] is future]:
                waiting.remove(entry)
        info = self._info.get(spec.name)
        if info is None:
            raise CaptureError(f"an image on {topic} but no camera_info on {self.node.resolve(info_topic(prefix))}")
        try:
            return from_messages(image, info)
        except ValueError as error:
            raise CaptureError(f"{topic}: {error}") from None


def attach_cameras(node: Node, backend: object) -> RosCamera | None:
    """Declare the camera parameters on a bridge node and wire them to the back end's cameras, if it has any.

    Every bridge declares them, cameras or not, so that one parameter file describes every bridge
    and a camera setting given to a back end without cameras is refused rather than ignored."""
    publish = bool(node.declare_parameter("publish_images", False, "publish every image the cameras take on <camera>/image_raw and <camera>/camera_info"))
    source = str(node.declare_parameter("camera_source", "", "'' = the back end's own cameras (the simulator renders the cell); 'ros' = <camera>/image_raw + camera_info topics"))
    timeout = float(declare_bounded(node, "camera_timeout", 2.0, "longest wait for an image from a ROS camera (s)"))
    if source not in ("", "ros"):
        raise ValueError(f"{node.fully_qualified_name}: camera_source must be '' or 'ros', got {source!r}")
    cameras = getattr(backend, "cameras", None)
    if not isinstance(cameras, CameraVision) or not cameras.specs:
        if source or publish:
            raise ValueError(f"{node.fully_qualified_name}: this back end has no cameras; leave publish_images false and camera_source ''")
        return None
    # a robot of a cell of several names its cameras for the cell (robot_bridges.placed: viper_tool_camera), so two
    # robots' tool_camera publish and subscribe apart; a robot of its own keeps the cameras' own names
    cell_camera = getattr(backend, "cell_camera", None)
    names = {c: cell_camera(c) if callable(cell_camera) else c for c in cameras.specs}
    ros = None
    if source == "ros":
        ros = RosCamera(node, names, timeout)
        cameras.use_source(ros)
    if publish:
        cameras.on_capture = ImagePublisher(node, names, names)
    return ros

