"""Breakpoints and "run to here" on the simulated clock (issue 26 item 1).

A breakpoint pauses the run before its operation -- in lock-step every group at its barrier, with
``sync="flags"`` only the group that reaches it while the others go on -- says why in the engine's
status, the trace and the run report, and the run goes on with resume, step or run-to.  Every wait
below is on the virtual clock, bounded by the run itself.
"""
from __future__ import annotations

import asyncio
import dataclasses
import io
import json
from typing import Any

import pytest
from app_builder import Cell, make_app

from execution_engine.app_model.model import Application
from execution_engine.engine.breakpoint_set import BreakpointSet
from execution_engine.observers import RunObserver, TraceWriter
from node_transport.clock import Clock

MOVE = ("move_to_joint_pose", "initial")
#: left_arm and right_arm each busy 2 s per operation; operation 3 is the breakpoint's.
OPS = [{"left_arm": MOVE, "right_arm": ("gripper_open",)} for _ in range(5)]
DURATIONS = {"move_joints": 2.0, "end_effector": 2.0}


def with_breaks(app: Application, *numbers: int, sync: str = "operation") -> Application:
    """``app`` with break="true" on the operations numbered (from 1), in ``sync`` mode."""
    ops = tuple(dataclasses.replace(op, breakpoint=True) if i + 1 in numbers else op for i, op in enumerate(app.operations))
    return dataclasses.replace(app, operations=ops, sync=sync)


def traced(cell: Cell) -> io.StringIO:
    """The run's JSON-lines trace, as ``run --trace`` writes it."""
    stream = io.StringIO()
    observer = RunObserver(cell.deployment.transport.create_node("trace"), cell.robot.group_names)
    writer = TraceWriter(stream)
    observer.sinks.append(writer.on_status)
    observer.engine_sinks.append(writer.on_engine)
    observer.event_sinks.append(writer.on_event)
    return stream


def records(stream: io.StringIO, event: str) -> list[dict[str, Any]]:
    return [r for r in map(json.loads, stream.getvalue().splitlines()) if r["event"] == event]


def started(cell: Cell, group: str) -> list[str]:
    """The operations whose function ``group`` has started so far."""
    return [e["operation"] for e in cell.events if e["event"] == "function_start" and e["group"] == group]


async def until_state(cell: Cell, clock: Clock, state: str, bound: float = 60.0) -> None:
    """Until the engine is in ``state``; bounded in run time."""
    deadline = clock.now() + bound
    while cell.deployment.engine.state != state:
        assert clock.now() < deadline, f"the engine never got to {state} (it is {cell.deployment.engine.state})"
        await clock.sleep(0.05)


def test_lock_step_pauses_every_group_at_the_barrier_before_the_operation_and_says_why(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        trace = traced(cell)
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(OPS), 3)))
        await until_state(cell, clock, "paused")
        engine = cell.deployment.engine
        at_pause = (clock.now(), engine.state, engine._message, started(cell, "left_arm"), started(cell, "right_arm"),
                    {g: link.state for g, link in engine.links.items()})
        await clock.sleep(30.0)  # held for as long as the operator looks: nothing starts
        still = (started(cell, "left_arm"), started(cell, "right_arm"))
        assert (await cell.operator("resume")).success
        report = await run
        return at_pause, still, report, trace, cell.engine_states

    (t, state, message, left, right, machines), still, report, trace, statuses = run_sim(main)
    assert state == "paused" and message == "paused at breakpoint before operation 3 '3' (line 3)"
    assert t == pytest.approx(4.0, abs=0.1)  # operations 1 and 2, 2 s each
    assert left == right == ["1", "2"]  # both at the barrier: neither started operation 3
    assert set(machines.values()) == {"Ready"}
    assert still == (["1", "2"], ["1", "2"])
    assert report.ok and report.operations_done == 5
    assert [(h.operation, h.kind, h.groups, h.held) for h in report.breakpoints] == [("3", "break", ("left_arm", "right_arm", "torso_head"), True)]
    assert "  breakpoint at 4.00 s: paused at breakpoint before operation 3 '3' (line 3)" in report.summary_lines()
    paused = [s for s in statuses if s["state"] == "paused"]
    assert paused and paused[0]["operation_index"] == 3 and paused[0]["message"].startswith("paused at breakpoint before operation 3")
    (hit,) = records(trace, "breakpoint")
    assert (hit["group"], hit["operation"], hit["kind"], hit["held"]) == ("engine", "3", "break", True)
    assert hit["message"] == "paused at breakpoint before operation 3 '3' (line 3)"


def test_flags_mode_holds_only_the_group_that_reaches_it(run_sim: Any) -> None:
    ops = [{"left_arm": MOVE}, {"left_arm": MOVE}, {"right_arm": ("gripper_open",)}, {"right_arm": ("gripper_close",)},
           {"right_arm": ("gripper_open",)}, {"left_arm": MOVE}]

    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        trace = traced(cell)
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(ops), 2, sync="flags")))
        await until_state(cell, clock, "paused")
        held_at = clock.now()
        message = cell.deployment.engine._message
        await clock.sleep(10.0)  # the right arm goes on through its three operations meanwhile
        during = (started(cell, "left_arm"), started(cell, "right_arm"))
        assert (await cell.operator("resume")).success
        report = await run
        return held_at, message, during, report, trace

    held_at, message, (left, right), report, trace = run_sim(main)
    assert held_at == pytest.approx(2.0, abs=0.1)
    assert message == ("paused at breakpoint before operation 2 '2' (line 2); left_arm holds there, "
                       "the other groups go on until they need it")
    assert left == ["1"] and right == ["3", "4", "5"]
    assert report.ok and [h.groups for h in report.breakpoints] == [("left_arm",)]
    (hit,) = records(trace, "breakpoint")
    assert (hit["group"], hit["operation"], hit["groups"]) == ("left_arm", "2", ["left_arm"])


def test_step_runs_one_operation_and_pauses_again_in_both_modes(run_sim: Any) -> None:
    def run_mode(sync: str) -> tuple[list[str], list[str], Any]:
        async def main(clock: Clock) -> tuple[list[str], list[str], Any]:
            cell = await Cell(clock, durations=DURATIONS).start()
            run = asyncio.ensure_future(cell.run(with_breaks(make_app(OPS), 2, sync=sync)))
            await until_state(cell, clock, "paused")
            assert (await cell.operator("step")).success
            await until_state(cell, clock, "stepping")
            await until_state(cell, clock, "paused")
            after_step = started(cell, "left_arm")
            message = cell.deployment.engine._message
            assert (await cell.operator("resume")).success
            return after_step, [message], await run

        return run_sim(main)

    after, (message,), report = run_mode("operation")
    assert after == ["1", "2"] and report.ok
    assert message == "one step done (operation 2): step or resume to go on"
    after, (message,), report = run_mode("flags")
    assert after == ["1", "2"] and report.ok
    assert message.startswith("one step done: paused before operation 3 '3' (line 3); ")
    assert [h.kind for h in report.breakpoints] == ["break", "break", "step", "step"]  # both arms reach 2, then each holds again before 3


def test_run_to_here_pauses_before_the_chosen_operation_once(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        trace = traced(cell)
        engine = cell.deployment.engine
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(OPS), 2)))
        await until_state(cell, clock, "paused")  # the breakpoint before 2
        behind = await engine.breakpoint_command("run_to", "1", "studio")
        here = await engine.breakpoint_command("run_to", "2", "studio")
        ahead = await engine.breakpoint_command("run_to", "#4", "studio")
        await until_state(cell, clock, "running")
        await until_state(cell, clock, "paused")
        at_target = (started(cell, "left_arm"), engine._message)
        assert (await cell.operator("resume")).success
        return behind, here, ahead, at_target, await run, trace

    behind, here, ahead, (left, message), report, trace = run_sim(main)
    assert behind == (False, "operation 1 '1' (line 1) has already run (the run is at operation 2)")
    assert here == (False, "the run is paused before operation 2 '2' (line 2) already: Step runs it, Resume goes on")
    assert ahead == (True, "running to operation 4 '4' (line 4): the run pauses before it")
    assert left == ["1", "2", "3"] and message == "paused before operation 4 '4' (line 4): the run-to target is reached"
    assert report.ok and [(h.operation, h.kind) for h in report.breakpoints] == [("2", "break"), ("4", "run_to")]
    run_to = [r for r in records(trace, "operator") if r["command"] == "run_to"]
    assert [(r["target"], r["source"], r["accepted"]) for r in run_to] == [("1", "studio", False), ("2", "studio", False), ("4", "studio", True)]
    said = "s from studio (in paused): accepted - running to operation 4 '4' (line 4): the run pauses before it"
    assert any(line.startswith("  operator: run_to 4 at 2.") and line.endswith(said) for line in report.summary_lines())


def test_breakpoints_set_and_cleared_at_run_time_without_the_file(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        engine = cell.deployment.engine
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(OPS), 2)))
        await clock.sleep(1.0)  # operation 1 runs
        answers = [
            await engine.breakpoint_command("clear", "2", "terminal console (key 'b')"),
            await engine.breakpoint_command("toggle", "", "terminal console (key 'b')"),  # the next one: 2 again
            await engine.breakpoint_command("set", "#4", "studio"),
            await engine.breakpoint_command("set", "nine", "studio"),
            await engine.breakpoint_command("clear_all", "", "studio"),
            await engine.breakpoint_command("set", "5", "studio"),
        ]
        ids = engine.breakpoints.ids()
        await until_state(cell, clock, "paused")
        where = engine._message
        assert (await cell.operator("resume")).success
        return answers, ids, where, await run

    answers, ids, where, report = run_sim(main)
    assert answers == [
        (True, "breakpoint cleared before operation 2 '2' (line 2)"),
        (True, "breakpoint set before operation 2 '2' (line 2)"),
        (True, "breakpoint set before operation 4 '4' (line 4)"),
        (False, "no operation 'nine' in this run: give an operation's id or #N (1 to 5, as the engine's status counts them)"),
        (True, "every breakpoint cleared (2 were set)"),
        (True, "breakpoint set before operation 5 '5' (line 5)"),
    ]
    assert ids == ["5"] and where.startswith("paused at breakpoint before operation 5 ")
    assert [(a.command, a.target, a.accepted) for a in report.operator_actions][:5] == [
        ("unbreak", "2", True), ("break", "2", True), ("break", "4", True), ("break", "nine", False), ("unbreak_all", "", True)]


def test_without_an_operator_a_breakpoint_is_passed_and_said(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        cell = await Cell(clock, durations=DURATIONS).start()
        cell.deployment.engine.operators = False  # run without --interactive: nobody could continue a pause
        return await cell.run(with_breaks(make_app(OPS), 3))

    report = run_sim(main)
    assert report.ok and report.operations_done == 5
    (hit,) = report.breakpoints
    assert not hit.held and hit.message.startswith("breakpoint before operation 3 '3' (line 3) passed: nobody can continue a paused run here")


def test_a_flag_wait_does_not_time_out_while_its_setter_is_held(run_sim: Any) -> None:
    ops = [{"left_arm": MOVE, "right_arm": ("wait_flag", "part_ready", "5")}, {"left_arm": ("set_flag", "part_ready")},
           {"right_arm": ("gripper_open",)}]

    async def main(clock: Clock) -> Any:
        cell = await Cell(clock, durations=DURATIONS).start()
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(ops), 2, sync="flags")))
        await until_state(cell, clock, "paused")
        await clock.sleep(20.0)  # four times the wait's 5 s
        assert (await cell.operator("resume")).success
        return await run

    report = run_sim(main)
    assert report.ok and not report.errors
    assert [w.outcome for w in report.flag_waits] == ["passed"]


def test_an_edited_remainder_takes_its_files_breakpoints_and_keeps_those_set_at_run_time() -> None:
    old = with_breaks(make_app(OPS), 2)
    run = object()
    bp = BreakpointSet()
    bp.ensure(old, run)
    bp.active.add("4")  # set at run time
    bp.target = "3"
    new = with_breaks(make_app(OPS), 5)
    edited = dataclasses.replace(new, operations=new.operations[:2] + new.operations[3:])
    bp.ensure(old, run)  # the same run: nothing starts over
    bp.adopt(edited)
    assert bp.ids() == ["4", "5"] and bp.target is None  # 2's breakpoint was the old file's; operation 3 is gone


class Resumed:
    """Where a resumed run starts (checkpoint/resume.py's ResumePlan, without a crash before it): operation 3."""

    index = 2
    outcomes: dict[str, str] = {}

    async def first_operation(self, engine: Any, operation: Any) -> Any:
        return operation


def test_a_resumed_run_keeps_the_files_breakpoints_after_where_it_starts(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        engine = cell.deployment.engine
        run = asyncio.ensure_future(engine.run(with_breaks(make_app(OPS), 1, 4), Resumed()))
        await until_state(cell, clock, "paused")
        at = (engine._message, started(cell, "left_arm"))
        assert (await cell.operator("resume")).success
        report = await run
        await cell.deployment.close()
        return at, report

    (message, left), report = run_sim(main)
    assert message == "paused at breakpoint before operation 4 '4' (line 4)" and left == ["3"]  # 1 was done before the crash
    assert report.ok and [h.operation for h in report.breakpoints] == ["4"]


def test_flags_mode_a_partner_already_at_the_barrier_does_not_time_out_while_the_other_is_held(run_sim: Any) -> None:
    ops = [{"left_arm": MOVE}, {"left_arm": MOVE}, {"left_arm": ("full_body_move", "initial"), "right_arm": ("full_body_move", "initial")}]

    async def main(clock: Clock) -> Any:
        cell = await Cell(clock, durations={**DURATIONS, "full_body": 1.0}).start()
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(ops), 2, sync="flags")))
        await until_state(cell, clock, "paused")
        await clock.sleep(60.0)  # twice the barrier's 30 s: the right arm has waited there since the start
        assert (await cell.operator("resume")).success
        return await run

    report = run_sim(main)
    assert report.ok and not report.errors, report.summary_lines()


def test_stop_at_a_breakpoint_ends_the_run_there_in_both_modes(run_sim: Any) -> None:
    def stopped(sync: str) -> tuple[Any, list[str], float]:
        async def main(clock: Clock) -> tuple[Any, list[str], float]:
            cell = await Cell(clock, durations=DURATIONS).start()
            run = asyncio.ensure_future(cell.run(with_breaks(make_app(OPS), 3, sync=sync)))
            await until_state(cell, clock, "paused")
            t = clock.now()
            assert (await cell.operator("stop")).success
            report = await run
            return report, started(cell, "left_arm"), clock.now() - t

        return run_sim(main)

    for sync in ("operation", "flags"):
        report, left, took = stopped(sync)
        assert report.outcome == "stopped" and left == ["1", "2"] and took < 5.0, sync


def test_flags_mode_run_to_holds_the_group_that_reaches_the_target(run_sim: Any) -> None:
    ops = [{"left_arm": MOVE}, {"left_arm": MOVE}, {"left_arm": MOVE}, {"right_arm": ("gripper_open",)}, {"right_arm": ("gripper_close",)}]

    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations=DURATIONS).start()
        engine = cell.deployment.engine
        run = asyncio.ensure_future(cell.run(with_breaks(make_app(ops), sync="flags")))
        await clock.sleep(1.0)
        answer = await engine.breakpoint_command("run_to", "3", "studio")
        await until_state(cell, clock, "paused")
        at = (clock.now(), engine._message, started(cell, "left_arm"), started(cell, "right_arm"))
        assert (await cell.operator("resume")).success
        return answer, at, await run

    answer, (t, message, left, right), report = run_sim(main)
    assert answer == (True, "running to operation 3 '3' (line 3): the run pauses before it")
    assert t == pytest.approx(4.0, abs=0.1) and left == ["1", "2"] and right == ["4", "5"]
    assert message.startswith("paused before operation 3 '3' (line 3): the run-to target is reached; left_arm holds there")
    assert report.ok and [(h.operation, h.kind, h.groups) for h in report.breakpoints] == [("3", "run_to", ("left_arm",))]
