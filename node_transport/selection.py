"""``--transport ros|dds`` on every node executable: rclpy inside a ROS 2 install, or Cyclone DDS without one.

The option sits outside ``--ros-args`` (it is ours, not rcl's) and is taken out of argv before the
transport reads it, so the same command line works under both::

    nextage_sim_bridge --transport dds --ros-args -p speed:=2.0
    ros2 run dual_arm_executive nextage_sim_bridge --ros-args -p speed:=2.0
"""
from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

from node_transport.clock import Clock
from node_transport.console_log import node_console
from node_transport.dds import DdsTransport  # cyclonedds itself is imported only when one starts
from node_transport.port import RosArgumentsError

TRANSPORTS = ("ros", "dds")
DEFAULT = "ros"


def split_transport(argv: Sequence[str]) -> tuple[str, list[str]]:
    """(transport name, argv without ``--transport NAME``); RosArgumentsError on an unknown name."""
    rest: list[str] = []
    chosen = DEFAULT
    args = list(argv)
    index = 0
    inside_ros = False
    while index < len(args):
        arg = args[index]
        if arg == "--ros-args":
            inside_ros = True
        elif arg == "--" and inside_ros:
            inside_ros = False
        if not inside_ros and (arg == "--transport" or arg.startswith("--transport=")):
            if "=" in arg:
                chosen = arg.partition("=")[2]
                index += 1
            elif index + 1 < len(args):
                chosen = args[index + 1]
                index += 2
            else:
                raise RosArgumentsError("--transport needs a value: ros or dds")
            if chosen not in TRANSPORTS:
                raise RosArgumentsError(f"--transport {chosen}: use one of {', '.join(TRANSPORTS)}")
            continue
        rest.append(arg)
        index += 1
    return chosen, rest


def dds_transport(clock: Clock, argv: Sequence[str]) -> DdsTransport:
    """The DDS transport of a node process; Python logging to stderr as rcutils prints it, a warning
    that repeats as one counted line per second (:func:`~node_transport.console_log.node_console`)."""
    transport = DdsTransport(clock, argv)
    if not logging.getLogger().handlers:
        node_console(sys.stderr, transport.args.log_level or logging.INFO)
    return transport
