"""Run an application on the simulated Nextage Open: five nodes, one process each.

    ros2 launch dual_arm_executive nextage_sim.launch.py
    ros2 launch dual_arm_executive nextage_sim.launch.py application:=/path/app.xml speed:=10.0

Nodes: ``nextage_sim_bridge`` (the kinematic simulator), ``left_arm_machine``,
``right_arm_machine``, ``torso_head_machine`` (one state machine per group) and
``execution_engine`` (runs ``application``).  Every other parameter comes from
``config/nextage_sim.yaml``; the node names here are the sections of that file and the names the
embedded deployment gives the same nodes (execution_engine/ros_main.py).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = "dual_arm_executive"
GROUPS = ("left_arm", "right_arm", "torso_head")


def _node(executable: str, name: str, config: str, overrides: dict) -> Node:
    """One node of the package: the YAML section named like the node, then ``overrides``."""
    return Node(package=PACKAGE, executable=executable, name=name, parameters=[config, overrides], output="screen")


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    config = os.path.join(share, "config", "nextage_sim.yaml")
    application = LaunchConfiguration("application")
    speed = LaunchConfiguration("speed")
    actions = [
        DeclareLaunchArgument(
            "application",
            default_value=os.path.join(share, "apps_xml", "rivet_installation.xml"),
            description="application XML file the engine runs",
        ),
        DeclareLaunchArgument(
            "speed",
            default_value="1.0",
            description="simulated seconds per wall second (10.0 runs the robot ten times faster)",
        ),
        _node(executable="nextage_sim_bridge", name="nextage_sim_bridge", config=config,
              overrides={"speed": ParameterValue(speed, value_type=float)}),
    ]
    for group in GROUPS:
        actions.append(_node(executable="group_machine", name=f"{group}_machine", config=config, overrides={"group": group}))
    actions.append(
        _node(executable="execution_engine", name="execution_engine", config=config,
              overrides={"application": ParameterValue(application, value_type=str)})
    )
    return LaunchDescription(actions)
