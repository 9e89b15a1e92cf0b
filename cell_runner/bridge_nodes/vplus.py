"""``vplus_bridge``: an Adept V+ controller (AdeptServer over TCP) as a ROS 2 node.

::

    ros2 run dual_arm_executive vplus_bridge --ros-args -p host:=192.168.0.10 -p port:=1234
    ros2 run dual_arm_executive vplus_bridge            # no host: an AdeptServer simulator in-process

It serves group ``arm``: ``/arm/bridge/command`` in, ``/arm/bridge/feedback``, ``/joint_states`` and
``/arm/tcp_pose`` out.
"""
from __future__ import annotations

from collections.abc import Sequence

from cell_runner.bridge_nodes.common import BridgeSetup, bridge_main
from core_functions.robots import ADEPT_VIPER_S850
from node_transport.bounded import declare_bounded
from node_transport.port import Node
from robot_bridges.backend import BackendOptions

BACKEND = "vplus"


def declare_vplus_parameters(node: Node) -> BridgeSetup:
    """The V+ bridge's parameters; an empty host starts the simulator."""
    host = str(node.declare_parameter("host", "", "AdeptServer address ('' = start the simulator on 127.0.0.1)"))
    port = int(declare_bounded(node, "port", 1234, "AdeptServer TCP port (without host: the simulator's, 0 = a free one)"))
    timeout = float(declare_bounded(node, "timeout", 5.0, "ack allowance per command on top of its motion time (s)", scope=BACKEND))
    retries = int(declare_bounded(node, "retries", 3, "connection attempts after the first"))
    linear = str(node.declare_parameter("linear", "joint", "linear moves: 'joint' (run joint-interpolated) or 'reject'"))
    camera = str(node.declare_parameter("camera", "", "what answers vision requests: simulated, rendered (images of the focus camera), none ('' = simulated without host)"))
    tolerance_mm = float(declare_bounded(node, "tolerance_mm", 1.0, "how far a reported position may lie from the commanded one (mm)", scope=BACKEND))
    tolerance_deg = float(declare_bounded(node, "tolerance_deg", 0.5, "how far a reported orientation may lie from the commanded one (deg)", scope=BACKEND))
    extra = {"timeout": repr(timeout), "retries": str(retries), "linear": linear, "tolerance_mm": repr(tolerance_mm), "tolerance_deg": repr(tolerance_deg)}
    if camera:
        extra["camera"] = camera
    options = BackendOptions(robot=ADEPT_VIPER_S850, host=host or None, port=port, extra=extra)
    return BridgeSetup(options)


def main(argv: Sequence[str] | None = None) -> int:
    return bridge_main(BACKEND, declare_vplus_parameters, argv)
