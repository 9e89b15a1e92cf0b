"""A group machine's vision corrections, passed on to the engine (latched ``<group>/sm/located``).

Skills correct the cell inside the machine (``locate_frame`` -> :meth:`CellIndex.correct`), but
the machine is not where the cell's frames are published: the engine alone publishes them on
``tf_static``, nominal first, corrected as corrections come in (see
:mod:`execution_engine.engine.cell_tf`).  One sender per frame is what keeps a late subscriber
from receiving a nominal pose after a corrected one.  So the machine only reports: every time
its cell index is corrected it publishes all the frames located so far in that cell, and when a
new cell model arrives (a new run, which starts nominal) it publishes an empty list for it.
"""
from __future__ import annotations

from core_functions.cell_index import CellIndex
from core_functions.geometry import Pose
from node_transport import typed
from node_transport.port import Node
from node_transport.qos import LATCHED
from node_transport.wire import LocatedFrames, sm_topic


class LocatedFramesPublisher:
    """Publishes the corrections of whichever cell index the machine works with."""

    def __init__(self, node: Node, group: str) -> None:
        self.node = node
        self.group = group
        self._pub = node.create_publisher(typed.LocatedFramesMsg, sm_topic(group, "located"), LATCHED)

    def attach(self, cell: CellIndex | None) -> None:
        """Follow the corrections of ``cell``, the machine's new cell model (none located yet)."""
        if cell is None:
            return
        cell.on_correct = lambda _name, _pose: self._publish(cell)
        self._publish(cell)

    def _publish(self, cell: CellIndex) -> None:
        frames: dict[str, Pose] = cell.corrections()
        message = LocatedFrames(group=self.group, cell=cell.name, frames=frames, t=self.node.clock.now())
        self._pub.publish(typed.to_msg(message, self.node.clock))
