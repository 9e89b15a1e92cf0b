"""Python mirrors of the few ROS 2 common_interfaces types the project uses.

The core never imports rclpy, yet its nodes must speak exactly what ROS 2 nodes speak.  Each
mirror names its ROS type (``ROS_TYPE``) and holds the same fields with the same meaning, so the
rclpy adapter converts field by field and the in-process transport passes the frozen objects
themselves.  The mirrors of the project's own types are generated from their .msg files
(:mod:`node_transport.mirrors`, :mod:`node_transport.typed`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar


@dataclass(frozen=True)
class Time:
    """builtin_interfaces/Time, as seconds since the node's clock origin."""

    ROS_TYPE: ClassVar[str] = "builtin_interfaces/msg/Time"
    sec: int = 0
    nanosec: int = 0

    @staticmethod
    def from_seconds(seconds: float) -> Time:
        whole = math.floor(seconds)
        nanosec = int(round((seconds - whole) * 1e9))
        if nanosec == 1_000_000_000:  # 2.9999999999 s is 3 s, not 2 s
            whole, nanosec = whole + 1, 0
        return Time(int(whole), nanosec)

    def to_seconds(self) -> float:
        return self.sec + self.nanosec * 1e-9


@dataclass(frozen=True)
class ClockMessage:
    """rosgraph_msgs/Clock: the simulator's time on ``/clock`` for nodes with ``use_sim_time``."""

    ROS_TYPE: ClassVar[str] = "rosgraph_msgs/msg/Clock"
    clock: Time = field(default_factory=Time)


@dataclass(frozen=True)
class Header:
    """std_msgs/Header."""

    ROS_TYPE: ClassVar[str] = "std_msgs/msg/Header"
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass(frozen=True)
class String:
    """std_msgs/String: the carrier of every JSON message of the project."""

    ROS_TYPE: ClassVar[str] = "std_msgs/msg/String"
    data: str = ""


@dataclass(frozen=True)
class Bool:
    """std_msgs/Bool (the cell safety stop)."""

    ROS_TYPE: ClassVar[str] = "std_msgs/msg/Bool"
    data: bool = False


@dataclass(frozen=True)
class JointState:
    """sensor_msgs/JointState: positions in rad, velocities in rad/s (REP 103)."""

    ROS_TYPE: ClassVar[str] = "sensor_msgs/msg/JointState"
    header: Header = field(default_factory=Header)
    name: tuple[str, ...] = ()
    position: tuple[float, ...] = ()
    velocity: tuple[float, ...] = ()
    effort: tuple[float, ...] = ()


@dataclass(frozen=True)
class Point:
    """geometry_msgs/Point in metres."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/Point"
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(frozen=True)
class Quaternion:
    """geometry_msgs/Quaternion (x, y, z, w)."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/Quaternion"
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass(frozen=True)
class Pose:
    """geometry_msgs/Pose."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/Pose"
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass(frozen=True)
class PoseStamped:
    """geometry_msgs/PoseStamped (a group's TCP pose)."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/PoseStamped"
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass(frozen=True)
class Vector3:
    """geometry_msgs/Vector3: a translation in metres (a transform's ``translation``)."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/Vector3"
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(frozen=True)
class Transform:
    """geometry_msgs/Transform: where a child frame is in its parent (m; rotation x y z w)."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/Transform"
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass(frozen=True)
class TransformStamped:
    """geometry_msgs/TransformStamped: ``header.frame_id`` is the parent, ``child_frame_id`` the child."""

    ROS_TYPE: ClassVar[str] = "geometry_msgs/msg/TransformStamped"
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass(frozen=True)
class TFMessage:
    """tf2_msgs/TFMessage: what ``tf`` and ``tf_static`` carry (RViz, Foxglove and tf2 read them)."""

    ROS_TYPE: ClassVar[str] = "tf2_msgs/msg/TFMessage"
    transforms: tuple[TransformStamped, ...] = ()


@dataclass(frozen=True)
class KeyValue:
    """diagnostic_msgs/KeyValue: one named value of a diagnostic status."""

    ROS_TYPE: ClassVar[str] = "diagnostic_msgs/msg/KeyValue"
    key: str = ""
    value: str = ""


@dataclass(frozen=True)
class DiagnosticStatus:
    """diagnostic_msgs/DiagnosticStatus.

    ``level`` is a ROS ``byte``, which rosidl's Python classes hold as ``bytes`` of length 1
    (``DiagnosticStatus.OK == b'\\x00'``) and whose setter refuses an ``int``; the mirror keeps
    that shape so a level travels unchanged, and names the constants as rosidl does.
    """

    ROS_TYPE: ClassVar[str] = "diagnostic_msgs/msg/DiagnosticStatus"
    OK: ClassVar[bytes] = b"\x00"
    WARN: ClassVar[bytes] = b"\x01"
    ERROR: ClassVar[bytes] = b"\x02"
    STALE: ClassVar[bytes] = b"\x03"
    level: bytes = b"\x00"
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: tuple[KeyValue, ...] = ()


@dataclass(frozen=True)
class DiagnosticArray:
    """diagnostic_msgs/DiagnosticArray: what ``diagnostics`` carries (rqt_robot_monitor, Foxglove)."""

    ROS_TYPE: ClassVar[str] = "diagnostic_msgs/msg/DiagnosticArray"
    header: Header = field(default_factory=Header)
    status: tuple[DiagnosticStatus, ...] = ()


@dataclass(frozen=True)
class TriggerRequest:
    """std_srvs/Trigger request (empty)."""

    ROS_TYPE: ClassVar[str] = "std_srvs/srv/Trigger_Request"


@dataclass(frozen=True)
class TriggerResponse:
    """std_srvs/Trigger response."""

    ROS_TYPE: ClassVar[str] = "std_srvs/srv/Trigger_Response"
    success: bool = False
    message: str = ""


@dataclass(frozen=True)
class Trigger:
    """std_srvs/Trigger: the service type of every operator command (pause, resume, ...)."""

    ROS_TYPE: ClassVar[str] = "std_srvs/srv/Trigger"
    Request: ClassVar[type[TriggerRequest]] = TriggerRequest
    Response: ClassVar[type[TriggerResponse]] = TriggerResponse


class ByteBuffer(bytes):
    """A ROS ``uint8[]`` buffer (image data): rclpy holds it as ``array.array('B')``, we as bytes.

    A distinct type so the converter moves the whole buffer at once instead of one int per byte.
    """


@dataclass(frozen=True)
class RegionOfInterest:
    """sensor_msgs/RegionOfInterest (px); all zero: the full image."""

    ROS_TYPE: ClassVar[str] = "sensor_msgs/msg/RegionOfInterest"
    x_offset: int = 0
    y_offset: int = 0
    height: int = 0
    width: int = 0
    do_rectify: bool = False


@dataclass(frozen=True)
class Image:
    """sensor_msgs/Image: ``height`` rows of ``step`` bytes each, pixels as ``encoding`` says (mono8, bgr8, ...)."""

    ROS_TYPE: ClassVar[str] = "sensor_msgs/msg/Image"
    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    encoding: str = ""
    is_bigendian: int = 0
    step: int = 0
    data: ByteBuffer = ByteBuffer()


@dataclass(frozen=True)
class CameraInfo:
    """sensor_msgs/CameraInfo: intrinsics ``k`` (3x3, row-major, px), rectification ``r``, projection ``p`` (3x4)."""

    ROS_TYPE: ClassVar[str] = "sensor_msgs/msg/CameraInfo"
    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    distortion_model: str = ""
    d: tuple[float, ...] = ()
    k: tuple[float, ...] = (0.0,) * 9
    r: tuple[float, ...] = (0.0,) * 9
    p: tuple[float, ...] = (0.0,) * 12
    binning_x: int = 0
    binning_y: int = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


#: Camera messages (robot_bridges.camera.ros_camera), published only when asked.
CAMERA_TYPES: tuple[type, ...] = (Image, CameraInfo)


MESSAGE_TYPES: tuple[type, ...] = (String, Bool, JointState, PoseStamped, TFMessage, DiagnosticArray)
SERVICE_TYPES: tuple[type, ...] = (Trigger,)
