"""``nextage_sim_bridge``: the Nextage Open kinematic simulator as a ROS 2 node.

::

    ros2 run dual_arm_executive nextage_sim_bridge --ros-args -p speed:=10.0 -p faults:="right_arm:joint_limit@0.5"
"""
from __future__ import annotations

from collections.abc import Sequence

from cell_runner.bridge_nodes.common import BridgeSetup, bridge_main, csv_list
from core_functions.robots import NEXTAGE_OPEN
from node_transport.bounded import declare_bounded
from node_transport.port import Node
from robot_bridges.backend import BackendOptions

BACKEND = "nextage-sim"


def declare_nextage_parameters(node: Node) -> BridgeSetup:
    """The simulator's parameters, with the defaults of the embedded deployment."""
    speed = float(declare_bounded(node, "speed", 1.0, "simulated time per wall second (10.0: ten times faster than real)"))
    initial_pose = str(node.declare_parameter("initial_pose", "initial", "joint pose the simulated robot starts in (initial or off)"))
    control_period = float(declare_bounded(node, "control_period", 0.01, "simulation step (s of simulated time)"))
    seed = int(declare_bounded(node, "seed", 0, "random seed of simulated vision noise"))
    faults = str(node.declare_parameter("faults", "", "comma-separated injected faults, e.g. right_arm:joint_limit@0.5"))
    options = BackendOptions(
        robot=NEXTAGE_OPEN,
        faults=csv_list(faults),
        seed=seed,
        extra={"initial_pose": initial_pose, "control_period": repr(control_period)},
    )
    return BridgeSetup(options, speed)


def main(argv: Sequence[str] | None = None) -> int:
    return bridge_main(BACKEND, declare_nextage_parameters, argv)
