"""A machine's watch on its bridge: who the bridge is, asked only when the live publishers change.

``publisher_nodes`` is a graph look-up (over DDS: the matched endpoints and their QoS, then
``ros_discovery_info``); the watch runs before every primitive and every 0.1 s of a wait, so it
must not ask on every check, yet must still name the bridge it saw last when it is gone.
"""
from __future__ import annotations

from typing import Any

from node_transport.clock import simulated_clock
from execution_engine.machine.bridge_watch import BridgeWatch
from node_transport.local import LocalTransport


class Feedback:
    """A feedback subscription whose live publishers the test sets."""

    topic = "left_arm/bridge/feedback"

    def __init__(self) -> None:
        self.count = 1
        self.nodes = ["/nextage_sim_bridge"]
        self.asked = 0

    def get_publisher_count(self) -> int:
        return self.count

    def publisher_nodes(self) -> list[str]:
        self.asked += 1
        return list(self.nodes)


def test_the_bridge_is_named_from_the_last_look_and_looked_up_only_when_the_publishers_change() -> None:
    node: Any = LocalTransport(simulated_clock()).create_node("left_arm_machine")
    feedback = Feedback()
    watch = BridgeWatch(node, feedback)  # type: ignore[arg-type]
    assert [watch.lost() for _ in range(50)] == [None] * 50
    assert feedback.asked == 1
    feedback.count, feedback.nodes = 2, ["/nextage_sim_bridge", "/spare_bridge"]
    assert watch.lost() is None and feedback.asked == 2
    feedback.count, feedback.nodes = 0, []
    lost = watch.lost()
    assert lost == ("bridge /nextage_sim_bridge, /spare_bridge lost: no live publisher on /left_arm/bridge/feedback "
                    "(its process died or was cut off from this one)")
    feedback.count, feedback.nodes = 1, ["/nextage_sim_bridge"]  # a restarted bridge is looked up again
    assert watch.lost() is None and feedback.asked == 3 and watch.names == ["/nextage_sim_bridge"]
