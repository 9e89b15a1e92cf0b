"""A group machine's watch on its bridge while it waits for the bridge's answer.

A bridge process killed mid-motion (``kill -9`` says no goodbye) or cut off from the machine
would otherwise be noticed only when the wait runs out: ``bridge_timeout`` for an
acknowledgement, ``primitive_timeout`` (minutes) for a motion.  The bridge's feedback publisher
is the sign of life: over DDS it asserts liveliness with a lease (1 s, see
:mod:`node_transport.dds`), and a subscription counts only live publishers.  While a
working state waits for the bridge it checks every :data:`WATCH_PERIOD`; once the count is zero
the wait ends as a CONNECTION fault naming the bridge's node (ErrorHandling; the engine stops the
other groups), within the lease plus :data:`WATCH_PERIOD` of the loss.
"""
from __future__ import annotations

from typing import Any

from node_transport.port import Node, Subscription

WATCH_PERIOD = 0.1  # run seconds between checks while a state waits for the bridge


class BridgeWatch:
    """Knows who publishes the bridge's feedback, and says when nobody alive does any more."""

    def __init__(self, node: Node, feedback: Subscription[Any] | None) -> None:
        self.node = node
        self.feedback = feedback
        self.names: list[str] = []  # the bridge's node(s), as last seen alive
        self._count = 0  # live publishers at the last check: the names are asked again only when it changes

    def lost(self) -> str | None:
        """Why the bridge is gone, or None while its feedback publisher is alive (or unwatched)."""
        feedback = self.feedback
        if feedback is None:
            return None
        count = feedback.get_publisher_count()
        if count > 0:
            if count != self._count or not self.names:  # asking who they are costs a graph look-up (DDS, rclpy)
                self.names = feedback.publisher_nodes() or self.names
            self._count = count
            return None
        self._count = 0
        who = f"bridge {', '.join(self.names)}" if self.names else "the bridge"
        topic = self.node.resolve(feedback.topic)
        return f"{who} lost: no live publisher on {topic} (its process died or was cut off from this one)"
