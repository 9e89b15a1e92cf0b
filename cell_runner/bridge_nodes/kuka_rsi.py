"""``kuka_rsi_bridge``: a KUKA KR C4 over RSI (UDP) as a ROS 2 node.

::

    ros2 run dual_arm_executive kuka_rsi_bridge --ros-args -p rsi_listen:=192.168.1.10:49152 -p host:=192.168.1.20
    ros2 run dual_arm_executive kuka_rsi_bridge          # no rsi_listen: a KR C4 RSI simulator is started

It serves group ``arm``.  RSI runs on the robot's own 4 ms (or 12 ms) clock, so this node always
runs in real time.  Every option of the back end a ROS user sets is a parameter (listed with its
default in ``config/kuka_rsi.yaml``); the ``sim_`` options, which make the simulated controller
misbehave on purpose for tests and demonstrations, are left to the command line.
"""
from __future__ import annotations

from collections.abc import Sequence

from cell_runner.bridge_nodes.common import BridgeSetup, bridge_main
from core_functions.robots import KUKA_KR
from node_transport.bounded import declare_bounded
from node_transport.port import Node
from robot_bridges.backend import BackendOptions

BACKEND = "kuka-rsi"

_TEXT_OPTIONS = {
    "runner": ("process", "where the real-time loop runs: process or thread"),
    "simulator": ("process", "simulated KR C4 without rsi_listen: process, thread or accelerated"),
    "mode": ("absolute", "how the RSI context corrects: absolute or relative"),
    "config": ("", "RSI Ethernet configuration XML ('' = the packaged config/kuka_rsi_ethernet.xml layout)"),
    "feedback": ("", "file to save every feedback packet to ('' = no saving)"),
}
_NUMBER_OPTIONS = {
    "cycle": (4, "RSI cycle of the controller in ms: 4 or 12"),
    "timeout": (100, "late packets in a row after which the simulated RSI stops"),
    "axis_monitor": (360.0, "simulated AXISCORRMON limit (deg)"),
    "silence": (0.0, "seconds without packets that mean the robot is lost (0 = the back end's default: 0.1 s for a real controller, 1 s for a simulated one, 2 s for an accelerated simulator)"),
    "connect_timeout": (10.0, "seconds to the controller's first valid packet before the bridge gives up, saying what arrived instead"),
    "linear_speed": (1.0, "Cartesian speed at 100 % (m/s)"),
    "linear_accel": (2.0, "Cartesian acceleration at 100 % (m/s^2)"),
    "tolerance": (0.1, "deg, every axis: how far the controller's reported set point (ASPos) may lie from the commanded one before the robot is held"),
    "tolerance_mm": (1.0, "mm: the same for the reported TCP (RSol) under Cartesian corrections"),
    "follow_time": (0.1, "s: where the controller reports no set point that follows the corrections (none, or frozen at the start), its actual axes must lie among the set points commanded this long before"),
}


def declare_kuka_parameters(node: Node) -> BridgeSetup:
    """The RSI bridge's parameters; an empty rsi_listen starts the simulator.  Every number in its
    range (KUKA RSI's own where the name has another meaning elsewhere), refused at start-up."""
    rsi_listen = str(node.declare_parameter("rsi_listen", "", "HOST:PORT of the controller's RSI configuration ('' = start a simulator)"))
    host = str(node.declare_parameter("host", "", "the controller's address (IP or name, resolved once at start): only its packets are answered (with rsi_listen)"))
    port = int(declare_bounded(
        node, "port", 0,
        "with rsi_listen: the UDP port the controller sends from (0 = the port of its first valid packet); without: the port the loop listens on (0 = a free one)",
    ))
    extra: dict[str, str] = {}
    for name, (default, description) in _TEXT_OPTIONS.items():
        value = str(node.declare_parameter(name, default, description))
        if value:
            extra[name] = value
    for name, (number, description) in _NUMBER_OPTIONS.items():
        value = declare_bounded(node, name, number, description, scope=BACKEND, unset=0.0 if name == "silence" else None)
        if not (name == "silence" and value == 0.0):
            extra[name] = str(value)
    options = BackendOptions(robot=KUKA_KR, host=host or None, port=port or None, rsi_listen=rsi_listen or None, extra=extra)
    return BridgeSetup(options)


def main(argv: Sequence[str] | None = None) -> int:
    return bridge_main(BACKEND, declare_kuka_parameters, argv)
