"""The ``ros2-control`` back end's options, parsed and checked before anything connects, starts or runs.

Written ``--backend-option KEY=VALUE``; per group ``GROUP.KEY=VALUE`` (``arm.controller=...``), so a
dual-arm cell names a controller, joints and gripper for each arm.  ``run`` checks them before its
dry run (``robot_bridges.registry.check_options``) and the factory builds from what this returns,
so both refuse a value in the same one line naming the option.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from core_functions import option_ranges
from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from robot_bridges.backend import BackendOptions
from robot_bridges.camera.spec import parse_mount
from robot_bridges.ros2_control.cameras import KNOWN, RobotCameras, robot_cameras

BACKEND = "ros2-control"
TRANSPORTS = ("dds", "ros", "model")  # model: no controller, the URDF model follows the trajectories (the dry run)
#: name: default (the range is core_functions.option_ranges')
NUMBERS: dict[str, float] = {"acceleration_time": 0.5, "state_timeout": 0.5, "start_timeout": 10.0, "goal_tolerance": 0.01, "result_timeout": 5.0,
                             "camera_timeout": 2.0}
GLOBAL_TEXTS = ("transport", "urdf", "description", "camera_source")
GROUP_TEXTS = ("controller", "joints", "tip", "tool", "gripper", "tool_service")
CAMERA_TEXTS = ("topic", "mount")  # per camera: CAMERA.topic, CAMERA.mount
#: per group: name -> (default, the option_ranges setting it is checked against)
GROUP_NUMBERS: dict[str, tuple[float, str]] = {
    "gripper_open": (0.08, "gripper_position"),
    "gripper_closed": (0.0, "gripper_position"),
    "gripper_effort": (0.0, "gripper_effort"),
}


@dataclass(frozen=True)
class GroupSettings:
    """One group: its FollowJointTrajectory action, its joints as the controller names them (in the
    application robot's order for that group), the tip frame of its IK and its gripper, if any."""

    group: str
    controller: str
    joints: tuple[str, ...]
    app_joints: tuple[str, ...]
    tip: str | None
    tool: Pose  # the TCP in the tip frame
    gripper: str | None
    tool_service: str | None  # the std_srvs/SetBool service switching the group's tool (tool_on, tool_off)
    gripper_open: float
    gripper_closed: float
    gripper_effort: float


@dataclass(frozen=True)
class Ros2ControlSettings:
    transport: str
    urdf: str | None  # a URDF file; None: /robot_description
    description: str  # where a model link reads /robot_description without a urdf file: dds or ros
    groups: tuple[GroupSettings, ...]
    acceleration_time: float
    state_timeout: float
    start_timeout: float
    goal_tolerance: float
    result_timeout: float
    camera_timeout: float = 2.0
    camera_source: str = ""  # "": no cameras (vision not available); "ros": <topic>/image_raw + camera_info
    cameras: RobotCameras | None = None  # with camera_source=ros: the robot's cameras, mounts as given
    camera_topics: Mapping[str, str] = field(default_factory=dict)  # camera -> its topic prefix (relative by default)

    def group(self, name: str) -> GroupSettings:
        for settings in self.groups:
            if settings.group == name:
                return settings
        raise KeyError(name)


def known_options(robot: RobotModel) -> list[str]:
    names = [*GLOBAL_TEXTS, *NUMBERS]
    for group in robot.group_names:
        names += [f"{group}.{key}" for key in (*GROUP_TEXTS, *GROUP_NUMBERS)]
    cameras = robot_cameras(robot)
    for camera in cameras.specs if cameras is not None else ():
        names += [f"{camera}.{key}" for key in CAMERA_TEXTS]
    return names


def _number(extra: dict[str, str], key: str, default: float, setting: str) -> float:
    text = extra.get(key)
    return default if text is None else option_ranges.check(setting, text, label=f"{BACKEND}: {key}")


def parse_options(options: BackendOptions, speed: float = 1.0) -> Ros2ControlSettings:
    """The options checked (ValueError naming the option); ``speed`` is the run's clock factor
    (``math.inf``: simulated time), which only the model link may take: a controller runs in real time."""
    robot = options.robot
    extra = dict(options.extra)
    unknown = sorted(set(extra) - set(known_options(robot)))
    if unknown:
        groups, cameras = ", ".join(robot.group_names), robot_cameras(robot)
        raise ValueError(f"{BACKEND}: unknown option(s) {', '.join(unknown)} (known: {', '.join((*GLOBAL_TEXTS, *NUMBERS))}, "
                         f"per group ({groups}) GROUP.{', GROUP.'.join((*GROUP_TEXTS, *GROUP_NUMBERS))}"
                         + (f", and per camera ({', '.join(cameras.specs)}) CAMERA.topic, CAMERA.mount)" if cameras is not None else ")"))
    for what, given in (("--host", options.host), ("--port", options.port), ("--rsi-listen", options.rsi_listen)):
        if given is not None:
            raise ValueError(f"{BACKEND}: takes no {what}: it reaches the robot through the ROS graph (transport=dds or ros, ROS_DOMAIN_ID)")
    if options.faults:
        raise ValueError(f"{BACKEND}: takes no --fault (it drives a real controller)")
    transport = extra.get("transport", "dds")
    if transport not in TRANSPORTS:
        raise ValueError(f"{BACKEND}: transport={transport!r} must be one of {', '.join(TRANSPORTS)}")
    if transport != "model" and speed != 1.0:
        raise ValueError(f"{BACKEND}: the controller runs in real time: run with --speed 1 (the default), not {'max' if math.isinf(speed) else f'{speed:g}'}")
    description = extra.get("description", "dds")
    if description not in ("dds", "ros"):
        raise ValueError(f"{BACKEND}: description={description!r} must be dds or ros (the transport /robot_description is read on)")
    urdf = extra.get("urdf") or None
    if urdf is not None:
        try:
            with open(urdf, encoding="utf-8"):
                pass
        except OSError as error:
            raise ValueError(f"{BACKEND}: urdf={urdf}: {error.strerror or error}") from None
    numbers = {key: _number(extra, key, default, key) for key, default in NUMBERS.items()}
    groups = tuple(_group(robot, name, extra) for name in robot.group_names)
    source, cameras, topics = _cameras(robot, extra)
    return Ros2ControlSettings(transport, urdf, description, groups, **numbers, camera_source=source, cameras=cameras, camera_topics=topics)


def _cameras(robot: RobotModel, extra: dict[str, str]) -> tuple[str, RobotCameras | None, dict[str, str]]:
    """camera_source and the per-camera options; the cameras only with camera_source=ros."""
    source = extra.get("camera_source", "")
    known = robot_cameras(robot)
    given = sorted(k for k in extra if k.split(".", 1)[0] in (known.specs if known else ()))
    if source not in ("", "ros"):
        raise ValueError(f"{BACKEND}: camera_source={source!r} must be ros (the cameras' <camera>/image_raw and camera_info topics) or empty (no cameras)")
    if not source:
        if given:
            raise ValueError(f"{BACKEND}: {given[0]} needs camera_source=ros (without it the robot has no cameras)")
        return "", None, {}
    if known is None:
        raise ValueError(f"{BACKEND}: camera_source=ros: no camera model of robot {robot.name} (cameras are known for: {', '.join(KNOWN)})")
    topics = {}
    for camera in known.specs:
        topic = extra.get(f"{camera}.topic", camera)
        if not topic or any(c.isspace() for c in topic) or topic.endswith("/") or "//" in topic:
            raise ValueError(f"{BACKEND}: {camera}.topic={topic!r} is not a topic prefix (e.g. {camera} or /cell/{camera}: its image_raw and camera_info are under it)")
        topics[camera] = topic
    mounts = {c: parse_mount(extra[f"{c}.mount"], f"{BACKEND}: {c}.mount") for c in known.specs if f"{c}.mount" in extra}
    return source, known.mounted(mounts), topics


def _group(robot: RobotModel, group: str, extra: dict[str, str]) -> GroupSettings:
    app_joints = robot.group(group).joint_names
    controller = extra.get(f"{group}.controller", f"/{group}_controller/follow_joint_trajectory")
    if not controller or any(c.isspace() for c in controller) or controller.endswith("/"):
        raise ValueError(f"{BACKEND}: {group}.controller={controller!r} is not an action name (e.g. /joint_trajectory_controller/follow_joint_trajectory)")
    joints = tuple(j.strip() for j in extra.get(f"{group}.joints", ",".join(app_joints)).split(",") if j.strip())
    if len(joints) != len(app_joints) or len(set(joints)) != len(joints):
        raise ValueError(f"{BACKEND}: {group}.joints must name {len(app_joints)} different joints, the controller's names of "
                         f"{', '.join(app_joints)} in that order; got {len(joints)}")
    gripper = extra.get(f"{group}.gripper") or None
    tool_service = extra.get(f"{group}.tool_service") or None
    if tool_service is not None and (any(c.isspace() for c in tool_service) or tool_service.endswith("/")):
        raise ValueError(f"{BACKEND}: {group}.tool_service={tool_service!r} is not a service name (e.g. /{group}_tool/set, a std_srvs/srv/SetBool)")
    numbers = {key: _number(extra, f"{group}.{key}", default, setting) for key, (default, setting) in GROUP_NUMBERS.items()}
    tool = _tool(group, extra.get(f"{group}.tool", "0 0 0 0 0 0"))
    return GroupSettings(group, controller, joints, app_joints, extra.get(f"{group}.tip") or None, tool, gripper, tool_service, **numbers)


def _tool(group: str, text: str) -> Pose:
    """``x y z roll pitch yaw`` (m, rad), the TCP in the tip frame."""
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) and abs(v) <= 10.0 for v in values):
        raise ValueError(f"{BACKEND}: {group}.tool must be six numbers x y z roll pitch yaw (m, rad; each within 10), the TCP in the tip frame, got {text!r}")
    return Pose.from_xyz_rpy(*values)
