"""``use_sim_time`` on any middleware: a node whose run clock follows a simulator's ``/clock``.

A simulator faster (or slower) than real time is the cell's source of time: it publishes
``/clock``.  Every other node of that cell must measure its waits in the robot's time, or at ten
times real time the engine reports wall seconds and a 5 s "bridge did not accept" bound is half a
second of a busy computer.  rclpy and the DDS transport both give a node with the ROS parameter
``use_sim_time`` a :class:`~node_transport.clock.FollowingClock` fed from ``/clock`` here, so the
two behave alike: time stands still while the source is silent, and a source silent for the stall
bound ends every pending wait with a fault reported on ``/clock`` instead of a hang.
"""
from __future__ import annotations

import asyncio

from node_transport.clock import FollowingClock
from node_transport.msgs import ClockMessage
from node_transport.port import Node
from node_transport.qos import CLOCK
from node_transport.wire import CLOCK_TOPIC

#: The ROS parameter rclpy declares on every node; the DDS transport declares it the same way.
USE_SIM_TIME = "use_sim_time"
USE_SIM_TIME_DESCRIPTION = "take the node's time (stamps, sleeps, timeouts) from <namespace>/clock instead of the wall clock"
#: Wall seconds of silence on ``/clock`` after which a node's pending waits end with a fault.
STALL_TIMEOUT = 10.0
#: The same before ``/clock``'s first tick: the simulator may still be starting (its models, its scene),
#: on a busy computer for longer than a running one may stall.
FIRST_TICK_TIMEOUT = 20.0


def follow_clock(node: Node, loop: asyncio.AbstractEventLoop, stall_timeout: float = STALL_TIMEOUT) -> FollowingClock:
    """A clock bound to ``loop`` that ``node`` feeds from ``/clock`` (remapped like any topic)."""
    clock = FollowingClock(
        stall_timeout=stall_timeout,
        on_stall=lambda text: node.report_fault(CLOCK_TOPIC, TimeoutError(text)),
        first_tick_timeout=max(stall_timeout, FIRST_TICK_TIMEOUT),
    )
    clock.bind(loop)
    node.create_subscription(ClockMessage, CLOCK_TOPIC, lambda msg: clock.advance_to(msg.clock.to_seconds()), CLOCK)
    return clock
