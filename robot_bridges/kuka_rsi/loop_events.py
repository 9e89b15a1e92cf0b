"""The KUKA RSI back end's feedback: what the real-time loop reports, turned into faults, log lines and waits.

The loop (:mod:`.interface`) runs beside the event loop and reports through a file descriptor: faults, warnings,
late replies, the controller's address, its own end.  Every wait of the back end is bounded by the robot itself --
a handshake or a tool output gets a budget of robot cycles, anything else ends when the loop reports a fault (it
cannot bind, the first packet does not come in time, packets stop, it dies) -- so all waits go through
:meth:`LoopEvents.until` here.  The first fault is kept: it fails the running primitive and every later one, as RSI
must be restarted on the controller before the robot moves again.
"""
from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from node_transport.console_log import ONCE
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.interface import RobotState, RsiInterface

#: The back end's logger: the loop's events are the back end's to report, under its name.
log = logging.getLogger("robot_bridges.kuka_rsi.backend")


def say_once(level: int, text: str) -> None:
    """Log ``text`` as a fact the console says once (``console_log.ONCE``): a checked run starts the back end
    more than once -- the dry runs on the simulated controller, the run itself -- and each finds it again."""
    log.log(level, "%s", text, extra={ONCE: True})


class LoopEvents:
    """The loop as the back end sees it: its state, its events, the first fault, and bounded waits."""

    def __init__(self, name: str, handshake_cycles: int, stop_reason: Callable[[], str | None]) -> None:
        """``stop_reason`` says why a simulated controller stopped (None: it did not, or there is none):
        a silence is then that stop, not a timeout."""
        self.name = name
        self.handshake_cycles = handshake_cycles
        self.stop_reason = stop_reason
        self.iface: RsiInterface | None = None
        self.fault: BridgeError | None = None
        self.starting = False  # a failed start says its fault once, in its exception
        self.changed = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._readers: list[int] = []

    def attach(self, iface: RsiInterface) -> None:
        """Take ``iface`` as the loop, on the running event loop; its events are read once it has started
        (``watch(iface.fileno(), on_events)``)."""
        self._loop = asyncio.get_running_loop()
        self.changed = asyncio.Event()
        self.iface = iface

    def watch(self, fd: int, callback: Callable[[], None]) -> None:
        assert self._loop is not None
        self._loop.add_reader(fd, callback)
        self._readers.append(fd)

    def unwatch(self, fd: int) -> None:
        assert self._loop is not None
        self._loop.remove_reader(fd)
        self._readers.remove(fd)

    def unwatch_all(self) -> None:
        for fd in self._readers:
            assert self._loop is not None
            self._loop.remove_reader(fd)
        self._readers = []

    def on_events(self) -> None:
        assert self.iface is not None
        try:
            messages = self.iface.poll_events()
        except ConnectionError:
            self.set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: the RSI loop has gone"))
            self.unwatch(self.iface.fileno())
            messages = []
        for message in messages:
            if message[0] == "fault":
                self.on_fault(str(message[2]), str(message[3]))
            elif message[0] == "warn":
                log.warning("%s: %s", self.name, message[2])
            elif message[0] == "note":
                say_once(int(message[2]), str(message[3]))  # the robot's name, not the loop's address: the same in the dry runs and the run
            elif message[0] == "late":
                log.warning("%s: the controller counts %d late replies (IPOC %d)", self.name, message[2], message[3])
            elif message[0] == "peer":
                log.info("%s: the controller speaks from %s (%s); datagrams from any other port are ignored", self.name, message[2], message[3])
            elif message[0] == "stopped" and self.fault is None:
                self.set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: the RSI loop stopped"))
        self.changed.set()

    def on_fault(self, kind: str, message: str) -> None:
        if kind == "timeout":
            reason = self.stop_reason()
            if reason is not None:
                self.set_fault(BridgeError(FaultKind.CONTROLLER, f"{self.name}: RSI stopped: {reason} ({message})"))
                return
            delay = self.state().delay
            hint = f"; the controller had counted {delay} late replies, so RSI may have stopped on its timeout" if delay else ""
            self.set_fault(BridgeError(FaultKind.TIMEOUT, f"{self.name}: {message}{hint}"))
        elif kind == "connection":
            self.set_fault(BridgeError(FaultKind.CONNECTION, f"{self.name}: {message}"))
        elif kind == "controller":
            self.set_fault(BridgeError(FaultKind.CONTROLLER, f"{self.name}: {message}"))
        else:
            self.set_fault(BridgeError(FaultKind.INTERNAL, f"{self.name}: {message}"))

    def set_fault(self, error: BridgeError) -> None:
        if self.fault is None:
            self.fault = error
            if not self.starting:  # a failed start says it once, in its exception
                log.error("%s", error)
        self.changed.set()

    def state(self) -> RobotState:
        assert self.iface is not None
        return self.iface.state(0)

    async def until(self, predicate: Callable[[], bool], cycles: int | None, what: str) -> None:
        """Wait until ``predicate()``; a fault, or ``cycles`` robot cycles, end the wait with an error.

        Without ``cycles`` the wait is bounded by the loop: it reports a fault when it cannot bind,
        when the first packet does not come in time, when packets stop, or when it dies.
        """
        start = self.state().cycles if cycles is not None and self.iface is not None else 0
        while True:
            self.changed.clear()
            if self.fault is not None:
                raise self.fault
            if predicate():
                return
            if cycles is not None and self.state().cycles - start > cycles:
                raise BridgeError(FaultKind.TIMEOUT, f"{self.name}: no {what} within {cycles} RSI cycles")
            await self.changed.wait()

    async def handshake(self, flag: str, ack: str, what: str) -> None:
        """ITRA's logical setters: raise a flag, wait for the KRL program's output, lower the flag."""
        assert self.iface is not None
        iface = self.iface
        raised = self.state().cycles
        iface.set_flag(0, flag, True)
        try:
            await self.until(lambda: self.fresh(raised, ack, True), self.handshake_cycles, f"acknowledgement of {what} ({ack})")
        finally:
            iface.set_flag(0, flag, False)

    def fresh(self, raised: int, tag: str, value: bool) -> bool:
        """Output ``tag`` reads ``value`` in a packet that answers a flag raised at cycle ``raised``
        (it leaves with the next reply; the robot's answer comes in the packet after)."""
        assert self.iface is not None
        state = self.state()
        return state.cycles >= raised + 2 and self.iface.digout(0, tag, state) == value

    async def wait_cycles(self, cycles: int) -> None:
        """Let ``cycles`` RSI cycles of robot time pass (raises the fault if the robot stops)."""
        assert self.iface is not None
        end = self.state().cycles + cycles
        self.iface.wake_at(0, end)
        await self.until(lambda: self.state().cycles >= end, None, f"{cycles} RSI cycles")
