"""Run an application on the simulated Nextage Open: five nodes, one process each.

    ros2 launch dual_arm_executive nextage_sim.launch.py
    ros2 launch dual_arm_executive nextage_sim.launch.py application:=/path/app.xml speed:=10.0
    ros2 launch dual_arm_executive nextage_sim.launch.py namespace:=cell_a use_sim_time:=true log_level:=debug
    ros2 launch dual_arm_executive nextage_sim.launch.py --show-args

Nodes: ``nextage_sim_bridge`` (the kinematic simulator), ``left_arm_machine``,
``right_arm_machine``, ``torso_head_machine`` (one state machine per group) and
``execution_engine`` (runs ``application``), all in ``namespace``: cells launched with
``namespace:=cell_a`` and ``namespace:=cell_b`` run side by side.  With ``use_sim_time:=true`` the
nodes take their ROS time from ``<namespace>/clock``; at a ``speed`` other than 1.0 the simulator
publishes that clock and the machines and the engine follow it anyway, so every timeout and the
engine's report are in the robot's time (the cycle time the dry run predicts).  Every other parameter comes from
``config/nextage_sim.yaml``; the node names here are the sections of that file and the names the
embedded deployment gives the same nodes (cell_runner/ros_main.py).  What every launch file of
the package shares is in ``cell_description.py`` beside this file.
"""
import os
import runpy

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, NotEqualsSubstitution


def generate_launch_description() -> LaunchDescription:
    cell = runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), "cell_description.py"))
    speed = DeclareLaunchArgument(
        "speed",
        default_value="1.0",
        description="simulated seconds per wall second, in [0.01, 1000] (10.0 runs the robot ten times faster; "
        "other than 1.0, the machines and the engine follow the simulator's /clock)",
    )
    return cell["cell_description"](
        config="nextage_sim.yaml",
        robot="nextage_open",
        groups=("left_arm", "right_arm", "torso_head"),
        bridge="nextage_sim_bridge",
        application="rivet_installation.xml",
        arguments=[speed],
        bridge_parameters={"speed": cell["typed"]("speed", float)},
        simulated=NotEqualsSubstitution(LaunchConfiguration("speed"), "1.0"),  # compared as numbers: 1 is 1.0
    )
