"""The breakpoint and run-to services of the engine over rclpy (the fake rclpy) and over Cyclone DDS.

``execution_engine/breakpoint`` (dual_arm_executive_interfaces/srv/Breakpoint: operation, action ->
success, message, breakpoints) and ``execution_engine/run_to`` (RunTo: operation -> success,
message) are served on every transport; each call is an operator action recorded with the resolved
service's name and the operation it names (``execution_engine/events``), as the Trigger services'
are.  The engine here waits for group machines that never come (its start-up bound is short), which
leaves it holding the application: the time the services are tried in.  Every wait is bounded.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from app_builder import make_app
from dds_domain import domain_env
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from cell_runner.libraries import APPLICATION_FUNCTIONS
from execution_engine.engine.breakpoints import BREAKPOINT_SERVICE, RUN_TO_SERVICE, BreakpointService, RunToService
from execution_engine.engine.engine import ExecutionEngine
from node_transport import typed
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.port import Transport, poll_until
from node_transport.qos import EVENTS
from node_transport.ros import RosTransport
from node_transport.wire import ENGINE_EVENTS, EngineEvent

BOUND = 10.0  # s: only ever reached when something hangs
OPS = [{"left_arm": ("move_to_joint_pose", "initial")} for _ in range(4)]


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:  # a domain no other test uses meanwhile (dds_domain.py)
        yield claimed


async def exercise(clock: Clock, engine_side: Transport, client_side: Transport) -> tuple[list[Any], list[EngineEvent]]:
    """Set, toggle, refuse and run-to through the services while the engine holds the application."""
    engine = ExecutionEngine(engine_side.create_node("execution_engine", parameters={"startup_timeout": 3.0}), APPLICATION_FUNCTIONS.catalog(None))
    run = asyncio.ensure_future(engine.run(make_app(OPS)))
    operator = client_side.create_node("operator")
    events: list[EngineEvent] = []
    operator.create_subscription(typed.msg_type(EngineEvent), ENGINE_EVENTS, lambda m: events.append(typed.from_msg(EngineEvent, m, clock)), EVENTS)
    breakpoint_ = operator.create_client(BreakpointService, BREAKPOINT_SERVICE)
    run_to = operator.create_client(RunToService, RUN_TO_SERVICE)
    assert await poll_until(clock, lambda: engine.app is not None, BOUND, 0.01)
    answers = [
        await breakpoint_.call(BreakpointService.Request(operation="#2", action="set"), timeout=BOUND),
        await breakpoint_.call(BreakpointService.Request(operation="4", action="toggle"), timeout=BOUND),
        await breakpoint_.call(BreakpointService.Request(operation="2", action="clear"), timeout=BOUND),
        await breakpoint_.call(BreakpointService.Request(operation="seven", action="set"), timeout=BOUND),
        await breakpoint_.call(BreakpointService.Request(operation="1", action="flip"), timeout=BOUND),
        await run_to.call(RunToService.Request(operation="3"), timeout=BOUND),
    ]
    assert await poll_until(clock, lambda: sum(e.event == "operator" for e in events) >= 6, BOUND, 0.01)
    await run  # no machine ever answers: the run ends after its start-up bound
    return answers, [e for e in events if e.event == "operator"]


def check(answers: list[Any], events: list[EngineEvent]) -> None:
    assert [(a.success, a.message, tuple(getattr(a, "breakpoints", ()))) for a in answers] == [
        (True, "breakpoint set before operation 2 '2' (line 2)", ("2",)),
        (True, "breakpoint set before operation 4 '4' (line 4)", ("2", "4")),
        (True, "breakpoint cleared before operation 2 '2' (line 2)", ("4",)),
        (False, "no operation 'seven' in this run: give an operation's id or #N (1 to 4, as the engine's status counts them)", ("4",)),
        (False, "unknown breakpoint action 'flip' (actions: set, clear, toggle, clear_all, run_to)", ("4",)),
        (True, "running to operation 3 '3' (line 3): the run pauses before it", ()),
    ]
    service = "service /execution_engine/breakpoint"
    assert [(e.command, e.message, e.source, e.accepted) for e in events] == [
        ("break", "2", service, True), ("break", "4", service, True), ("unbreak", "2", service, True),
        ("break", "seven", service, False), ("flip", "1", service, False), ("run_to", "3", "service /execution_engine/run_to", True),
    ]


def run_real(main: Callable[[Clock], Any]) -> Any:
    return run_with_clock(main, real_clock())


def test_the_services_through_rclpy(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], list[EngineEvent]]:
        transport = RosTransport(clock, ["test"])
        try:
            return await exercise(clock, transport, transport)
        finally:
            await transport.shutdown()

    check(*run_real(main))


def test_the_services_between_dds_participants(env: dict[str, str]) -> None:
    async def main(clock: Clock) -> tuple[list[Any], list[EngineEvent]]:
        cell, tool = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        try:
            return await exercise(clock, cell, tool)
        finally:
            await cell.shutdown()
            await tool.shutdown()

    check(*run_real(main))
