"""Editing a paused ``sync="flags"`` run (issue 26 item 3): each group stands at its own operation, what no group has
started may change, the dry run starts every group from where it stands, and the run goes on with the edit.

In-process on simulated time, the Nextage simulator with its collision check, as ``run`` has it (test_paused_edit's
set-up: trace, MCAP recording, checkpoint).  The left arm holds at a breakpoint before ``closer`` while the right arm
waits inside ``right_wait`` for the flag the left one sets after it: two groups paused at different operations.
"""
from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from cell_runner.cli import main
from cell_runner.dry_run.remainder import remainder_app
from execution_engine.app_model import Application
from execution_engine.checkpoint.resume import check_same
from execution_engine.checkpoint.store import CheckpointError, CheckpointStore
from execution_engine.engine.remainder_groups import GroupAt
from execution_engine.engine.remainder_swap import PresentState, SwapAnswer, application_digest, decode_groups, encode_answer
from execution_engine.engine.report import RunReport
from execution_engine.record_reader import read_record
from node_transport.clock import Clock
from test_paused_edit import HOME, LEFT_IN, LEFT_OUT, REACH, RIGHT_OUT, PausedRun, edited_and_stopped, load, op, resumed, started

#: Where each group stands at the pause (the torso has no call: through from the start).
WHERE = "left_arm before operation 3, right_arm in operation 2, torso_head finished"
WIDER, RIGHT_WIDER = "0.30,0.25,0.10,180deg,0,90deg", "0.30,-0.25,0.10,180deg,0,90deg"


def flags_app(*operations: str) -> str:
    return '<?xml version="1.0"?>\n<application name="edit_flags" robot="nextage" sync="flags">\n' + "".join(operations) + "</application>\n"


def breaks(operation: str) -> str:
    """``operation`` with ``break="true"``."""
    return operation.replace('">\n', '" break="true">\n', 1)


RIGHT_WAIT = op("right_wait", right_arm=("wait_flag", "left_done"))
CLOSER = breaks(op("closer", left_arm=("move_to", LEFT_IN)))
LEFT_DONE = op("left_done", left_arm=("set_flag", "left_done"))
RIGHT_IN = op("right_in", right_arm=("move_to", "0.30,-0.12,0.10,180deg,0,90deg"))
OLD = flags_app(REACH, RIGHT_WAIT, CLOSER, LEFT_DONE, RIGHT_IN, HOME)
#: Another target for the left hand (renamed: its id shows it ran), and an operation more for the right one.
SAFE = flags_app(REACH, RIGHT_WAIT, breaks(op("wider", left_arm=("move_to", WIDER))), LEFT_DONE,
                 op("right_more", right_arm=("move_to", RIGHT_WIDER)), RIGHT_IN, HOME)
#: The left hand sent to where the right one stands (it waits there for the flag): the dry run finds the collision.
COLLIDES = flags_app(REACH, RIGHT_WAIT, breaks(op("closer", left_arm=("move_to", RIGHT_OUT))), LEFT_DONE, RIGHT_IN, HOME)


async def held(clock: Clock, app: Application, tmp: Path, right: Callable[[Any], bool] | None = None) -> PausedRun:
    """``app`` started and run until the left arm holds at its breakpoint and the right one waits for its flag
    (``right``: until that holds of the engine instead)."""
    run = await started(clock, app, tmp)
    engine = run.deployment.engine
    there = right or (lambda engine: engine.flags.waiting_for("right_arm") == "flag left_done")
    assert (await engine.operator_command("start", "test"))[0]
    for _ in range(600):  # bounded: 60 s of simulated time
        await clock.sleep(0.1)
        if engine.state == "paused" and there(engine):
            break
    assert engine.state == "paused" and there(engine) and "left_arm" in engine.breakpoints.held, engine.state
    return run


def started_calls(run: PausedRun) -> list[tuple[str, str]]:
    return [(r["operation"], r["group"]) for r in run.records("function_start")]


def test_a_safe_edit_is_swapped_with_each_group_where_it_stands_and_the_run_finishes_with_it(run_sim: Any, tmp_path: Path) -> None:
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)

    async def main_(clock: Clock) -> tuple[SwapAnswer, RunReport, PausedRun]:
        run = await held(clock, old, tmp_path)
        answer = await run.edit(new)
        assert run.deployment.engine.app is (new if answer.ok else old)
        return answer, await run.finish(), run

    answer, report, run = run_sim(main_)
    assert answer.ok, (answer.message, [f.message for f in answer.findings])
    assert answer.message.startswith("edit: swapped: the operations no group has started are ")
    assert WHERE in answer.message
    assert report.ok and report.operations_done == report.operations_total == 7, report.message
    calls = started_calls(run)
    assert ("wider", "left_arm") in calls and ("right_more", "right_arm") in calls and ("closer", "left_arm") not in calls
    assert calls.count(("reach", "left_arm")) == calls.count(("reach", "right_arm")) == 1  # nothing started twice
    waits = [(r["operation"], r["state"]) for r in run.records("flag") if r["group"] == "right_arm"]
    assert waits == [("right_wait", "waiting"), ("right_wait", "passed")]  # the flag waited for once, across the swap
    assert calls.index(("right_more", "right_arm")) < calls.index(("right_in", "right_arm"))

    digests = {"from_digest": application_digest(old), "to_digest": application_digest(new)}
    (swap,) = run.records("swap")
    assert {k: swap[k] for k in digests} == digests and swap["file"] == str(new.path)
    assert f"({WHERE})" in swap["message"]
    assert swap["groups"] == {"left_arm": {"where": "before", "operation": 3}, "right_arm": {"where": "in", "operation": 2},
                              "torso_head": {"where": "finished", "operation": 7}}
    recorded = []
    read_record(tmp_path / "run.mcap", lambda r: recorded.append(r) if r.get("event") == "swap" else None)
    assert [r["groups"] for r in recorded] == [swap["groups"]]  # the recording's event reads back the same
    assert answer.swap is not None and answer.swap.groups == (("left_arm", "before", 2), ("right_arm", "in", 1), ("torso_head", "finished", 6))
    assert decode_groups(encode_answer(answer.swap)) == {
        "left_arm": {"where": "before", "operation": 3}, "right_arm": {"where": "in", "operation": 2}, "torso_head": {"where": "finished", "operation": 7}}
    with open(tmp_path / "run.mcap", "rb") as stream:
        described = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    edit = described["dual_arm_executive_edit_1"]
    assert (edit["from_digest"], edit["to_digest"], edit["groups"]) == (digests["from_digest"], digests["to_digest"], WHERE)
    store = CheckpointStore(tmp_path / "run.checkpoint.sqlite", read_only=True)
    (row,) = store.swaps()
    assert row[3:] == (digests["from_digest"], digests["to_digest"], str(new.path))
    assert store.meta()["swap_1_groups"] == WHERE
    check_same(store, new)  # a resume goes on with the edited application
    with pytest.raises(CheckpointError, match=r"the run was edited while paused .* goes on with .*safe.xml"):
        check_same(store, old)
    store.close()
    assert any("edited while paused" in line and WHERE in line for line in report.summary_lines())


def test_an_edit_that_would_collide_with_the_arm_waiting_for_its_flag_is_refused_and_the_old_remainder_runs(run_sim: Any, tmp_path: Path) -> None:
    old, colliding = load(tmp_path, "old.xml", OLD), load(tmp_path, "collide.xml", COLLIDES)

    async def main_(clock: Clock) -> tuple[SwapAnswer, RunReport, PausedRun]:
        run = await held(clock, old, tmp_path)
        answer = await run.edit(colliding)
        engine = run.deployment.engine
        assert engine.state == "paused" and engine.app is old and not engine.remainder.swaps
        return answer, await run.finish(), run

    answer, report, run = run_sim(main_)
    assert not answer.ok and answer.message.startswith("edit: not swapped: ")
    assert "found by the dry run of the operations no group has started from where the robot is" in answer.message
    line = COLLIDES.splitlines().index('    <left_arm><function name="move_to"><params><param value="%s"/></params></function></left_arm>' % RIGHT_OUT) + 1
    assert any(f.line == line and "collision between left_arm hand" in f.message and "operation closer left_arm move_to" in f.message
               for f in answer.findings), [(f.line, f.message) for f in answer.findings]
    assert report.ok and report.operations_total == 6 and not report.edits
    assert ("closer", "left_arm") in started_calls(run) and run.records("swap") == []


def test_edits_of_what_a_group_has_started_or_left_behind_are_refused_naming_the_operation(run_sim: Any, tmp_path: Path) -> None:
    old = load(tmp_path, "old.xml", OLD)
    waiting_changed = load(tmp_path, "wait.xml", flags_app(REACH, op("right_wait", right_arm=("wait_flag", "other")), CLOSER,
                                                           LEFT_DONE, op("other", left_arm=("set_flag", "other")), RIGHT_IN, HOME))
    reach_changed = load(tmp_path, "reach.xml", flags_app(op("reach", left_arm=("move_to", WIDER), right_arm=("move_to", RIGHT_OUT)),
                                                          RIGHT_WAIT, CLOSER, LEFT_DONE, RIGHT_IN, HOME))
    behind = load(tmp_path, "behind.xml", flags_app(REACH, op("sneak", right_arm=("move_to", RIGHT_WIDER)), RIGHT_WAIT, CLOSER, LEFT_DONE, RIGHT_IN, HOME))
    same = load(tmp_path, "same.xml", OLD.replace("\n  <operation", "\n\n  <operation"))
    lockstep = load(tmp_path, "lockstep.xml", flags_app(REACH, HOME).replace(' sync="flags"', ""))

    async def main_(clock: Clock) -> tuple[list[str], RunReport]:
        run = await held(clock, old, tmp_path)
        answers = [(await run.edit(app)).message for app in (waiting_changed, reach_changed, behind, same, lockstep)]
        assert run.deployment.engine.app is old
        return answers, await run.finish()

    answers, report = run_sim(main_)
    assert answers[0] == "edit: operation 2 'right_wait' is running (right_arm started it); only operations no group has started may change"
    assert answers[1] == "edit: operation 1 'reach' has already run (left_arm started it); only operations no group has started may change"
    assert answers[2].startswith("edit: operation 2 'sneak' gives right_arm a call before operation 3 'right_wait', which right_arm is in: it would never run it")
    assert answers[3] == "edit: nothing to change: the operations no group has started are the run's"
    assert answers[4].startswith("edit: the edited application changes the sync (flags -> operation)")
    assert report.ok and report.operations_total == 6 and not report.edits


#: The right arm works 40 s (a wait) in right_hold while the left one holds at its breakpoint: it still moves.
BUSY = flags_app(REACH, op("right_hold", right_arm=("wait", "40")), CLOSER, LEFT_DONE, RIGHT_IN, HOME)


async def busy_held(clock: Clock, app: Application, tmp: Path) -> PausedRun:
    """``app`` (BUSY's) started and run until the left arm holds at its breakpoint while the right one is in right_hold."""
    return await held(clock, app, tmp, lambda engine: engine.remainder.groups.at["right_arm"].inside == "right_hold")


def test_a_group_still_running_beside_the_held_one_is_paused_before_the_edit_is_taken(run_sim: Any, tmp_path: Path) -> None:
    old = load(tmp_path, "old.xml", BUSY)
    new = load(tmp_path, "new.xml", BUSY.replace(f'value="{LEFT_IN}"', f'value="{WIDER}"'))

    async def main_(clock: Clock) -> tuple[str, SwapAnswer, RunReport, PausedRun]:
        run = await busy_held(clock, old, tmp_path)
        engine = run.deployment.engine
        refused = (await run.edit(new)).message
        assert (await engine.operator_command("pause", "test"))[0]  # now the right arm stands too (its machine in Pause)
        answer = await run.edit(new)
        return refused, answer, await run.finish(), run

    refused, answer, report, run = run_sim(main_)
    assert refused == ("edit: right_arm is still running (in operation 2 'right_hold'): the run holds only some groups; "
                       "pause it (Pause) and apply again")
    assert answer.ok and WHERE in answer.message, answer.message
    assert report.ok and report.operations_done == 6
    ended = [(r["operation"], r["group"], r["outcome"]) for r in run.records("function_end")]
    assert ("right_hold", "right_arm", "succeeded") in ended and ("closer", "left_arm", "succeeded") in ended


def test_the_dry_run_of_a_flags_remainder_starts_each_group_where_it_stands_with_the_flags_set_and_the_zone_held_first(tmp_path: Path) -> None:
    """What the check of an edit runs (remainder_app): the calls each group ended are left out, the one it is in runs
    again from where the arm is, a flag set stays set (set first), and the call inside a zone goes ahead of every other
    call (its operation split: the holder's call in front, the others' where they were)."""
    app = load(tmp_path, "app.xml", flags_app(REACH, RIGHT_WAIT, op("both_in", left_arm=("move_to", LEFT_IN), right_arm=("move_to", RIGHT_WIDER)),
                                              LEFT_DONE, RIGHT_IN, HOME))
    state = PresentState(2, {}, ("tray_ready",), {}, {"left_arm": GroupAt(done=("reach",), inside="both_in"), "right_arm": GroupAt(done=("reach",), inside="right_wait"),
                                                     "torso_head": GroupAt(finished=True)}, {"hands": ("both_in", "left_arm")})
    rest = remainder_app(app, state)
    calls = [(o.id, {g: c.function for g, c in o.calls.items() if not c.implicit}) for o in rest.operations]
    assert calls == [("present_flag_1", {"left_arm": "set_flag"}), ("both_in", {"left_arm": "move_to"}), ("right_wait", {"right_arm": "wait_flag"}),
                     ("both_in", {"right_arm": "move_to"}), ("left_done", {"left_arm": "set_flag"}), ("right_in", {"right_arm": "move_to"}),
                     ("home", {"left_arm": "move_to_joint_pose", "right_arm": "move_to_joint_pose"})]
    assert rest.operations[1].calls["left_arm"].line == app.operation("both_in").calls["left_arm"].line  # findings land on the file's lines


def test_a_step_after_the_swap_runs_the_held_groups_next_edited_operation_and_holds_before_the_one_after(run_sim: Any, tmp_path: Path) -> None:
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)

    async def main_(clock: Clock) -> tuple[list[str], RunReport, PausedRun]:
        run = await held(clock, old, tmp_path)
        engine = run.deployment.engine
        assert (await run.edit(new)).ok
        assert (await engine.operator_command("step", "test"))[0]
        for _ in range(300):  # bounded: 30 s of simulated time
            await clock.sleep(0.1)
            if engine.state == "paused" and "left_arm" in engine.breakpoints.held:
                break
        holds = [f"{g} {engine.app.operations[h.index].id} {h.kind}" for g, h in engine.breakpoints.held.items()]
        return holds, await run.finish(), run

    holds, report, run = run_sim(main_)
    assert holds == ["left_arm left_done step"]
    assert report.ok and report.operations_done == 7
    ended = [(r["operation"], r["group"]) for r in run.records("function_end") if r["outcome"] == "succeeded"]
    assert ended.index(("wider", "left_arm")) < ended.index(("right_more", "right_arm"))  # the right arm went on once the flag was set


def test_a_flags_run_stopped_after_a_swap_resumes_each_group_after_its_done_calls_with_the_edited_file(run_sim: Any, tmp_path: Path) -> None:
    """``run EDITED.xml --resume CHECKPOINT``: each group goes on after the calls it had done (none run twice), the
    flag wait the right arm was in runs again and passes once the left arm sets it; the old file is refused."""
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)
    assert run_sim(lambda clock: edited_and_stopped(held(clock, old, tmp_path), new)).ok
    records = resumed(tmp_path, new)
    started = [(r["operation"], r["group"]) for r in records if r["event"] == "function_start"]
    assert started[0] == ("wider", "left_arm") and ("reach", "left_arm") not in started and ("reach", "right_arm") not in started
    assert started.count(("right_more", "right_arm")) == 1 and ("home", "right_arm") in started
    assert [(r["group"], r["state"]) for r in records if r["event"] == "flag" and r["operation"] == "right_wait"][-1] == ("right_arm", "passed")
    assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "finished"
    err = io.StringIO()
    assert main(["run", str(old.path), "--resume", str(tmp_path / "run.checkpoint.sqlite"), "--speed", "max", "--quiet"], out=io.StringIO(), err=err) == 2
    assert "the run was edited while paused" in err.getvalue() and "goes on with" in err.getvalue()


def test_a_flags_run_resumed_from_its_checkpoint_skips_the_interrupted_call_when_told_and_redoes_nothing_done(run_sim: Any, tmp_path: Path) -> None:
    """A crash resume of a sync="flags" run (no edit): the right arm was stopped inside right_hold, the left arm held
    before closer; ``--on-interrupted skip`` takes right_hold as done, and no call done before runs again."""
    old = load(tmp_path, "old.xml", BUSY)

    async def main_(clock: Clock) -> None:
        await (await busy_held(clock, old, tmp_path)).finish("stop")

    run_sim(main_)
    records = resumed(tmp_path, old, "--on-interrupted", "skip")
    calls = [(r["operation"], r["group"]) for r in records if r["event"] == "function_start"]
    assert ("closer", "left_arm") in calls and ("right_hold", "right_arm") not in calls
    assert ("reach", "left_arm") not in calls and ("right_in", "right_arm") in calls
    assert records[-1]["outcome"] == "finished"
