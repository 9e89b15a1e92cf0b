"""Run an application on a KUKA KR (KR C4 controller, RSI over UDP): three nodes.

    ros2 launch dual_arm_executive kuka_rsi.launch.py                   # a simulated KR C4, real time
    ros2 launch dual_arm_executive kuka_rsi.launch.py rsi_listen:=192.168.1.10:49152 host:=192.168.1.20
    ros2 launch dual_arm_executive kuka_rsi.launch.py rsi_listen:=... host:=... rsi_config:=/path/RSI_Ethernet.xml cycle:=12
    ros2 launch dual_arm_executive kuka_rsi.launch.py application:=/path/app.xml namespace:=cell_a
    ros2 launch dual_arm_executive kuka_rsi.launch.py --show-args

Nodes, one process each: ``kuka_rsi_bridge`` (the RSI external system; without ``rsi_listen`` it
starts a simulated KR C4 that sends to it), ``arm_machine`` (the state machine of group ``arm``)
and ``execution_engine`` (runs ``application``), all in ``namespace``: cells launched with
``namespace:=cell_a`` and ``namespace:=cell_b`` run side by side (simulated ones listen on free
ports; real ones each on their own ``rsi_listen``).  RSI runs on the robot's clock, so there is no
``speed``.  Every other parameter comes from ``config/kuka_rsi.yaml``; the node names here are the
sections of that file and the names the embedded deployment gives the same nodes
(cell_runner/ros_main.py).  What every launch file of the package shares is in
``cell_description.py`` beside this file.
"""
import os
import runpy

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument


def generate_launch_description() -> LaunchDescription:
    cell = runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), "cell_description.py"))
    typed = cell["typed"]
    return cell["cell_description"](
        config="kuka_rsi.yaml",
        robot="kuka_kr",
        groups=("arm",),
        bridge="kuka_rsi_bridge",
        application="kuka_rsi_demo.xml",
        arguments=[
            DeclareLaunchArgument(
                "rsi_listen",
                default_value="",
                description="HOST:PORT the bridge listens on: IP_NUMBER:PORT of the controller's RSI configuration "
                "('' = start a simulated KR C4)",
            ),
            DeclareLaunchArgument(
                "host",
                default_value="",
                description="the controller's address, the only one whose packets are answered (required with rsi_listen)",
            ),
            DeclareLaunchArgument(
                "rsi_config",
                default_value="",
                description="RSI Ethernet configuration XML of the controller ('' = the packaged config/kuka_rsi_ethernet.xml)",
            ),
            DeclareLaunchArgument("cycle", default_value="4", choices=["4", "12"], description="RSI cycle of the controller in ms"),
            DeclareLaunchArgument(
                "mode",
                default_value="absolute",
                choices=["absolute", "relative"],
                description="how the controller's RSI context applies corrections",
            ),
        ],
        bridge_parameters={
            "rsi_listen": typed("rsi_listen", str),
            "host": typed("host", str),
            "config": typed("rsi_config", str),
            "cycle": typed("cycle", int),
            "mode": typed("mode", str),
        },
    )
