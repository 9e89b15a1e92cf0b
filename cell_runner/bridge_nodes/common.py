"""The shared body of every bridge's ``ros2 run`` entry point (``bridge_nodes/<backend>.py``: nextage_sim, vplus, kuka_rsi).

A bridge executable differs from another only in its back end and in the parameters that
configure it.  So an entry point is one line::

    def main(argv=None) -> int:
        return bridge_main("nextage-sim", declare_nextage_parameters, argv)

where ``declare_...(node)`` declares the back end's parameters on the node and returns a
:class:`BridgeSetup`.  This module builds the back end through the registry, wraps it in the
same :class:`BridgeNode` the embedded deployment uses, and serves until the process stops;
process start-up, signals and exit codes are :mod:`cell_runner.ros_main`'s.
"""
from __future__ import annotations

import asyncio
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

from cell_runner.ros_main import (
    ExitCode,
    Outcome,
    StartupError,
    run_node,
    serve_forever,
    startup_errors,
    warn_undeclared,
)
from core_functions.cell_robots import CellNames
from core_functions.geometry import Pose
from node_transport.clock import Clock, FollowingClock, scaled_clock
from node_transport.msgs import ClockMessage, Time
from node_transport.port import Node
from node_transport.qos import CLOCK
from node_transport.wire import CLOCK_TOPIC, bridge_node_name
from robot_bridges.backend import BackendOptions, BridgeError, RobotBackend
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.placed import PlacedBackend
from robot_bridges.registry import create_backend


#: The largest coordinate or angle of a base pose (m, rad): a cell is a room, not a city.
BASE_BOUND = 100.0
CLOCK_PERIOD = 0.01  # wall seconds between /clock messages of a simulator faster than real time


@dataclass(frozen=True)
class BridgeSetup:
    """How to build a back end: its options, and how fast its clock runs against wall time.

    ``speed`` is for simulators (10 runs a simulated robot ten times faster than real time);
    a bridge to a real controller leaves it at 1.
    """

    options: BackendOptions
    speed: float = 1.0
    #: the joints the robot's own driver publishes on /joint_states under the names the bridge would give them
    #: (a ros2-control robot, whose driver shares the graph): the bridge leaves them out of its own joint states
    driver_joints: Callable[[RobotBackend], frozenset[str]] | None = None


DeclareBridge = Callable[[Node], BridgeSetup]


def csv_list(text: str) -> tuple[str, ...]:
    """A list parameter written as one comma-separated string (ROS 2 cannot type an empty list)."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


def backend_clock(node: Node, speed: float) -> Clock:
    """The node's clock, or a clock ``speed`` times faster on the same loop for a simulator.

    A robot never runs on a clock taken from ``/clock`` (``use_sim_time``): it is the source of
    time, or a real controller in wall time; then it gets its own clock on the node's loop."""
    if speed == 1.0 and not isinstance(node.clock, FollowingClock):
        return node.clock
    return scaled_clock(speed).bind(node.clock.loop)


async def publish_clock(node: Node, clock: Clock, period: float) -> None:
    """``/clock`` from a simulator that runs faster than real time, every ``period`` of its time,
    so nodes with ``use_sim_time`` measure their waits in the robot's time."""
    publisher = node.create_publisher(ClockMessage, CLOCK_TOPIC, CLOCK)
    while True:
        publisher.publish(ClockMessage(Time.from_seconds(clock.epoch_now())))
        await clock.sleep(period)


def declare_base_pose(node: Node) -> Pose | None:
    """``base_pose``: where the robot's base stands in a mixed cell's world frame (``launch`` sets it from the
    cell's ``<robot xyz rpy>``); None when the robot's base is the world, as in a cell of one robot."""
    text = str(node.declare_parameter(
        "base_pose", "", "x y z roll pitch yaw (m, rad): the robot's base in the cell's world frame, for a robot of a mixed cell ('' = the base is the world)",
    ))
    if not text.strip():
        return None
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) and abs(v) <= BASE_BOUND for v in values):
        raise StartupError(f"{node.fully_qualified_name}: parameter base_pose must be six numbers x y z roll pitch yaw (m, rad; each within {BASE_BOUND:g}), got {text!r}")
    return Pose.from_xyz_rpy(*values)


def declare_cell_names(node: Node) -> CellNames:
    """``cell_names``: how a mixed cell names the robot's groups and joints (``launch`` sets it from the cell's
    ``<robot prefix>`` and ``<group name as>``): its per-group topics, actions and /joint_states carry them."""
    text = str(node.declare_parameter(
        "cell_names", "", "how a cell of several robots names this robot's groups and joints (prefix=viper_;arm=inspector); '' = its own names",
    ))
    try:
        return CellNames.parse(text)
    except ValueError as error:
        raise StartupError(f"{node.fully_qualified_name}: parameter {error}") from None


async def run_bridge(backend: str, declare: DeclareBridge, node: Node, outcome: Outcome) -> None:
    """Build the back end and its bridge node, then serve; the back end is closed on the way out."""
    with startup_errors():
        setup = declare(node)
        base = declare_base_pose(node)
        names = declare_cell_names(node)
        clock = backend_clock(node, setup.speed)
        robot_backend = await create_backend(backend, clock, setup.options)
        if base is not None or not names.identity:  # a robot of a mixed cell: poses in the cell's world frame, groups and joints by its names
            robot_backend = PlacedBackend(robot_backend, base or Pose(), node.name.removesuffix("_bridge"), names, setup.options.robot.cameras)
    try:
        with startup_errors():
            bridge = BridgeNode(node, robot_backend)
        if setup.driver_joints is not None:
            bridge.graph_joints = setup.driver_joints(robot_backend)
    except StartupError:
        await robot_backend.close()
        raise
    warn_undeclared(node)
    ticking: asyncio.Task[None] | None = None
    try:
        try:
            await bridge.start()
        except BridgeError as error:
            raise StartupError(f"{backend}: {error}", ExitCode.FAILED) from None
        if setup.speed != 1.0:
            bridge.hold_turnarounds()  # the machines and the engine are other processes
            ticking = asyncio.get_running_loop().create_task(publish_clock(node, clock, CLOCK_PERIOD * setup.speed), name="/clock")
        node.logger.info("%s: serving %s for %s", node.fully_qualified_name, robot_backend.name, ", ".join(robot_backend.groups))
        await serve_forever()
    finally:
        if ticking is not None:
            ticking.cancel()
            await asyncio.gather(ticking, return_exceptions=True)
        await bridge.close()


def bridge_main(backend: str, declare: DeclareBridge, argv: Sequence[str] | None = None) -> int:
    """Run the bridge for registry back end ``backend`` as a ROS 2 node process."""
    return run_node(bridge_node_name(backend), partial(run_bridge, backend, declare), sys.argv if argv is None else argv)
