"""What a bridge answers a command with, as a group machine (or a tool on the topics) relies on.

A primitive that is over in its first step is answered ``done`` alone, at once; one that takes time
is ``accepted`` first, then ``done`` when it ends; a second primitive while one runs is refused as
BUSY; a bridge shutting down ends the running one as STOPPED. The bridge starts a primitive inside
the command's callback and keeps a task only for one that waits, so these hold for both kinds.
"""
from __future__ import annotations

from typing import Any

import pytest
from scripted_backend import ScriptedBackend

from core_functions.primitives import MoveJoints, SetSpeed
from core_functions.robots import NEXTAGE_OPEN
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.wire import BridgeCommand, BridgeFeedback, FaultKind, bridge_topic
from robot_bridges.bridge_node import BridgeNode

ARM = "left_arm"


async def bridge_and_machine(clock: Clock) -> tuple[BridgeNode, TypedPublisher[BridgeCommand], list[tuple[float, str, str, Any]]]:
    bus = LocalTransport(clock)
    bridge = BridgeNode(bus.create_node("bridge"), ScriptedBackend(clock, NEXTAGE_OPEN, {"set_speed": 0.0, "move_joints": 2.0}))
    await bridge.start()
    machine = bus.create_node("machine")
    seen: list[tuple[float, str, str, Any]] = []
    subscribe(machine, BridgeFeedback, bridge_topic(ARM, "feedback"), lambda f: seen.append((clock.now(), f.id, f.status, f.fault)), seen.append)
    return bridge, TypedPublisher(machine, BridgeCommand, bridge_topic(ARM, "command")), seen


def test_an_instant_primitive_is_done_at_once_and_a_long_one_accepted_then_done(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[tuple[float, str, str, Any]]:
        bridge, commands, seen = await bridge_and_machine(clock)
        try:
            commands.publish(BridgeCommand("c-1", ARM, "execute", SetSpeed(0.5)))
            await clock.sleep(0.5)
            commands.publish(BridgeCommand("c-2", ARM, "execute", MoveJoints((0.1, 0.2, 0.3, 0.4, 0.5, 0.6))))
            await clock.sleep(0.5)
            commands.publish(BridgeCommand("c-3", ARM, "execute", SetSpeed(1.0)))  # while c-2 runs
            await clock.sleep(3.0)
            return seen
        finally:
            await bridge.close()

    seen = run_sim(main)
    assert [(i, s) for _, i, s, _ in seen] == [("c-1", "done"), ("c-2", "accepted"), ("c-3", "error"), ("c-2", "done")]
    times = {(i, s): t for t, i, s, _ in seen}
    assert [times[("c-1", "done")], times[("c-2", "accepted")], times[("c-2", "done")]] == pytest.approx([0.0, 0.5, 2.5], abs=1e-6)
    assert [f for _, i, _, f in seen if i == "c-3"] == [FaultKind.BUSY]


def test_a_bridge_shutting_down_ends_the_running_primitive_as_stopped(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[float, str, str, Any]], list[str]]:
        bridge, commands, seen = await bridge_and_machine(clock)
        commands.publish(BridgeCommand("c-1", ARM, "execute", MoveJoints((0.1, 0.2, 0.3, 0.4, 0.5, 0.6))))
        await clock.sleep(0.5)
        backend = bridge.backend
        await bridge.close()
        await clock.sleep(0)
        assert isinstance(backend, ScriptedBackend)
        return seen, [e.outcome for e in backend.executed(ARM)]

    seen, outcomes = run_sim(main)
    assert [(i, s, f) for _, i, s, f in seen] == [("c-1", "accepted", None), ("c-1", "error", FaultKind.STOPPED)]
    assert outcomes == ["running"]  # cancelled inside the back end's wait: it never finished the move
