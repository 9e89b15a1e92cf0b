"""``studio APP.xml --transport ros``: watch and command a cell that runs elsewhere, through the transport port.

The cell (engine, machines, bridge) runs in other processes on a ROS graph; the station joins it
as one more node, ``operator_station``, and sees exactly what it would see of its own run: the
machines' status and structure, the engine's status and events, ``joint_states``
(:func:`operator_station.session.observe`).  Commands go to the engine's services
(``execution_engine/<command>``, Trigger) and the safety stop to ``cell/safety_stop``: the engine
records a service call under the service's name (a Trigger request carries no caller).  Start
calls the engine's start service: a cell launched with ``autostart:=false`` waits for it.

The transport is made by a *connect* coroutine on the session's own loop and thread (a real
clock): :func:`ros_connect` for a ROS graph; anything that returns a
:class:`~node_transport.port.Transport` works the same (the tests attach to a cell on
the in-process transport this way).
"""
from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Awaitable, Callable
from typing import Any

from core_functions.robots import RobotModel
from execution_engine.app_model import Application
from node_transport.clock import Clock, real_clock, run_with_clock
from execution_engine.observers import TraceWriter
from node_transport.msgs import Bool, Trigger
from node_transport.port import Transport, TransportError
from node_transport.qos import LATCHED
from node_transport.ros import RosTransport
from execution_engine.engine.breakpoints import BREAKPOINT_SERVICE, RUN_TO_SERVICE, BreakpointService, RunToService
from node_transport.wire import ENGINE_SERVICES, SAFETY_STOP, engine_service
from operator_station.feed import Feed
from operator_station.run_summary import SummaryOnEnd
from operator_station.session import FeedStream, observe, publish_safety

log = logging.getLogger(__name__)

Connect = Callable[[Clock], Awaitable[Transport]]
#: Seconds a service of the engine may take to answer.
SERVICE_TIMEOUT = 10.0


def ros_connect(argv: list[str]) -> Connect:
    """Join the ROS graph (``--ros-args`` in ``argv`` as for any node); needs rclpy."""

    async def connect(clock: Clock) -> Transport:
        return RosTransport(clock, argv)

    return connect


class AttachedSession:
    """The station's view of a cell it does not run; the same face to the server as :class:`RunSession`."""

    def __init__(self, feed: Feed, robot: RobotModel, app_name: str, connect: Connect, clock: Clock | None = None) -> None:
        self.feed = feed
        self.clock = clock or real_clock()  # the station's own (the cell keeps its time; stamps come with the messages)
        self.robot = robot
        self.app_name = app_name
        self.connect = connect
        self._loop: asyncio.AbstractEventLoop | None = None
        self._clients: dict[str, Any] = {}
        self._safety: Any = None
        self._ready = threading.Event()
        self._closing: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self.error: str | None = None

    @property
    def running(self) -> bool:
        return False  # the run is the cell's: the station never holds one of its own

    def attach(self) -> None:
        """Join the graph on a thread of its own; the feed fills as the cell publishes."""
        self.feed.begin("live", self.app_name, list(self.robot.group_names))
        self._thread = threading.Thread(target=self._main, name="studio attach", daemon=True)
        self._thread.start()

    def wait_started(self, timeout: float) -> bool:
        return self._ready.wait(timeout) and self.error is None

    def join(self, timeout: float | None = None) -> None:
        """Leave the graph (the cell goes on)."""
        loop, closing = self._loop, self._closing
        if loop is not None and closing is not None:
            loop.call_soon_threadsafe(closing.set)
        if self._thread is not None:
            self._thread.join(timeout)

    def _main(self) -> None:
        try:
            run_with_clock(self._watch, self.clock)
        except Exception as error:  # noqa: BLE001 - said on the page and in the log, never lost
            log.exception("studio: the attached session failed")
            self.error = f"{type(error).__name__}: {error}"
            self.feed.update(messages=[{"severity": "error", "message": f"cannot watch the cell: {self.error}"}])
        finally:
            self._loop = None
            self._ready.set()

    async def _watch(self, clock: Clock) -> None:
        transport = await self.connect(clock)
        try:
            node = transport.create_node("operator_station")
            observe(node, self.robot, self.feed, [TraceWriter(FeedStream(self.feed, SummaryOnEnd(self.feed).see))])  # the run summary when the engine ends
            self._clients = {c: node.create_client(Trigger, engine_service(c)) for c in ENGINE_SERVICES}
            self._clients["breakpoint"] = node.create_client(BreakpointService, BREAKPOINT_SERVICE)
            self._clients["run_to"] = node.create_client(RunToService, RUN_TO_SERVICE)
            self._safety = node.create_publisher(Bool, SAFETY_STOP, LATCHED)
            self._closing = asyncio.Event()
            self._loop = asyncio.get_running_loop()
            self._ready.set()
            await self._closing.wait()
        finally:
            self._loop = None
            await transport.shutdown()

    # ------------------------------------------------------------------------ the page's side
    def start(self, app: Application, operations: list[dict[str, Any]]) -> tuple[bool, str]:
        """Not used: the server's Start of an attached cell goes to :meth:`command` ("start")."""
        return False, "attached to a running cell: Start calls its engine's start service"

    async def command(self, command: str) -> tuple[bool, str]:
        loop = self._loop
        client = self._clients.get(command)
        if loop is None or client is None:
            return False, "not attached to a cell"

        async def call() -> tuple[bool, str]:
            try:
                response = await client.call(Trigger.Request(), timeout=SERVICE_TIMEOUT)
            except (TransportError, asyncio.TimeoutError) as error:
                return False, f"{command}: the engine's service did not answer: {error or 'timeout'}"
            return bool(response.success), str(response.message)

        return await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(call(), loop))

    async def breakpoint(self, action: str, operation: str) -> tuple[bool, str, list[str]]:
        """A breakpoint or run-to command: the engine's breakpoint and run-to services (engine/breakpoints.py)."""
        loop = self._loop
        client = self._clients.get("run_to" if action == "run_to" else "breakpoint")
        if loop is None or client is None:
            return False, "not attached to a cell", []
        request = RunToService.Request(operation=operation) if action == "run_to" else BreakpointService.Request(operation=operation, action=action)

        async def call() -> tuple[bool, str, list[str]]:
            try:
                response = await client.call(request, timeout=SERVICE_TIMEOUT)
            except (TransportError, asyncio.TimeoutError) as error:
                return False, f"{action}: the engine's service did not answer: {error or 'timeout'}", []
            return bool(response.success), str(response.message), list(getattr(response, "breakpoints", ()))

        return await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(call(), loop))

    def safety_stop(self, active: bool) -> tuple[bool, str]:
        return publish_safety(self._loop, self._safety, active, "not attached to a cell")
