"""Commands and safety stops that did not come through the page, in the station's audit log (issue 26 item 5).

A cell is paused from the terminal of ``run --interactive``, resumed by a ROS service call (a script, another
station), slowed through the engine's ``speed_override`` parameter, and stopped by a light curtain on
``cell/safety_stop``: each is audited once, under its source as the engine recorded it (the topic's name for the
safety input), in the order the station saw them -- and the page's own commands once, with the user, never again
under the service they went through.  Both ways the station meets a run: the run it started itself and a cell it is
attached to on the graph (the in-process transport standing in for it, as test_studio_server does).
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from cell_runner.deployment import Deployment, deploy_local  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from execution_engine.engine.breakpoints import BREAKPOINT_SERVICE, BreakpointService  # noqa: E402
from execution_engine.engine.operator import console_source  # noqa: E402
from node_transport.clock import Clock, scaled_clock  # noqa: E402
from node_transport.local import LocalTransport  # noqa: E402
from node_transport.msgs import Bool, Trigger  # noqa: E402
from node_transport.port import Node, Transport  # noqa: E402
from node_transport.qos import LATCHED  # noqa: E402
from node_transport.wire import SAFETY_STOP, engine_service  # noqa: E402
from operator_station.access import OPERATOR, Access  # noqa: E402
from operator_station.attach import AttachedSession  # noqa: E402
from operator_station.feed import Feed  # noqa: E402
from operator_station.server import Station  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402
from test_studio_roles import USERS, body, entries, logged_in, station_for  # noqa: E402
from test_studio_server import CATALOG, cell_dir, wait_until  # noqa: E402, F401

TERMINAL = console_source("p")
SERVICE = "service /execution_engine/{}"
PARAMETER = "parameter /execution_engine/speed_override"
TOPIC = "/cell/safety_stop"


def state_of(station: Station) -> str:
    return str((station.feed.snapshot.status or {}).get("state", ""))


class Elsewhere:
    """Someone else on the run's graph -- another station, ``ros2 service call``, the terminal of the process that
    runs the engine -- acting on the run's own loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop, engine: Any) -> None:
        self.loop, self.engine = loop, engine
        self.node: Node = self.on_loop(self._node())
        self.safety = self.on_loop(self._publisher())

    async def _node(self) -> Node:
        return self.engine.node.transport.create_node("another_station")

    async def _publisher(self) -> Any:
        return self.node.create_publisher(Bool, SAFETY_STOP, LATCHED)

    def on_loop(self, coroutine: Coroutine[Any, Any, Any]) -> Any:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(30.0)

    def terminal(self, command: str) -> tuple[bool, str]:
        return self.on_loop(self.engine.operator_command(command, TERMINAL))  # type: ignore[no-any-return]

    def service(self, command: str) -> bool:
        async def call() -> bool:
            response = await self.node.create_client(Trigger, engine_service(command)).call(Trigger.Request(), timeout=10.0)
            return bool(response.success)

        return self.on_loop(call())  # type: ignore[no-any-return]

    def breakpoint(self, operation: str) -> bool:
        async def call() -> bool:
            client = self.node.create_client(BreakpointService, BREAKPOINT_SERVICE)
            return bool((await client.call(BreakpointService.Request(operation=operation, action="set"), timeout=10.0)).success)

        return self.on_loop(call())  # type: ignore[no-any-return]

    def parameter(self, percent: float) -> str:
        async def set_() -> str:
            return str(self.engine.node.set_parameter("speed_override", percent))  # as `ros2 param set` does

        return self.on_loop(set_())  # type: ignore[no-any-return]

    def light_curtain(self, active: bool) -> None:
        self.loop.call_soon_threadsafe(self.safety.publish, Bool(active))


def outside(station: Station) -> list[tuple[str, str, bool]]:
    """(who, what, ok) of every entry not made by a person at a page."""
    return [(e["who"], e["what"], e["ok"]) for e in entries(station) if e["kind"] in ("cell", "engine")]


def test_commands_from_the_terminal_a_service_and_the_parameter_and_an_outside_safety_stop_in_the_stations_run_are_audited_once(cell_dir: Path) -> None:
    station = station_for(cell_dir, speed=1.0, no_check=True)  # real time: the run lasts; it is held paused most of the test
    session = station.session
    assert session is not None
    with logged_in(station, "anna", "anna-pw") as page:
        assert page.post("/api/run", json=body(station, page)).json()["ok"]
        try:
            assert session.wait_started(60.0) and wait_until(lambda: state_of(station) == "running")
            assert wait_until(lambda: session.edit_target is not None)
            target = session.edit_target
            assert target is not None
            other = Elsewhere(target.loop, target.engine)
            assert other.terminal("pause")[0]
            assert wait_until(lambda: state_of(station) == "paused")
            assert other.service("resume")
            assert wait_until(lambda: state_of(station) == "running")
            assert page.post("/api/operator/pause", json={}).json()["ok"]  # the page's own: audited with anna, once
            assert other.parameter(50.0) == ""
            assert other.breakpoint("#9")
            other.light_curtain(True)
            assert wait_until(lambda: any(e["what"] == "safety event" for e in entries(station)))
            other.light_curtain(False)
            assert wait_until(lambda: any(e["what"] == "safety stop cleared" for e in entries(station)))
        finally:
            assert page.post("/api/operator/stop", json={}).status_code == 200
            session.join(120.0)
        assert wait_until(lambda: any(e["what"] == "run end" for e in entries(station)), 10.0)
    assert outside(station) == [
        (TERMINAL, "pause", True), (SERVICE.format("resume"), "resume", True), (PARAMETER, "speed override", True),
        (SERVICE.format("breakpoint"), "breakpoint set", True), (TOPIC, "safety stop raised", True),
        ("cell", "safety event", True), (TOPIC, "safety stop cleared", True)]
    pages = [(e["who"], e["what"]) for e in entries(station) if e["kind"] == "session"]
    assert pages == [("anna", "login"), ("anna", "run start"), ("anna", "pause"), ("anna", "stop"), ("anna", "run end")] or \
        pages == [("anna", "login"), ("anna", "run start"), ("anna", "pause"), ("anna", "run end"), ("anna", "stop")]  # the stop's answer may come after the end
    terminal = next(e for e in entries(station) if e["who"] == TERMINAL)
    assert (terminal["source"], terminal["command"], terminal["role"]) == (TERMINAL, "pause", "") and terminal["t"] > 0.0
    assert terminal["answer"] == "paused"
    speed = next(e for e in entries(station) if e["who"] == PARAMETER)
    assert speed["answer"] == "speed override 50 % (was 100 %)"
    assert next(e for e in entries(station) if e["what"] == "breakpoint set")["target"] == "9"
    assert [e["seq"] for e in entries(station)] == sorted(e["seq"] for e in entries(station))


def cell_kept(app: Any, kept: list[Any]) -> Callable[[Clock], Coroutine[Any, Any, Transport]]:
    """A connect for AttachedSession: the cell on an in-process transport, its engine waiting for the start service;
    ``kept`` gets the loop and the engine (the test acts on the cell as another node would)."""

    async def connect(clock: Clock) -> Transport:
        transport = LocalTransport(clock)
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        deployment: Deployment = await deploy_local(clock, app.robot, backend, transport=transport, engine_parameters={"autostart": False})
        kept.extend([asyncio.get_running_loop(), deployment.engine, asyncio.get_running_loop().create_task(deployment.engine.run(app))])
        return transport

    return connect


def test_attached_to_a_cell_the_pages_commands_are_audited_once_and_the_others_under_their_source(cell_dir: Path) -> None:
    app = load_application(cell_dir / "rivet_installation.xml", CATALOG)
    feed, kept = Feed(), []  # type: ignore[var-annotated]
    session = AttachedSession(feed, app.robot, app.name, cell_kept(app, kept), scaled_clock(2.0))
    session.attach()
    access = Access.for_address("127.0.0.1", users=USERS)
    station = Station(CATALOG, feed, session, cell_dir, cell_dir / "rivet_installation.xml", access=access)
    try:
        assert session.wait_started(60.0)
        other = Elsewhere(kept[0], kept[1])
        with logged_in(station, "anna", "anna-pw") as page:
            assert page.post("/api/run", json=body(station, page)).json()["ok"]  # the engine's start service, the page's
            assert wait_until(lambda: state_of(station) == "running")
            assert other.service("pause")  # someone else's call of the same kind of service
            assert wait_until(lambda: state_of(station) == "paused")
            assert page.post("/api/operator/resume", json={}).json()["ok"]
            assert wait_until(lambda: state_of(station) == "running")
            assert other.terminal("pause")[0]
            assert wait_until(lambda: state_of(station) == "paused")
            assert page.post("/api/breakpoint", json={"action": "set", "operation": "#9"}).json()["ok"]
            other.light_curtain(True)
            assert wait_until(lambda: any(e["what"] == "safety event" for e in entries(station)))
            assert page.post("/api/safety/clear", json={"confirm": True}).json()["ok"]  # the page clears it: anna's
            assert page.post("/api/operator/stop", json={}).json()["ok"]
            assert wait_until(lambda: any(e["what"] == "run end" for e in entries(station)), 60.0)
    finally:
        session.join(30.0)
    assert outside(station) == [
        (SERVICE.format("pause"), "pause", True), (TERMINAL, "pause", True), (TOPIC, "safety stop raised", True),
        ("cell", "safety event", True), ("cell", "run end", False)]  # the engine's pause for the safety stop, then the end it saw
    pages = [(e["who"], e["what"], e["role"]) for e in entries(station) if e["kind"] == "session"]
    assert pages == [("anna", w, OPERATOR) for w in ("login", "run start", "resume", "breakpoint set", "safety stop cleared", "stop")]
    assert next(e for e in entries(station) if e["what"] == "run end")["answer"] == "stopped"
