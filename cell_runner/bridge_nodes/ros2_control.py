"""``ros2_control_bridge``: a robot whose ROS 2 driver serves FollowJointTrajectory, as a bridge node of the cell.

::

    ros2 run dual_arm_executive ros2_control_bridge --ros-args -p robot:=kuka_kr \\
        -p arm.controller:=/joint_trajectory_controller/follow_joint_trajectory
    python -m execution_engine launch APP.xml --robot ros2-control --backend-option arm.controller=/...   # the same, started by launch

The back end (robot_bridges/ros2_control) is a client of the driver on the ROS graph -- ``/robot_description``,
``/joint_states``, the controllers' actions -- and this node serves the cell's side of it: ``<group>/bridge/command``
in, ``<group>/bridge/feedback`` and ``<group>/tcp_pose`` out, as every bridge.  Each back-end option
(``--backend-option KEY=VALUE`` of ``run``) is a parameter of the same name, per group ``<group>.controller``
and so on for the groups of ``robot``, the model the driver drives.

Here the cell's nodes and the driver share one graph, unlike in ``run`` (where the cell talks in-process):
the driver already publishes ``/joint_states`` under its controllers' joint names and serves the
FollowJointTrajectory actions, so the bridge publishes on ``/joint_states`` only the joints the cell names
otherwise (a ``joints`` mapping, a cell's prefix) and serves no action.  A copy of the driver's own states under
the driver's names would reach the back end as fresh samples of the driver and hide a driver that stopped.
"""
from __future__ import annotations

from collections.abc import Sequence

from cell_runner.bridge_nodes.common import BridgeSetup, bridge_main
from cell_runner.ros_main import StartupError
from core_functions.robots import RobotModel, find_robot
from node_transport.bounded import declare_bounded
from node_transport.port import Node
from robot_bridges.backend import BackendOptions, RobotBackend
from robot_bridges.placed import PlacedBackend
from robot_bridges.ros2_control.backend import Ros2ControlBackend
from robot_bridges.ros2_control.options import BACKEND, GROUP_NUMBERS, GROUP_TEXTS, NUMBERS

#: the back end's global text options, each a parameter ('' = the back end's default)
_TEXTS = {
    "transport": "how the back end reaches the driver: dds (Cyclone DDS, default) or ros (rclpy)",
    "urdf": "the robot's URDF file ('' = /robot_description from the driver's robot_state_publisher)",
    "description": "the transport /robot_description is read on without urdf: dds or ros ('' = dds)",
}
_NUMBER_TEXT = {
    "acceleration_time": "how long a joint takes to reach its URDF speed limit (s): URDF gives no accelerations, so this sets them",
    "state_timeout": "joint_states older than this while the robot is used is a fault (s)",
    "start_timeout": "wait for robot_description, joint_states and the controllers' actions at start (s)",
    "goal_tolerance": "how far from its target a joint may end a motion (rad)",
    "result_timeout": "wait for a result after a trajectory's end, and for a stopped arm (s)",
}
_GROUP_TEXT = {
    "controller": "its FollowJointTrajectory action ('' = /<group>_controller/follow_joint_trajectory)",
    "joints": "the controller's names of the group's joints, comma-separated, in the model's order ('' = the model's names)",
    "tip": "the frame Cartesian targets put at the target, with tool ('' = tool0 if the URDF has it, else the link the group's last joint moves)",
    "tool": "the TCP in the tip frame: x y z roll pitch yaw (m, rad; '' = 0 0 0 0 0 0)",
    "gripper": "its control_msgs/action/GripperCommand action ('' = none)",
    "tool_service": "its std_srvs/srv/SetBool tool switch ('' = none)",
}
_GROUP_NUMBER_TEXT = {
    "gripper_open": "GripperCommand position of an open gripper",
    "gripper_closed": "GripperCommand position of a closed gripper",
    "gripper_effort": "GripperCommand max_effort (0: the controller's default)",
}


def _robot(node: Node) -> RobotModel:
    name = str(node.declare_parameter("robot", "", "the robot model the driver drives (kuka_kr, adept_viper_s850, nextage_open): its groups and joints"))
    if not name:
        raise StartupError(f"{node.fully_qualified_name}: parameter robot is required: the model the driver drives (kuka_kr, adept_viper_s850, nextage_open)")
    try:
        return find_robot(name)
    except KeyError as error:
        raise StartupError(f"{node.fully_qualified_name}: parameter robot: {error.args[0] if error.args else error}") from None


def declare_ros2_control_parameters(node: Node) -> BridgeSetup:
    """The back end's options as parameters (checked by the back end as ``--backend-option`` is); cameras stay
    the bridge's own parameters (camera_source, camera_timeout), which a robot without cameras refuses."""
    robot = _robot(node)
    extra: dict[str, str] = {}
    for name, description in _TEXTS.items():
        value = str(node.declare_parameter(name, "", description))
        if value:
            extra[name] = value
    for name, description in _NUMBER_TEXT.items():
        extra[name] = repr(declare_bounded(node, name, NUMBERS[name], description, scope=BACKEND))
    for group in robot.group_names:
        for key in GROUP_TEXTS:
            value = str(node.declare_parameter(f"{group}.{key}", "", f"group {group}: {_GROUP_TEXT[key]}"))
            if value:
                extra[f"{group}.{key}"] = value
        for key, (default, setting) in GROUP_NUMBERS.items():
            value = declare_bounded(node, f"{group}.{key}", default, f"group {group}: {_GROUP_NUMBER_TEXT[key]}", setting=setting, scope=BACKEND)
            extra[f"{group}.{key}"] = repr(value)
    return BridgeSetup(BackendOptions(robot=robot, extra=extra), driver_joints=driver_joints)


def driver_joints(backend: RobotBackend) -> frozenset[str]:
    """The joints the robot's driver already publishes on ``/joint_states`` under the names the bridge would
    (the controller's name of a joint is the cell's): the bridge leaves them out of its own."""
    placed = backend if isinstance(backend, PlacedBackend) else None
    inner = placed.inner if placed is not None else backend
    if not isinstance(inner, Ros2ControlBackend):
        return frozenset()
    same: set[str] = set()
    for group in inner.settings.groups:
        for own, controller in zip(group.app_joints, group.joints):
            name = placed.names.joint(own) if placed is not None else own
            if name == controller:
                same.add(name)
    return frozenset(same)


def main(argv: Sequence[str] | None = None) -> int:
    return bridge_main(BACKEND, declare_ros2_control_parameters, argv)
