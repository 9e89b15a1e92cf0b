"""The reason on an engine status line belongs to that change of state only.

A run paused, resumed and stopped from the terminal printed ``STOPPING ... - resumed by terminal
console``: the engine kept the last reason it was given and repeated it on every later change.
Each change now carries its own reason or none: the live console, the trace's ``engine_state``
records and the status topic all say why *this* state was entered.
"""
from __future__ import annotations

import asyncio
import io
import json
from typing import Any

from app_builder import Cell, make_app

from cell_runner.operator_console import OperatorConsole
from execution_engine.app_model.model import ErrorPolicy
from execution_engine.observers import LivePrinter, RunObserver, TraceWriter
from node_transport.clock import Clock
from node_transport.wire import FaultKind

OPS = [{"left_arm": ("move_to_joint_pose", "initial")}, {"left_arm": ("gripper_close",)}, {"left_arm": ("gripper_open",)}]


def watch(cell: Cell) -> tuple[io.StringIO, io.StringIO]:
    """The live console view and the trace, wired as ``run --trace`` wires them."""
    observer = RunObserver(cell.deployment.transport.create_node("run_observer"), cell.robot.group_names)
    screen, trace = io.StringIO(), io.StringIO()
    printer, writer = LivePrinter(screen, (*cell.robot.group_names, "engine")), TraceWriter(trace)
    observer.engine_sinks += [printer.on_engine, writer.on_engine]
    observer.event_sinks += [printer.on_event, writer.on_event]
    return screen, trace


def engine_lines(screen: io.StringIO) -> list[str]:
    return [line.split("engine", 1)[1].strip() for line in screen.getvalue().splitlines() if "] engine " in line and " operator " not in line]


def states(trace: io.StringIO) -> list[tuple[str, str]]:
    return [(r["to"], r["message"]) for r in map(json.loads, trace.getvalue().splitlines()) if r["event"] == "engine_state"]


def test_pause_resume_stop_each_line_says_its_own_reason(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, io.StringIO, io.StringIO]:
        cell = await Cell(clock, durations={"move_joints": 3.0, "end_effector": 3.0}).start()
        screen, trace = watch(cell)
        console = OperatorConsole(cell.deployment.transport.create_node("operator_console"), io.StringIO(), cell.deployment.engine.operator_command)
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(1.0)
        await console.handle_line("p")
        await clock.sleep(2.0)
        await console.handle_line("r")
        await clock.sleep(1.0)
        await console.handle_line("s")
        return await run, screen, trace

    report, screen, trace = run_sim(main)
    assert report.outcome == "stopped"
    assert states(trace) == [
        ("running", ""),
        ("paused", "paused by terminal console (key 'p')"),
        ("running", "resumed by terminal console (key 'r')"),
        ("stopping", "stopped by terminal console (key 's')"),
        ("stopped", "stopped by terminal console (key 's')"),
    ]
    lines = engine_lines(screen)
    stopping = next(line for line in lines if line.startswith("STOPPING"))
    assert stopping.endswith("- stopped by terminal console (key 's')") and "resumed" not in stopping
    assert not any("resumed by" in line for line in lines if not line.startswith("RUNNING"))


def test_a_run_that_finishes_after_a_resume_stops_without_the_resume_reason(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, io.StringIO, io.StringIO]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 1.0}).start()
        screen, trace = watch(cell)
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(1.0)
        assert (await cell.operator("pause")).success
        await clock.sleep(1.0)
        assert (await cell.operator("resume")).success
        return await run, screen, trace

    report, screen, trace = run_sim(main)
    assert report.ok
    assert states(trace)[-2:] == [("stopping", ""), ("finished", "")]
    assert [line for line in engine_lines(screen) if line.startswith(("STOPPING", "FINISHED"))] == ["STOPPING operation 3/3", "FINISHED operation 3/3"]


def test_after_a_retried_failure_running_again_does_not_repeat_the_failure(run_sim: Any) -> None:
    async def main(clock: Clock) -> io.StringIO:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        _, trace = watch(cell)
        cell.backend.fail_next("left_arm", FaultKind.TIMEOUT, after=0.5, message="no answer")
        report = await cell.run(make_app(OPS, ErrorPolicy(retries=1)))
        assert report.ok
        return trace

    seen = states(run_sim(main))
    error = next(i for i, (state, _) in enumerate(seen) if state == "error")
    assert "no answer" in seen[error][1] and "retrying" in seen[error][1]
    assert seen[error + 1] == ("running", "")  # the failure was the reason of the error state, not of running again
    assert all("no answer" not in message for state, message in seen[error + 1:])


def test_a_step_pauses_with_its_own_reason(run_sim: Any) -> None:
    async def main(clock: Clock) -> io.StringIO:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 1.0}).start()
        _, trace = watch(cell)
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(0.5)
        assert (await cell.operator("pause")).success
        await clock.sleep(0.5)
        assert (await cell.operator("step")).success  # the rest of operation 1
        await clock.sleep(5.0)
        assert (await cell.operator("step")).success  # operation 2
        await clock.sleep(5.0)
        assert (await cell.operator("stop")).success
        await run
        return trace

    seen = states(run_sim(main))
    assert seen[1:5] == [
        ("paused", "paused by service /execution_engine/pause"),
        ("stepping", "one step by service /execution_engine/step"),
        ("paused", "one step done (operation 1): step or resume to go on"),
        ("stepping", "one step by service /execution_engine/step"),
    ]
    assert seen[5] == ("paused", "one step done (operation 2): step or resume to go on")
    assert seen[-2] == ("stopping", "stopped by service /execution_engine/stop")


def test_an_announcement_while_running_is_an_event_of_its_own_and_not_the_next_lines_reason(run_sim: Any) -> None:
    """A resumed run names the trace it continues (checkpoint/resume.py): that line is in the trace
    when it is said, and STOPPING does not say it again."""
    async def main(clock: Clock) -> io.StringIO:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 1.0}).start()
        _, trace = watch(cell)
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(1.0)
        cell.deployment.engine.announce("resumed from run.checkpoint.sqlite at operation 1; continues run.jsonl")
        await run
        return trace

    seen = states(run_sim(main))
    assert seen == [
        ("running", ""),
        ("running", "resumed from run.checkpoint.sqlite at operation 1; continues run.jsonl"),
        ("stopping", ""),
        ("finished", ""),
    ]
