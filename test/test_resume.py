"""Crash resume: kill -9 a run anywhere, resume it from its checkpoint, every function runs exactly once."""
from __future__ import annotations

import asyncio
import io
import shutil
import sqlite3
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from app_builder import Cell, make_app
from killed_runs import env, records, run_and_freeze
from app_functions.registry import full_catalog
from cell_runner.cli import main
from core_functions.primitives import TrajectoryResult
from core_functions.trajectory_store import TrajectoryStore
from execution_engine.app_model import load_application
from execution_engine.app_model.model import Call
from execution_engine.checkpoint.resume import ResumePlan, sits_out
from execution_engine.checkpoint.store import CheckpointStore
from execution_engine.engine.operator import Flags, decide
from node_transport.msgs import Trigger
from node_transport.wire import engine_service

RIVET = "apps_xml/rivet_installation.xml"
ROOT = Path(__file__).resolve().parent.parent
TRACE_LINES = 480  # about what a whole rivet run writes


def required() -> set[tuple[str, str]]:
    catalog = full_catalog()
    app = load_application(ROOT / RIVET, catalog)
    return {(op.id, g) for op in app.operations for g, call in op.calls.items() if not sits_out(app, catalog, call)}


def lines(count: int) -> Callable[[bytes], bool]:
    return lambda trace: trace.count(b"\n") >= count


MOMENTS = [5 + moment * (TRACE_LINES - 10) // 19 for moment in range(20)]  # trace lines, spread over the whole run
IN_AN_OPERATION = 150  # trace lines: a moment inside an operation


@pytest.fixture(scope="module")
def cuts(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """One run of the demonstrator in its own process, with what a kill -9 leaves at each of the 20 moments and at
    IN_AN_OPERATION, by trace lines (killed_runs.run_and_freeze: stopped and copied at each, killed with SIGKILL at the last)."""
    counts = sorted([*MOMENTS, IN_AN_OPERATION])
    return dict(zip(counts, run_and_freeze(ROOT / RIVET, tmp_path_factory.mktemp("killed"), [lines(count) for count in counts])))


def resume_copy(cut: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of its own of what a kill left, as the working directory with its home: the run named its outputs relative
    to its folder."""
    folder = Path(shutil.copytree(cut, tmp_path / "run", symlinks=True))
    monkeypatch.chdir(folder)
    for name, value in env(folder).items():
        monkeypatch.setenv(name, value)
    return folder


@pytest.mark.xdist_group("resume_cuts")  # one worker makes the run they share, once
@pytest.mark.parametrize("moment", range(20))
def test_kill_anywhere_then_resume_runs_every_function_once(cuts: dict[int, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, moment: int) -> None:
    folder = resume_copy(cuts[MOMENTS[moment]], tmp_path, monkeypatch)
    trace = folder / "run.jsonl"
    assert len(records(trace)) >= MOMENTS[moment] - 1  # killed at its moment (the last line may be cut)
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(ROOT / RIVET), "--speed", "max", "-q", "--no-check", "--resume", "run.sqlite",
                 "--on-interrupted", "redo", "--trace", "resumed.jsonl"], out, err)
    assert code == 0, err.getvalue()
    first, second = records(trace), records(folder / "resumed.jsonl")
    done = Counter((r["operation"], r["group"]) for r in first + second if r["event"] == "function_end" and r["outcome"] == "succeeded")
    assert set(done) == required() and set(done.values()) == {1}, "every function completed exactly once across the two runs"
    inserted = [r["operation"] for r in first + second if r["event"] == "function_end" and r.get("function") == "insert_rivet" and r["outcome"] == "succeeded"]
    assert len(inserted) == len(set(inserted)) == 4  # no rivet twice
    assert second[-1]["event"] == "run_end" and second[-1]["outcome"] == "finished"
    resumed = [r for r in second if r["event"] == "engine_state" and str(r.get("message", "")).startswith("resumed from")]
    if any(r["event"] == "function_start" for r in second):
        assert resumed and "continues run.jsonl" in resumed[0]["message"]  # the new trace names the one it continues, as the run was given it


@pytest.mark.xdist_group("resume_cuts")
def test_an_interrupted_function_waits_for_the_operator(cuts: dict[int, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = resume_copy(cuts[IN_AN_OPERATION], tmp_path, monkeypatch)
    trace = folder / "run.jsonl"
    checkpoint = "run.sqlite"
    store = CheckpointStore(checkpoint)
    in_flight = {(r.operation, r.group) for r in store.functions() if r.outcome == "started"} - {(r.operation, r.group) for r in store.functions() if r.outcome == "succeeded"}
    store.close()
    assert in_flight, "the kill landed inside an operation"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(ROOT / RIVET), "--speed", "max", "-q", "--no-check", "--resume", checkpoint, "--trace", str(tmp_path / "asked.jsonl")], out, err)
    assert code == 1  # nobody at a terminal can answer: the run ends before anything moves
    asked = records(tmp_path / "asked.jsonl")
    assert not [r for r in asked if r["event"] == "function_start"]
    alarm = [r for r in asked if r["event"] == "engine_state" and r["to"] == "alarm"]
    assert alarm and alarm[0]["message"].startswith("interrupted: ") and "reset to redo the function, or skip" in alarm[0]["message"]
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(ROOT / RIVET), "--speed", "max", "-q", "--no-check", "--resume", checkpoint, "--on-interrupted", "skip",
                 "--trace", str(tmp_path / "skipped.jsonl")], out, err)
    assert code == 0, err.getvalue()
    skipped = records(tmp_path / "skipped.jsonl")
    assert not {(r["operation"], r["group"]) for r in skipped if r["event"] == "function_start"} & in_flight
    assert records(trace)


def test_a_changed_application_or_cell_is_refused(tmp_path: Path) -> None:
    app = tmp_path / "app.xml"
    text = (ROOT / RIVET).read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{ROOT / "apps_xml/cells/rivet_cell.xml"}"')
    app.write_text(text)
    err = io.StringIO()
    assert main(["run", str(app), "--speed", "max", "-q", "--no-check", "--trace", str(tmp_path / "a.jsonl")], io.StringIO(), err) == 0, err.getvalue()
    checkpoint = tmp_path / "a.checkpoint.sqlite"
    assert checkpoint.is_file()
    with sqlite3.connect(checkpoint) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert db.execute("SELECT count(*) FROM functions WHERE outcome = 'succeeded'").fetchone()[0] == len(required())
        assert dict(db.execute("SELECT grp, holds FROM hands").fetchall()).get("right_arm")
    app.write_text(text.replace("Debur four drilled holes", "Debur 4 drilled holes"))
    before = sorted(p.name for p in tmp_path.iterdir())
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "-q", "--no-check", "--resume", str(checkpoint)], out, err)
    assert code == 2 and err.getvalue().count("\n") == 1
    assert "the application" in err.getvalue() and "changed since the checkpoint" in err.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
    code = main(["run", str(app), "--speed", "max", "-q", "--no-check", "--resume", str(checkpoint), "--trace", str(tmp_path / "a.jsonl")], io.StringIO(), io.StringIO())
    assert code == 2  # never the file being resumed


OPS3 = [{"left_arm": ("gripper_open",), "right_arm": ("gripper_open",)}, {"right_arm": ("gripper_close",), "left_arm": ("gripper_close",)},
        {"left_arm": ("gripper_open",)}]


@pytest.mark.parametrize("answer", ["skip", "reset"])
def test_nothing_moves_until_the_operator_answers_for_an_interrupted_function(run_sim: Any, answer: str) -> None:
    app = make_app(OPS3)
    skipped: list[str] = []

    async def main(clock: Any) -> tuple[str, Any, list[Any], list[Any]]:
        cell = await Cell(clock).start()
        interrupted = {"right_arm": app.operations[1].calls["right_arm"]}
        plan = ResumePlan(1, frozenset({"left_arm"}), interrupted, "ask", "run.sqlite", "run.jsonl",
                          on_skip=lambda index, op, group: skipped.append(f"{op.id}:{group}"))
        skip = cell.node.create_client(Trigger, engine_service("skip"))
        run = asyncio.ensure_future(cell.deployment.engine.run(app, plan))
        while not any(s["state"] == "alarm" for s in cell.engine_states):
            await clock.sleep(0.1)
        message = next(s["message"] for s in cell.engine_states if s["state"] == "alarm")
        await clock.sleep(30.0)  # however long the operator takes
        before = cell.functions("right_arm") + cell.functions("left_arm")
        reply = await (skip.call(Trigger.Request(), timeout=5.0) if answer == "skip" else cell.operator("reset"))
        await run
        await cell.deployment.close()
        return message, reply, before, cell.functions("right_arm") + cell.functions("left_arm")

    message, reply, before, after = run_sim(main)
    assert message.startswith("interrupted: right_arm was running gripper_close of operation 2") and "reset to redo the function, or skip" in message
    assert before == []  # nothing ran while the alarm waited
    assert reply.success
    ran = {(op, function) for op, function, _, _ in after}
    assert ("1", "gripper_open") not in ran  # completed before the crash: never again
    assert ("3", "gripper_open") in ran
    if answer == "skip":
        assert ("2", "gripper_close") not in ran and skipped == ["2:right_arm"]
    else:
        assert ("2", "gripper_close") in ran and skipped == []


def test_skip_answers_only_the_alarm_of_an_interrupted_function() -> None:
    assert decide("skip", "running", Flags(False, False))[0] is False
    ok, answer = decide("skip", "alarm", Flags(False, False))  # a failed function's alarm: retry or stop, not skip
    assert not ok and "use reset or stop" in answer
    assert decide("skip", "alarm", Flags(False, False, skippable=True)) == (True, "alarm acknowledged: the interrupted function is skipped (taken as done)")


@pytest.mark.parametrize("content", [b"", b"not a database at all", "trajectories"])
def test_resume_from_something_that_is_not_a_checkpoint_is_one_line_and_changes_nothing(tmp_path: Path, content: Any) -> None:
    path = tmp_path / "cp.sqlite"
    if content == "trajectories":  # another database of this program: the trajectory store
        store = TrajectoryStore(path)
        store.save("right_arm", "sweep", TrajectoryResult(("a",), ((0.0,),), (0.0,)), "plan", 0.0)
        store.close()
    else:
        path.write_bytes(content)
    before = path.read_bytes()
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", RIVET, "--speed", "max", "-q", "--no-check", "--resume", str(path), "--trace", str(tmp_path / "t.jsonl")], out, err)
    assert code == 2 and err.getvalue().count("\n") == 1 and "Traceback" not in err.getvalue()
    assert ("not a checkpoint" in err.getvalue()) or ("holds no run" in err.getvalue())
    assert path.read_bytes() == before and not (tmp_path / "t.jsonl").exists()


def test_resuming_a_run_that_did_everything_is_refused_and_writes_nothing(tmp_path: Path) -> None:
    """A finished run has nothing to go on with: no second trace, no new run in its checkpoint, exit 2."""
    trace, checkpoint = tmp_path / "run.jsonl", tmp_path / "run.checkpoint.sqlite"
    assert main(["run", RIVET, "--speed", "max", "-q", "--no-check", "--trace", str(trace)], io.StringIO(), io.StringIO()) == 0
    store = CheckpointStore(checkpoint, read_only=True)
    runs_before = store.runs()
    store.close()
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm"))}
    err = io.StringIO()
    code = main(["run", RIVET, "--speed", "max", "-q", "--no-check", "--resume", str(checkpoint)], io.StringIO(), err)
    total = len(load_application(RIVET, full_catalog()).operations)
    assert code == 2 and err.getvalue() == (
        f"error: --resume {checkpoint}: the run it holds did every operation ({total} of {total}): nothing is left to resume; "
        "run without --resume to start again\n"
    )
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm"))}
    assert after == before  # no run.resume2.jsonl beside it, the trace and the checkpoint as they were
    store = CheckpointStore(checkpoint, read_only=True)
    assert store.runs() == runs_before
    store.close()
