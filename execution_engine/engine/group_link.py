"""The engine's handle on one group machine: requests out, results and state in, operator services.

Results are matched to requests by id; a result for a request the engine no longer waits for
(a retried or abandoned one) is dropped.  While a request waits, the link watches that the machine
is still there: its result publisher must stay matched (over DDS: hold its liveliness lease), or
every waiting request ends at once as preempted (a CONNECTION fault) naming the machine's node, and
the link answers no more: a machine process killed or cut off mid-run is noticed within the lease
plus :data:`WATCH_PERIOD` and ends the run (the engine stops the other groups), instead of
waiting out the function timeout and retrying into a machine that is not there.  The group's state arrives on its latched state topic,
so the engine knows where each machine is even if it started after them.
"""
from __future__ import annotations

import asyncio
import itertools
import uuid
from collections.abc import Callable
from typing import Any

from node_transport import codec, typed
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.clock import Clock
from node_transport.msgs import Trigger
from node_transport.port import Node, ServiceUnavailable, TransportError, wait_until_matched
from node_transport.qos import COMMANDS, LATCHED
from node_transport.wire import FaultKind, SmRequest, SmResult, machine_node_name, sm_service, sm_topic

WATCH_PERIOD = 0.1  # run seconds between checks that a machine with waiting requests is still there


class GroupLink:
    def __init__(self, node: Node, group: str, service_timeout: float) -> None:
        self.node = node
        self.group = group
        self.clock: Clock = node.clock
        self.service_timeout = service_timeout
        self.state = "unknown"
        self._state_changed = asyncio.Event()
        self._pending: dict[str, asyncio.Future[SmResult]] = {}
        self._ids = itertools.count(1)
        self._session = uuid.uuid4().hex[:6]
        self._requests = TypedPublisher(node, SmRequest, sm_topic(group, "request"), COMMANDS)
        # a result only resolves a future: taken as a hand-over (node_transport/local.py); the state is not, so
        # the groups of the engine's status, read at its own events, are the same as over any transport
        self._results = subscribe(node, SmResult, sm_topic(group, "result"), self._on_result, self._reject, COMMANDS, hand_over=True)
        self._state_source = node.resolve(sm_topic(group, "state"))
        node.create_subscription(typed.MachineStateMsg, sm_topic(group, "state"), self._on_state, LATCHED)
        self._clients = {c: node.create_client(Trigger, sm_service(group, c)) for c in ("pause", "resume", "stop", "reset")}
        self.rejected: list[str] = []
        self._watch: asyncio.Task[None] | None = None
        self.lost: str | None = None  # why the machine is gone, once it is
        self.on_result: Callable[[], None] | None = None  # told when a result resolves a future (the engine's ResultWaiter)

    def new_id(self) -> str:
        return f"engine-{self._session}-{self.group}-{next(self._ids)}"

    # -------------------------------------------------------------------------- requests
    async def link(self, timeout: float) -> bool:
        """True once requests and results have matched the machine (DDS discovery), so the first
        request is not lost; False after ``timeout`` run seconds."""
        return await wait_until_matched(self.clock, (self._requests, self._results), timeout)

    def send(self, request: SmRequest) -> asyncio.Future[SmResult]:
        future: asyncio.Future[SmResult] = asyncio.get_running_loop().create_future()
        self._pending[request.id] = future
        self._requests.publish(request)
        if self._watch is None or self._watch.done():
            self._watch = asyncio.get_running_loop().create_task(self._watch_machine(), name=f"{self.group} machine watch")
        return future

    async def _watch_machine(self) -> None:
        """Fail every waiting request once the machine's result publisher is gone."""
        topic = self.node.resolve(sm_topic(self.group, "result"))
        while self._pending:
            if self._results.get_publisher_count() == 0:
                error = self.lost = (
                    f"group machine {self.group} (node {machine_node_name(self.group)}) lost: no live publisher "
                    f"on {topic} (its process died or was cut off from this one)"
                )
                self.node.logger.error("%s: %s", self.node.fully_qualified_name, error)
                self._state_changed.set()
                for request_id, future in list(self._pending.items()):
                    if not future.done():
                        future.set_result(SmResult(id=request_id, group=self.group, outcome="preempted", error=error, fault=FaultKind.CONNECTION))
                self._pending.clear()
                if self.on_result is not None:
                    self.on_result()
                return
            await self.clock.sleep(WATCH_PERIOD)

    def send_end(self) -> None:
        self._requests.publish(SmRequest(id=self.new_id(), kind="end"))

    def forget(self, request_id: str) -> None:
        future = self._pending.pop(request_id, None)
        if future is not None and not future.done():
            future.cancel()

    def _reject(self, error: codec.WireError) -> None:
        self.rejected.append(str(error))
        self.node.logger.error("%s: %s", self.node.fully_qualified_name, error)

    def _on_result(self, result: SmResult) -> None:
        future = self._pending.pop(result.id, None)
        if future is not None and not future.done():
            future.set_result(result)
            if self.on_result is not None:
                self.on_result()

    # ------------------------------------------------------------------------------ state
    def _on_state(self, msg: Any) -> None:
        try:
            self.state = typed.read_state(msg, source=self._state_source)
        except codec.WireError as error:
            self._reject(error)
            return
        self._state_changed.set()

    async def wait_state(self, states: tuple[str, ...], timeout: float) -> bool:
        """True once the machine is in one of ``states``; False after ``timeout`` run seconds."""
        deadline = self.clock.now() + timeout
        while self.state not in states:
            if self.lost is not None:
                return False
            remaining = deadline - self.clock.now()
            if remaining <= 0:
                return False
            self._state_changed.clear()
            try:
                await self.clock.wait_for(self._state_changed.wait(), remaining)
            except asyncio.TimeoutError:
                return self.state in states
        return True

    # --------------------------------------------------------------------------- services
    async def command(self, name: str) -> tuple[bool, str]:
        """Call the machine's pause/resume/stop/reset; never raises (a failure is the answer)."""
        if self.lost is not None:
            return False, self.lost
        try:
            response = await self._clients[name].call(Trigger.Request(), timeout=self.service_timeout)
        except (ServiceUnavailable, TransportError, asyncio.TimeoutError) as error:
            return False, f"{self.node.resolve(sm_service(self.group, name))}: {type(error).__name__}: {error}"
        return response.success, response.message
