"""The 3D view's scene of a live run: the goals each machine sends its bridge, the frames vision located and
the cell the engine published, taken from the run's transport as any tool on the graph would take them."""
from __future__ import annotations

import logging

from core_functions.robots import RobotModel
from node_transport import codec
from node_transport.carriage import subscribe
from node_transport.port import Node
from node_transport.qos import COMMANDS, LATCHED
from node_transport.wire import ENGINE_CELL, BridgeCommand, CellSnapshot, LocatedFrames, bridge_topic, sm_topic
from operator_station.feed import Feed
from operator_station.scene3d import scene_log, snapshot_cell

log = logging.getLogger(__name__)


def observe(node: Node, robot: RobotModel, feed: Feed) -> None:
    """Subscribe ``node`` to what the 3D view shows of the run ``feed`` shows now (its robot drawn from ``robot``
    when the run was not begun with its application: a cell run elsewhere)."""
    scene = scene_log(feed)
    run = feed.snapshot.run
    if scene.run != run:
        scene.begin(run, robot, None)

    def refused(error: codec.WireError) -> None:  # a message out of contract is not drawn; said once per message
        log.warning("studio 3D view: %s", error)

    def command(message: BridgeCommand) -> None:
        if message.op == "execute" and message.primitive is not None and scene.run == run:
            scene.goal(node.clock.now(), message.group, message.primitive)

    def located(message: LocatedFrames) -> None:
        if scene.run == run:
            scene.located(message.t, message.group, message.frames)

    def cell(message: CellSnapshot) -> None:
        if scene.run == run:
            scene.set_cell(snapshot_cell(message))

    subscribe(node, CellSnapshot, ENGINE_CELL, cell, refused, LATCHED)
    for group in robot.group_names:
        subscribe(node, BridgeCommand, bridge_topic(group, "command"), command, refused, COMMANDS)
        subscribe(node, LocatedFrames, sm_topic(group, "located"), located, refused, LATCHED)
