"""A group machine's health on ``diagnostics`` (diagnostic_msgs/DiagnosticArray), for operators' tools.

rqt_robot_monitor, the diagnostic aggregator and Foxglove's diagnostics panels read
``diagnostics``; publishing there lets an operator see at a glance which group is working,
held, or failed, without knowing this project's JSON topics.  Like a diagnostic_updater task,
each machine sends one status for its group on every state change and once per second of run
time (so a monitor can tell a silent machine from a quiet one), named ``<node name>: <group>``
with the group as hardware id.

Levels follow Table 2: OK in Ready, the working states and Finish; WARN in Pause and Stop (held,
an operator or the engine must act); ERROR in ErrorHandling.  STALE is the aggregator's verdict
on a status that stopped coming, never ours.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable

from execution_engine.machine.context import MachineContext
from execution_engine.machine.table import ERROR_HANDLING, PAUSE, STOP
from node_transport.msgs import DiagnosticArray, DiagnosticStatus, Header, KeyValue
from node_transport.port import Node, TransportError
from node_transport.qos import DIAGNOSTICS
from node_transport.wire import DIAGNOSTICS_TOPIC

#: diagnostic_updater's default period (s of run time).
PERIOD = 1.0
_LEVELS = {PAUSE: DiagnosticStatus.WARN, STOP: DiagnosticStatus.WARN, ERROR_HANDLING: DiagnosticStatus.ERROR}


def level_of(state: str) -> bytes:
    """The diagnostic level of a machine state (OK unless held or failed)."""
    return _LEVELS.get(state, DiagnosticStatus.OK)


class MachineDiagnostics:
    """Publishes one machine's :class:`DiagnosticStatus`; :meth:`update` on each state change."""

    def __init__(self, node: Node, ctx: MachineContext, error: Callable[[], str | None], period: float = PERIOD) -> None:
        self.node = node
        self.ctx = ctx
        self.period = period
        self._error = error
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS)
        self._timer: asyncio.TimerHandle | None = None
        self._closed = False
        self.last_error = ""
        self._work: tuple[str, str, int] = ("", "", 0)  # operation, function, primitive index

    def update(self) -> None:
        """The machine changed state: publish now, and every period from the first update on."""
        error = self._error()
        if error:
            self.last_error = error
        self._publish()
        if self._timer is None and not self._closed:
            self._timer = self.node.clock.call_later(self.period, self._tick)

    def status(self) -> DiagnosticStatus:
        """The group's status as it stands."""
        state = self.ctx.state_name
        level = level_of(state)
        operation, function, index = self._current_work()
        message = state
        if function:
            message += f", {function} (operation {operation})"
        if level == DiagnosticStatus.ERROR and self.last_error:
            message += f": {self.last_error}"
        values = (
            KeyValue("state", state),
            KeyValue("operation", operation),
            KeyValue("function", function),
            KeyValue("primitive_index", str(index)),
            KeyValue("last_error", self.last_error),
        )
        name = f"{self.node.name}: {self.ctx.group}"
        return DiagnosticStatus(level=level, name=name, message=message, hardware_id=self.ctx.group, values=values)

    def _current_work(self) -> tuple[str, str, int]:
        """(operation, function, primitive index) of the function under way; in ErrorHandling, of
        the one that failed (the machine has already closed it by then)."""
        run = self.ctx.run
        if run is not None:
            self._work = (run.request.operation, run.request.function, run.started)
        elif self.ctx.state_name != ERROR_HANDLING:
            self._work = ("", "", 0)
        return self._work

    def close(self) -> None:
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _publish(self) -> None:
        self._current_work()  # remember the function under way: ErrorHandling reports the one that failed
        if self._pub.get_subscription_count() == 0:
            return  # nobody listens: a state change costs nothing (the 1 Hz tick reaches a late monitor)
        self._pub.publish(DiagnosticArray(header=Header(stamp=self.node.now_stamp()), status=(self.status(),)))

    def _tick(self) -> None:
        self._timer = None
        if self._closed:
            return
        try:
            self._publish()
        except TransportError:  # the node is gone (shutdown): so is the periodic report
            self._closed = True
            return
        self._timer = self.node.clock.call_later(self.period, self._tick)
