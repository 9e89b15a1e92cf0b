"""What operators did, and the alarm they answer: in the trace, in the report, on the wall clock.

Every operator command -- from the terminal console of ``run --interactive`` or a call of the
``/execution_engine/*`` services -- and every change of the engine's state is a line of the
JSON trace; the run report lists the commands with their run time and source.  An alarm names
the key and the service that answer it, and its timeout counts the operator's wall time even
when the robot's clock is simulated.
"""
from __future__ import annotations

import asyncio
import io
import json
from typing import Any

import pytest
from app_builder import Cell, make_app

from cell_runner.operator_console import OperatorConsole
from execution_engine.app_model.model import ErrorPolicy
from execution_engine.observers import LivePrinter, RunObserver, TraceWriter
from node_transport.clock import Clock, VirtualTimeLoop, run_with_clock, simulated_clock
from node_transport.msgs import Bool
from node_transport.qos import LATCHED
from node_transport.wall_clock import ManualWallClock, RealWallClock, wake_loop
from node_transport.wire import SAFETY_STOP, FaultKind

OPS = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("gripper_open",)}, {"left_arm": ("gripper_close",)}]


def trace_to(cell: Cell, stream: io.StringIO, screen: io.StringIO) -> None:
    """Wire a trace writer and the live console view as ``run --trace`` does."""
    observer = RunObserver(cell.deployment.transport.create_node("run_observer"), cell.robot.group_names)
    writer = TraceWriter(stream)
    printer = LivePrinter(screen, (*cell.robot.group_names, "engine"))
    observer.sinks.append(writer.on_status)
    observer.engine_sinks.append(writer.on_engine)
    observer.event_sinks.append(writer.on_event)
    observer.engine_sinks.append(printer.on_engine)
    observer.event_sinks.append(printer.on_event)


def engine_lines(stream: io.StringIO, event: str) -> list[dict[str, Any]]:
    return [r for r in map(json.loads, stream.getvalue().splitlines()) if r["group"] == "engine" and r["event"] == event]


def test_operator_commands_from_the_console_and_the_services_are_in_the_trace_and_the_report(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, io.StringIO, str]:
        cell = await Cell(clock, durations={"move_joints": 3.0, "end_effector": 3.0}).start()
        trace, screen = io.StringIO(), io.StringIO()
        trace_to(cell, trace, screen)
        console = OperatorConsole(cell.deployment.transport.create_node("operator_console"), screen, cell.deployment.engine.operator_command)
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(1.0)
        assert (await cell.operator("pause")).success
        await clock.sleep(4.0)
        await console.handle_line("x\n")  # no alarm: refused, and still recorded
        await console.handle_line("r\n")
        return await run, trace, screen.getvalue()

    report, trace, screen = run_sim(main)
    assert report.ok
    actions = [(round(a.t, 2), a.command, a.source, a.state, a.accepted) for a in report.operator_actions]
    assert actions == [
        (1.0, "pause", "service /execution_engine/pause", "running", True),
        (5.0, "reset", "terminal console (key 'x')", "paused", False),
        (5.0, "resume", "terminal console (key 'r')", "paused", True),
    ]
    assert "resume: ok - resumed" in screen  # the console's answer
    assert "operator pause from service /execution_engine/pause: accepted - paused" in screen  # the live view
    summary = report.summary_lines()
    assert "  operator: pause at 1.00 s from service /execution_engine/pause (in running): accepted - paused" in summary
    operators = engine_lines(trace, "operator")
    assert [(r["t"], r["command"], r["source"], r["accepted"]) for r in operators] == [
        (pytest.approx(1.0), "pause", "service /execution_engine/pause", True),
        (pytest.approx(5.0), "reset", "terminal console (key 'x')", False),
        (pytest.approx(5.0), "resume", "terminal console (key 'r')", True),
    ]
    assert operators[1]["answer"] == "no alarm to reset (paused)"
    states = [(r["from"], r["to"]) for r in engine_lines(trace, "engine_state")]
    assert states == [("idle", "running"), ("running", "paused"), ("paused", "running"), ("running", "stopping"), ("stopping", "finished")]
    paused = next(r for r in engine_lines(trace, "engine_state") if r["to"] == "paused")
    assert paused["t"] == pytest.approx(1.0) and paused["message"] == "paused by service /execution_engine/pause"
    times = [r["t"] for r in map(json.loads, trace.getvalue().splitlines())]
    assert times == sorted(times)


def test_the_safety_stop_and_an_answer_to_an_alarm_are_recorded_with_their_source(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        cell = await Cell(clock, durations={"move_joints": 3.0}).start()
        console = OperatorConsole(cell.deployment.transport.create_node("operator_console"), io.StringIO(), cell.deployment.engine.operator_command)
        cell.backend.fail_next("left_arm", FaultKind.COLLISION, after=0.5, message="contact")
        safety = cell.node.create_publisher(Bool, SAFETY_STOP, LATCHED)
        run = asyncio.ensure_future(cell.run(make_app(OPS, ErrorPolicy(action="alarm"))))
        await clock.sleep(10.0)  # in alarm since 1.5 s
        safety.publish(Bool(True))  # the alarm holds every group already: the pause is refused, but recorded
        await clock.sleep(1.0)
        await console.handle_line("s\n")
        return await run

    report = run_sim(main)
    assert report.outcome == "stopped"
    actions = [(a.command, a.source, a.state, a.accepted) for a in report.operator_actions]
    assert actions == [
        ("pause", "safety stop on /cell/safety_stop", "alarm", False),
        ("stop", "terminal console (key 's')", "alarm", True),
    ]
    assert report.errors[0].recovery.endswith("alarm answered with stop")


def test_the_alarm_says_which_key_and_which_service_answer_it(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[dict[str, Any]]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.VISION, after=0.5, message="hole not found")
        run = asyncio.ensure_future(cell.run(make_app(OPS, ErrorPolicy(action="alarm", alarm_timeout=120.0))))
        await clock.sleep(5.0)
        assert (await cell.operator("stop")).success
        await run
        return cell.engine_states

    states = run_sim(main)
    message = next(s["message"] for s in states if s["state"] == "alarm")
    assert message.startswith("ALARM left_arm: move_joints")
    assert "hole not found" in message
    assert "to retry: key 'x' (run --interactive) or call /execution_engine/reset" in message
    assert "to abort: key 's' or call /execution_engine/stop" in message
    assert "gives up after 120 s (wall clock)" in message


def test_alarm_timeout_counts_the_operators_wall_time_not_the_simulated_robot_time(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str]]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        wall = ManualWallClock()
        cell.deployment.engine.wall_clock = wall
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        run = asyncio.ensure_future(cell.run(make_app(OPS, ErrorPolicy(action="alarm", alarm_timeout=30.0))))
        seen = []
        await clock.sleep(300.0)  # ten times the timeout in simulated time passes in no time: nobody could have answered
        seen.append(cell.deployment.engine.state)
        wall.advance(29.0)
        await clock.sleep(0.1)
        seen.append(cell.deployment.engine.state)
        wall.advance(1.0)  # 30 s of the operator's time
        return await run, seen + [cell.deployment.engine.state]

    report, seen = run_sim(main)
    assert seen[:2] == ["alarm", "alarm"]
    assert report.outcome == "failed" and "alarm not answered within 30 s (wall clock)" in report.message
    assert report.total > 300.0


def test_a_wall_clock_deadline_wakes_a_virtual_time_loop_from_its_timer_thread() -> None:
    """The real mechanism: a thread's deadline reaches a loop that is blocked with nothing to run."""

    async def main(clock: Clock) -> float:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, VirtualTimeLoop)
        woke: asyncio.Future[None] = loop.create_future()
        RealWallClock().call_later(0.0, wake_loop(loop, lambda: woke.set_result(None)))
        await woke  # no timer pending: the loop blocks in select until the thread writes its self-pipe
        return clock.now()

    assert run_with_clock(main, simulated_clock()) == 0.0
