"""Editing a paused run (issue 26 item 3): the operations not started are swapped for an edited application's only
when the done part is unchanged and the dry run of the new remainder from where the robot is finds nothing.

In-process on simulated time, the Nextage simulator with its collision check, as ``run`` has it; the edit goes
through the engine's entry (:func:`swap_remainder`) with the wiring's check (:func:`remainder_check`), as the
studio's route calls them.
"""
from __future__ import annotations

import asyncio
import io
import json
from collections.abc import Awaitable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from app_functions.registry import full_catalog
from cell_runner.cli import main
from cell_runner.console_edit import console_editor
from cell_runner.deployment import Deployment, deploy_local
from cell_runner.dry_run.remainder import remainder_app, remainder_check
from cell_runner.dry_run.runner import dry_run_setup
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.start import backend_measure
from cell_runner.operator_console import OperatorConsole
from cell_runner.record_hook import record_node
from execution_engine.app_model import Application, load_application
from execution_engine.checkpoint.resume import app_meta, check_same
from execution_engine.checkpoint.store import CheckpointError, CheckpointStore
from execution_engine.checkpoint.writer import CheckpointWriter
from core_functions.geometry import Pose
from execution_engine.engine.remainder_swap import PresentState, SwapAnswer, application_digest, swap_remainder
from execution_engine.engine.report import RunReport
from execution_engine.observers import RunObserver, TraceWriter
from execution_engine.record_reader import read_record
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
LEFT_OUT, RIGHT_OUT, LEFT_IN = "0.30,0.20,0.10,180deg,0,90deg", "0.30,-0.20,0.10,180deg,0,90deg", "0.30,0.12,0.10,180deg,0,90deg"


def op(id_: str, **calls: tuple[str, ...]) -> str:
    body = "".join(
        f'    <{g}><function name="{f}"><params>' + "".join(f'<param value="{p}"/>' for p in params) + f"</params></function></{g}>\n"
        for g, (f, *params) in calls.items()
    )
    return f'  <operation id="{id_}">\n{body}  </operation>\n'


def application(*operations: str) -> str:
    return '<?xml version="1.0"?>\n<application name="edit_demo" robot="nextage">\n' + "".join(operations) + "</application>\n"


REACH = op("reach", left_arm=("move_to", LEFT_OUT), right_arm=("move_to", RIGHT_OUT))
HOLD = op("hold", left_arm=("wait", "1"))
CLOSER = op("closer", left_arm=("move_to", LEFT_IN))
HOME = op("home", left_arm=("move_to_joint_pose", "initial"), right_arm=("move_to_joint_pose", "initial"))
OLD = application(REACH, HOLD, CLOSER, HOME)
#: The left hand sent to where the right one stands: the dry run of the remainder finds the collision.
COLLIDES = application(REACH, HOLD, op("closer", left_arm=("move_to", RIGHT_OUT)), HOME)
#: Another target for the left hand, and an operation more for the right one.
SAFE = application(REACH, HOLD, op("wider", left_arm=("move_to", "0.30,0.25,0.10,180deg,0,90deg")),
                   op("right_in", right_arm=("move_to", "0.30,-0.25,0.10,180deg,0,90deg")), HOME)
#: An edit of the operation that has already run.
DONE_EDITED = application(op("reach", left_arm=("move_to", LEFT_IN), right_arm=("move_to", RIGHT_OUT)), HOLD, CLOSER, HOME)


def load(tmp: Path, name: str, text: str) -> Application:
    path = tmp / name
    path.write_text(text)
    return load_application(str(path), full_catalog())


@dataclass
class PausedRun:
    """A run of ``app`` stepped through its first operation and paused there, with its trace, recording and checkpoint."""

    clock: Clock
    deployment: Deployment
    app: Application
    run: asyncio.Task[RunReport]
    trace: io.StringIO
    store: CheckpointStore
    check: Any
    recorder: Any
    backend: Any

    async def edit(self, new: Application) -> SwapAnswer:
        return await swap_remainder(self.deployment.engine, new, self.check, str(new.path), "test")

    async def finish(self, command: str = "resume") -> RunReport:
        """Resume (or ``stop``) the run and wait for its end; its recording, checkpoint and deployment closed."""
        assert (await self.deployment.engine.operator_command(command, "test"))[0]
        report = await self.run
        await self.recorder.close()
        self.store.close()
        await self.deployment.close()
        return report

    def records(self, event: str) -> list[dict[str, Any]]:
        return [r for r in map(json.loads, self.trace.getvalue().splitlines()) if r["event"] == event]


async def paused(clock: Clock, app: Application, tmp: Path, steps: int = 2) -> PausedRun:
    """Start ``app`` as run does (trace, MCAP recording, checkpoint) and step ``steps`` operations: paused after them."""
    run = await started(clock, app, tmp)
    engine = run.deployment.engine
    for _ in range(steps):
        assert (await engine.operator_command("step", "test"))[0]
        for _ in range(400):  # bounded: 40 s of simulated time
            await clock.sleep(0.1)
            if engine.state == "paused":
                break
        assert engine.state == "paused"
    return run


async def started(clock: Clock, app: Application, tmp: Path) -> PausedRun:
    """``app`` set up as run does (trace, MCAP recording, checkpoint, the edit's check) and waiting for its start."""
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
    deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
    engine = deployment.engine
    engine.autostart = False
    trace = io.StringIO()
    writer = TraceWriter(trace)
    observer = RunObserver(deployment.transport.create_node("run_observer"), app.robot.group_names)
    store = CheckpointStore(tmp / "run.checkpoint.sqlite")
    store.begin_run(app_meta(app), str(tmp / "run.jsonl"), str(tmp / "run.mcap"), "")
    checkpoint = CheckpointWriter(store, app, full_catalog())
    observer.sinks += [writer.on_status, checkpoint.on_status]
    observer.engine_sinks.append(writer.on_engine)
    observer.event_sinks += [writer.on_event, checkpoint.on_event]
    engine.remainder.hooks += [checkpoint.swapped, writer.swapped]
    recorder = record_node(deployment.transport.create_node("recorder"), str(tmp / "run.mcap"), app, "nextage-sim", derive_tf=True)
    assert recorder is not None
    engine.remainder.hooks.append(recorder.swapped)  # as run wires it: the recording holds the edited file
    check = remainder_check(setup_for("nextage-sim", BackendOptions(robot=app.robot)), None, backend_measure(app.robot, backend, "the simulator"), clock)
    run = asyncio.get_running_loop().create_task(engine.run(app))
    await asyncio.sleep(0)  # the run has begun (its state reset): a command now is this run's
    return PausedRun(clock, deployment, app, run, trace, store, check, recorder, backend)


def test_a_safe_edit_is_swapped_in_and_its_operations_run_recorded_with_both_digests(run_sim: Any, tmp_path: Path) -> None:
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)

    async def main_(clock: Clock) -> tuple[SwapAnswer, RunReport, PausedRun]:
        run = await paused(clock, old, tmp_path)
        answer = await run.edit(new)
        return answer, await run.finish(), run

    answer, report, run = run_sim(main_)
    assert answer.ok, answer.message
    assert answer.message.startswith("edit: swapped: operations from 3 on are")
    assert report.ok and report.operations_done == report.operations_total == 5
    started = [(r["operation"], r["group"]) for r in run.records("function_start") if r["function"] != "wait"]
    assert ("wider", "left_arm") in started and ("right_in", "right_arm") in started and ("closer", "left_arm") not in started
    digests = {"from_digest": application_digest(old), "to_digest": application_digest(new)}
    (swap,) = run.records("swap")
    assert {k: swap[k] for k in digests} == digests and swap["operation"] == "hold" and swap["from_operation"] == 3
    assert swap["file"] == str(new.path) and swap["source"] == "test"
    recorded = []
    read_record(tmp_path / "run.mcap", lambda r: recorded.append(r) if r.get("event") == "swap" else None)
    assert [{k: r[k] for k in digests} for r in recorded] == [digests]
    with open(tmp_path / "run.mcap", "rb") as stream:
        reader = make_reader(stream)
        attached = {a.name: a.data for a in reader.iter_attachments()}
        described = {m.name: m.metadata for m in reader.iter_metadata()}
    assert attached["edited/1/safe.xml"] == new.path.read_bytes() and "application/old.xml" in attached
    edit = described["dual_arm_executive_edit_1"]
    assert (edit["from_digest"], edit["to_digest"], edit["from_operation"], edit["after_operation"]) == (digests["from_digest"], digests["to_digest"], "3", "hold")
    store = CheckpointStore(tmp_path / "run.checkpoint.sqlite", read_only=True)
    (row,) = store.swaps()
    assert row[1:] == (2, "hold", digests["from_digest"], digests["to_digest"], str(new.path))
    assert store.meta()["application_path"] == str(new.path)
    check_same(store, new)  # a resume goes on with the edited application
    with pytest.raises(CheckpointError, match=r"cannot resume with .*old.xml: the run was edited while paused \(after operation hold\) and goes on with .*safe.xml \(sha256 [0-9a-f]{12}…\), operations from 3 on"):
        check_same(store, old)  # never silently with the old one
    store.close()
    assert any(line.startswith("  edited while paused at") and "operations from 3 on swapped" in line for line in report.summary_lines())


def test_a_loop_added_by_an_edit_runs_each_iteration_named_in_the_trace(run_sim: Any, tmp_path: Path) -> None:
    old = load(tmp_path, "old.xml", OLD)
    looped = load(tmp_path, "looped.xml", application(REACH, HOLD, '  <repeat count="2">\n' + op("in_{index}", left_arm=("move_to", LEFT_IN)) + "  </repeat>\n", HOME))

    async def main_(clock: Clock) -> tuple[SwapAnswer, RunReport, PausedRun]:
        run = await paused(clock, old, tmp_path)
        answer = await run.edit(looped)
        return answer, await run.finish(), run

    answer, report, run = run_sim(main_)
    assert answer.ok and report.ok and report.operations_done == 5
    named = {(r["operation"], r.get("iteration")) for r in run.records("function_start") if r["operation"].startswith("in_")}
    assert named == {("in_1", "repeat index=1"), ("in_2", "repeat index=2")}


def test_an_edit_that_would_collide_is_refused_with_the_finding_and_the_old_remainder_runs(run_sim: Any, tmp_path: Path) -> None:
    old, colliding = load(tmp_path, "old.xml", OLD), load(tmp_path, "collide.xml", COLLIDES)

    async def main_(clock: Clock) -> tuple[SwapAnswer, RunReport, PausedRun]:
        run = await paused(clock, old, tmp_path)
        answer = await run.edit(colliding)
        assert run.deployment.engine.state == "paused" and run.deployment.engine.app is old
        return answer, await run.finish(), run

    answer, report, run = run_sim(main_)
    assert not answer.ok and "problem(s) found by the dry run of operations 3.. from where the robot is" in answer.message
    assert any(f.line == 11 and "collision between left_arm hand" in f.message and "operation closer left_arm move_to" in f.message for f in answer.findings)
    assert report.ok and report.operations_total == 4 and not report.edits
    assert ("closer", "left_arm") in [(r["operation"], r["group"]) for r in run.records("function_start")]
    assert run.records("swap") == []


def test_edits_of_done_operations_other_robots_and_runs_not_paused_are_refused(run_sim: Any, tmp_path: Path) -> None:
    old, done = load(tmp_path, "old.xml", OLD), load(tmp_path, "done.xml", DONE_EDITED)
    same = load(tmp_path, "same.xml", OLD.replace("\n  <operation", "\n\n  <operation"))  # lines moved, operations the same
    other = load(tmp_path, "kuka.xml", '<?xml version="1.0"?>\n<application name="k" robot="kuka">\n'
                 '  <operation id="a"><arm><function name="gripper_open"/></arm></operation>\n</application>\n')

    async def main_(clock: Clock) -> list[str]:
        run = await paused(clock, old, tmp_path)
        answers = [(await run.edit(done)).message, (await run.edit(same)).message, (await run.edit(other)).message]
        assert (await run.deployment.engine.operator_command("resume", "test"))[0]
        answers.append((await run.edit(load(tmp_path, "safe.xml", SAFE))).message)
        report = await run.run
        await run.recorder.close()
        run.store.close()
        await run.deployment.close()
        assert report.ok and report.operations_total == 4
        return answers

    answers = run_sim(main_)
    assert answers[0] == "edit: operation 1 'reach' has already run; only operations from 3 on may change"
    assert answers[1] == "edit: nothing to change: the operations from 3 on are the run's"
    assert answers[2].startswith("edit: the edited application changes the robot (nextage_open -> ")
    assert answers[3].startswith("edit: the run is not paused (running); pause it first")


def test_a_run_stopped_after_a_swap_resumes_with_the_new_remainder(run_sim: Any, tmp_path: Path) -> None:
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)
    assert run_sim(lambda clock: edited_and_stopped(paused(clock, old, tmp_path), new)).ok
    records = resumed(tmp_path, new)
    started = [(r["operation"], r["group"]) for r in records if r["event"] == "function_start"]
    assert started and started[0] == ("wider", "left_arm") and ("right_in", "right_arm") in started and ("reach", "left_arm") not in started
    err = io.StringIO()
    assert main(["run", str(old.path), "--resume", str(tmp_path / "run.checkpoint.sqlite"), "--speed", "max", "--quiet"], out=io.StringIO(), err=err) == 2
    assert "the run was edited while paused (after operation hold) and goes on with" in err.getvalue()


async def edited_and_stopped(pausing: Awaitable[PausedRun], new: Application) -> SwapAnswer:
    """The run ``pausing`` gives, edited with ``new`` and stopped (its checkpoint left for a resume)."""
    run = await pausing
    answer = await run.edit(new)
    await run.finish("stop")
    return answer


def resumed(tmp: Path, app: Application, *options: str) -> list[dict[str, Any]]:
    """``run APP --resume`` the checkpoint in ``tmp`` (``options`` added); the resumed run's trace records."""
    err, trace = io.StringIO(), tmp / "resumed.jsonl"
    code = main(["run", str(app.path), "--resume", str(tmp / "run.checkpoint.sqlite"), *options, "--speed", "max", "--trace", str(trace), "--quiet"],
                out=io.StringIO(), err=err)
    assert code == 0, err.getvalue()
    return [json.loads(line) for line in trace.read_text().splitlines()]


def test_the_terminal_edits_the_paused_run_from_a_file_and_says_why_it_will_not(run_sim: Any, tmp_path: Path) -> None:
    """run --interactive: e asks for the file (a line), e FILE in line mode; the answers are the console's lines."""
    old, new = load(tmp_path, "old.xml", OLD), load(tmp_path, "safe.xml", SAFE)
    (tmp_path / "broken.xml").write_text(SAFE.replace("move_to", "fly_to", 1))
    screen = io.StringIO()

    async def main_(clock: Clock) -> RunReport:
        run = await paused(clock, old, tmp_path)
        engine = run.deployment.engine
        console = OperatorConsole(run.deployment.transport.create_node("operator_console"), screen, engine.operator_command)
        console.editor = console_editor(engine, old, run.backend, clock, setup_for("nextage-sim", BackendOptions(robot=old.robot)), None)
        await console.handle_line("e\n")  # asks for the file
        await console.handle_line(f"{tmp_path / 'broken.xml'}\n")
        await console.handle_line(f"e {tmp_path / 'nowhere.xml'}\n")
        await console.handle_line(f"e {new.path}\n")
        return await run.finish()

    report = run_sim(main_)
    lines = screen.getvalue().splitlines()
    assert lines[0] == "edit the paused run: the edited application's file, then Enter"
    assert any(line.startswith(f"{tmp_path / 'broken.xml'}:") and "fly_to" in line for line in lines)
    assert f"edit: {tmp_path / 'broken.xml'}: not swapped: 1 problem(s); nothing changed" in lines
    assert f"edit: {tmp_path / 'nowhere.xml'}: no such file; nothing changed" in lines
    assert lines[-1].startswith("edit: swapped: operations from 3 on are")
    assert report.ok and report.operations_total == 5
    assert any("edited while paused" in line and "terminal console (key 'e')" in line for line in report.summary_lines())


def test_the_remainder_is_checked_from_the_flags_set_the_frames_located_and_the_branches_decided(tmp_path: Path) -> None:
    """What the dry run of an edit starts from besides the joints: the flags set (set again first, moving nothing), the
    located frames at their measured poses (children with them, the simulated camera's truth where it was), and the
    <if> branches on operations already run resolved as the run will take them."""
    app = load_application(str(ROOT / "apps_xml" / "rivet_loop_branch.xml"), full_catalog())
    ids = [op.id for op in app.operations]
    frontier = ids.index("look_drill_1") + 1
    assert app.cell is not None
    measured = Pose(0.341, 0.0602, 0.0005, 1.0, 0.0, 0.0, 0.0)
    truth = app.cell.to_snapshot().truth
    state = PresentState(frontier, {"drill_1": measured}, ("tray_ready",), {"look_drill_1/left_arm": "not_found"})
    rest = remainder_app(app, state)
    first = rest.operations[0]
    assert first.calls["left_arm"].function == "set_flag" and first.calls["left_arm"].params == ("tray_ready",)
    assert all(call.implicit for group, call in first.calls.items() if group != "left_arm")
    kept = [op.id for op in rest.operations[1:]]
    assert kept[:2] == ["put_back_drill_1", "over_drill_2"] and "debur_drill_1" not in kept and "insert_drill_1" not in kept
    assert rest.operations[1].when == () and rest.operation("debur_drill_2").when == app.operation("debur_drill_2").when
    assert rest.cell is not None
    assert rest.cell.pose("drill_1").distance_to(measured) < 1e-9
    assert rest.cell.to_snapshot().truth["drill_1"].distance_to(truth["drill_1"]) < 1e-9  # the camera's truth stays
    assert rest.cell.pose("drill_2").distance_to(app.cell.pose("drill_2")) < 1e-9  # not located: nominal

    old = load(tmp_path, "old.xml", OLD)
    report = dry_run_setup(remainder_app(old, PresentState(2, {}, ("tray_ready",), {})), setup_for("nextage-sim", BackendOptions(robot=old.robot)))
    assert report.ok and report.operations_checked == 3  # the flag's operation, then closer and home
