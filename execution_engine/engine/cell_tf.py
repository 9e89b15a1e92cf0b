"""The cell's frames on ``tf_static``: nominal when a run starts, moved as vision locates them.

RViz and Foxglove show a cell from tf.  The engine owns the cell model of the run (it publishes
the :class:`CellSnapshot`), so it also publishes the cell's frames: one transform per frame,
from its parent frame (a cell model's ``world`` is the robot's base frame,
:attr:`RobotModel.world_frame`, the root link of its URDF, so robot and cell form one tree).

Vision corrections are made inside the group machines; each machine reports all the frames it
has located on its latched ``<group>/sm/located`` (:mod:`execution_engine.machine.located`).
This module merges them into the cell and publishes the whole set again: a located frame at its
measured pose, its child frames moved with it (what :meth:`CellIndex.pose` does for skills).
``tf_static`` is latched with depth 1 and tf2 keeps the latest transform per child frame, so
each message carries every frame, and because this is the only sender of the cell's frames a
late subscriber can only receive the newest, corrected set.

Known limit: corrections are matched to the run by the cell's name.  A machine that outlives an
engine keeps its last list latched until the new engine's cell model reaches it (it then sends
an empty one), so for that moment a restarted engine may show the previous run's corrections.
"""
from __future__ import annotations

from typing import Any

from core_functions.cell_index import CellIndex
from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from node_transport import codec, typed
from node_transport.msgs import TFMessage, Time, TransformStamped
from node_transport.port import Node
from node_transport.qos import LATCHED, TF_STATIC
from node_transport.transforms import transform_stamped
from node_transport.wire import TF_STATIC_TOPIC, CellSnapshot, LocatedFrames, sm_topic

WORLD = "world"


def cell_transforms(cell: CellIndex, root: str, stamp: Time) -> tuple[TransformStamped, ...]:
    """Every frame of ``cell`` in its parent, at its best known pose; ``world`` is called ``root``."""
    transforms = []
    for name in cell.frame_names():
        parent = cell.frame(name).parent
        local = cell.pose(parent).inverse().compose(cell.pose(name))
        transforms.append(transform_stamped(root if parent == WORLD else parent, name, local, stamp))
    return tuple(transforms)


class CellFramesBroadcaster:
    """The engine's tf_static sender for the cell of the current run."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._pub = node.create_publisher(TFMessage, TF_STATIC_TOPIC, TF_STATIC)
        self._groups: set[str] = set()
        self._cell: CellSnapshot | None = None
        self._root = WORLD
        self._located: dict[str, LocatedFrames] = {}

    def publish_cell(self, snapshot: CellSnapshot, robot: RobotModel) -> None:
        """A run starts in ``snapshot``: publish its nominal frames, then follow the corrections."""
        for group in robot.group_names:
            if group not in self._groups:
                self._groups.add(group)
                self.node.create_subscription(typed.LocatedFramesMsg, sm_topic(group, "located"), lambda m, g=group: self._on_located(g, m), LATCHED)
        self._cell, self._root = snapshot, robot.world_frame
        self._located.clear()
        self._publish()

    def located(self) -> dict[str, Pose]:
        """Every frame vision located in this run so far, its measured world pose (a later report wins)."""
        return {name: pose for located in self._located.values() for name, pose in located.frames.items()}

    def _on_located(self, group: str, msg: Any) -> None:
        topic = self.node.resolve(sm_topic(group, "located"))
        try:
            located = typed.from_msg(LocatedFrames, msg, self.node.clock, source=topic)
        except codec.WireError as error:
            self.node.logger.error("%s: ignored located frames: %s", self.node.fully_qualified_name, error)
            return
        if self._cell is None or located.cell != self._cell.name or located.group != group:
            return  # from another cell model (an earlier application), or on the wrong topic
        self._located.pop(group, None)  # keep arrival order: the newest list is applied last
        self._located[group] = located
        self._publish()

    def _publish(self) -> None:
        assert self._cell is not None
        cell = self._cell.index()
        known = set(cell.frame_names())
        for located in self._located.values():  # two groups located one frame: the later report wins
            for name, pose in located.frames.items():
                if name in known:
                    cell.correct(name, pose)
        self._pub.publish(TFMessage(cell_transforms(cell, self._root, self.node.now_stamp())))
