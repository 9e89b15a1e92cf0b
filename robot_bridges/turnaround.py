"""A simulator in a cell of several processes holds robot time while a group's next step is on its way.

In one process (``run --speed 10``) the engine, the machines and the simulated robot share one
paced loop: the work between two primitives -- the engine dispatching a function, a machine
planning its next move -- takes no robot time, and the cycle time is the dry run's.  With one
process per node (``launch --speed 10``, ``ros2 launch ... speed:=10.0``) the simulator's loop
waits idle meanwhile, and that turnaround, a few milliseconds of messages and planning, would count
ten times over: 5 % of the rivet demonstrator's cycle (93.0 s against the dry run's 88.77 s).

So a paced simulator in its own process holds its time while a group's next step is in flight:
from the engine's request of a function to the group (``<group>/sm/request``) or the end of the
group's primitive (``done``, ``measured``) until the group's next command reaches the bridge.  A
group whose function ends (``<group>/sm/result``) while another group is still moving lets go: the
operation waits for the one still moving, whose own end holds the time while the engine dispatches
the next one.  Every hold ends by itself after :data:`TURNAROUND` wall seconds, so a machine with
nothing to send (waiting for a partner at a barrier, or gone) slows the simulation by that much
once and never stops it.  A hold is robot time standing still for the whole cell -- every node
follows the simulator's ``/clock``, which stands still too -- so no timeout can fire during it.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Collection
from typing import Any

from node_transport.clock import PacedLoop
from node_transport import typed
from node_transport.port import Node
from node_transport.qos import COMMANDS, EVENTS
from node_transport.wire import ENGINE_EVENTS, sm_topic

#: The longest a group's turnaround is held, in wall seconds: well above a machine's answer on a
#: busy computer (a few milliseconds; 100 ms at worst when it plans a long path), short enough that
#: a group with nothing to send slows the simulation by little.
TURNAROUND = 0.25
#: The engine's own steps are held under this name (no group is called so: group names are identifiers).
ENGINE = "(engine)"
FINAL_STATES = ("finished", "failed", "stopped")


class Turnaround:
    """Holds a paced loop's time while a group's next step is on its way to the robot.

    ``executing()`` names the groups whose primitive the back end is carrying out now.
    """

    def __init__(
        self, node: Node, loop: asyncio.AbstractEventLoop, groups: Collection[str], executing: Callable[[], Collection[str]],
        bound: float = TURNAROUND,
    ) -> None:
        self._loop = loop if isinstance(loop, PacedLoop) else None
        self._executing = executing
        self.bound = bound
        self._held: set[str] = set()
        if self._loop is None:
            return
        for group in groups:
            node.create_subscription(typed.MachineRequestMsg, sm_topic(group, "request"), lambda msg, g=group: self._requested(g, msg), COMMANDS)
            node.create_subscription(typed.MachineResultMsg, sm_topic(group, "result"), lambda _msg, g=group: self._function_ended(g), COMMANDS)
        node.create_subscription(typed.EngineEventMsg, ENGINE_EVENTS, self._on_engine_event, EVENTS)

    def hold(self, group: str) -> None:
        """``group`` has work on its way (a function requested, a primitive ended): hold until its next command."""
        if self._loop is not None:
            self._loop.hold_for(_key(group), self.bound)
            self._held.add(group)

    def commanded(self, group: str) -> None:
        """A command for ``group`` reached the bridge: its turnaround (and the run's start) is over."""
        if self._loop is None:
            return
        for held in {group, ENGINE} & self._held:
            self._loop.release(_key(held))
            self._held.discard(held)

    def _on_engine_event(self, msg: Any) -> None:
        """A run's start (idle: the machines are asked whether they are ready, then the first
        requests go out) and its end (stopping: every machine is told to finish) are steps of the
        engine's on their way too; a final state (the run is over) ends every hold at once."""
        if getattr(msg, "event", "") != "state":
            return
        if msg.state in ("idle", "running", "stopping"):
            self.hold(ENGINE)
        elif msg.state in FINAL_STATES:
            self.release_all()

    def _requested(self, group: str, msg: Any) -> None:
        if getattr(msg, "kind", "") == "execute":  # "end" sends the machine to Finish: nothing follows
            self.hold(group)

    def _function_ended(self, group: str) -> None:
        if set(self._executing()) - {group}:  # the operation waits for those; their ends hold the time
            self.commanded(group)

    def release_all(self) -> None:
        for group in list(self._held):
            self.commanded(group)


def _key(group: str) -> Any:
    return ("turnaround", group)
