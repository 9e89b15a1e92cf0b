"""Run an application on an Adept Viper s850 (V+ controller, AdeptServer over TCP): three nodes.

    ros2 launch dual_arm_executive vplus.launch.py                                 # AdeptServer simulator in the bridge
    ros2 launch dual_arm_executive vplus.launch.py host:=192.168.0.10 port:=1234  # a real controller
    ros2 launch dual_arm_executive vplus.launch.py application:=/path/app.xml namespace:=cell_b port:=1235
    ros2 launch dual_arm_executive vplus.launch.py --show-args

Nodes, one process each: ``vplus_bridge`` (the AdeptServer client; without ``host`` it starts an
AdeptServer simulator on 127.0.0.1:``port`` inside its process), ``arm_machine`` (the state machine
of group ``arm``) and ``execution_engine`` (runs ``application``), all in ``namespace``: cells
launched with ``namespace:=cell_a`` and ``namespace:=cell_b`` run side by side -- two simulated
ones need two ``port`` values, since each simulator listens on its own.  The simulator runs in real
time (the bridge has no ``speed``).  Every other parameter comes from ``config/vplus.yaml``; the
node names here are the sections of that file and the names the embedded deployment gives the same
nodes (cell_runner/ros_main.py).  What every launch file of the package shares is in
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
        config="vplus.yaml",
        robot="adept_viper_s850",
        groups=("arm",),
        bridge="vplus_bridge",
        application="vplus_pick_inspect.xml",
        arguments=[
            DeclareLaunchArgument(
                "host",
                default_value="",
                description="AdeptServer address of the V+ controller ('' = start an AdeptServer simulator in the bridge)",
            ),
            DeclareLaunchArgument(
                "port",
                default_value="1234",
                description="AdeptServer TCP port, in [0, 65535]; without host, the port the simulator listens on (0: a free one)",
            ),
        ],
        bridge_parameters={"host": typed("host", str), "port": typed("port", int)},
    )
