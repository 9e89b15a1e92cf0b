"""Crash resume of an application made of loops and calls (issue 24 item 4): kill -9 in the second
iteration (what a kill leaves at three moments of one run: killed_runs.run_and_freeze), resume, and the run goes on at the iteration it was in, every function done once; a changed
library block refuses the resume like a changed application."""
from __future__ import annotations

import io
import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main
from execution_engine.app_model import load_application
from execution_engine.checkpoint.resume import sits_out
from execution_engine.recorder.reading import Recording, iter_messages
from killed_runs import env, records, run_and_freeze, run_and_kill

ROOT = Path(__file__).resolve().parent.parent
BLOCKS = ROOT / "apps_xml" / "rivet_blocks.xml"


def copy_application(folder: Path) -> Path:
    """The demonstrator built from the library block, in a folder of its own (so its block can be changed)."""
    (folder / "blocks").mkdir()
    shutil.copy(ROOT / "apps_xml" / "blocks" / "rivet_block.xml", folder / "blocks" / "rivet_block.xml")
    cell = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
    for name, source in (("app.xml", BLOCKS), ("blocks/rivet_block.xml", ROOT / "apps_xml" / "blocks" / "rivet_block.xml")):
        text = (folder / name).read_text() if (folder / name).exists() else source.read_text()
        (folder / name).write_text(text.replace('cell="cells/rivet_cell.xml"', f'cell="{cell}"').replace('cell="../cells/rivet_cell.xml"', f'cell="{cell}"'))
    return folder / "app.xml"


def second_iteration_starts(starts: int) -> Callable[[bytes], bool]:
    """Once the trace shows ``starts`` function starts of the second iteration."""
    mark = b'"iteration":"for_each hole=drill_2'
    return lambda trace: sum(1 for line in trace.splitlines() if mark in line and b'"event":"function_start"' in line) >= starts


def start_and_kill(app: Path, folder: Path, starts: int) -> Path:
    """Run in a process of its own; kill -9 once the trace shows ``starts`` function starts of the second iteration
    (test_branches_run's kill)."""
    return run_and_kill(app, folder, second_iteration_starts(starts))


@pytest.fixture(scope="module")
def cuts(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path]]:
    """The block-built demonstrator run once in its own process, with what a kill -9 leaves at 1, 2 and 3 function
    starts of the second iteration (killed_runs.run_and_freeze: stopped and copied at each, killed with SIGKILL at the
    last): the application and the copies."""
    folder = tmp_path_factory.mktemp("killed")
    app = copy_application(folder)
    return app, run_and_freeze(app, folder, [second_iteration_starts(starts) for starts in (1, 2, 3)])


@pytest.mark.xdist_group("resume_loops_cuts")  # one worker makes the run they share, once
@pytest.mark.parametrize("starts", [1, 2, 3])
def test_kill_in_the_second_iteration_then_resume_does_every_function_once(
    cuts: tuple[Path, list[Path]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, starts: int
) -> None:
    app = cuts[0]
    catalog = full_catalog()
    application = load_application(app, catalog)
    required = {(op.id, g) for op in application.operations for g, call in op.calls.items() if not sits_out(application, catalog, call)}
    folder = Path(shutil.copytree(cuts[1][starts - 1], tmp_path / "run", symlinks=True))  # a copy of its own to resume
    monkeypatch.chdir(folder)  # the run named its outputs relative to its folder
    for name, value in env(folder).items():
        monkeypatch.setenv(name, value)
    trace = folder / "run.jsonl"
    first = records(trace)
    done_first = {(r["operation"], r["group"]) for r in first if r["event"] == "function_end" and r["outcome"] == "succeeded"}
    left = next(op for op in application.operations if any((op.id, g) in required and (op.id, g) not in done_first for g in op.calls))
    assert left.origin.startswith("for_each hole=drill_2"), "the kill landed in the second iteration"
    out = io.StringIO()
    assert main(["report", str(trace)], out, io.StringIO()) == 0
    iterations = [line for line in out.getvalue().splitlines() if line.strip().startswith("iterations:")]
    assert len(iterations) == 1 and " (for_each hole=drill_2 > call blocks/rivet_block.xml hole=drill_2 slot=rivet_2 at " in iterations[0]
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "-q", "--no-check", "--resume", "run.sqlite",
                 "--on-interrupted", "redo", "--trace", "resumed.jsonl"], out, err)
    assert code == 0, err.getvalue()
    second = records(folder / "resumed.jsonl")
    started = [r for r in second if r["event"] == "function_start"]
    assert started[0]["operation"] == left.id and started[0]["iteration"] == left.origin  # on at the iteration it was in
    done = Counter((r["operation"], r["group"]) for r in first + second if r["event"] == "function_end" and r["outcome"] == "succeeded")
    assert set(done) == required and set(done.values()) == {1}, "every function completed exactly once across the two runs"
    inserted = [r["iteration"] for r in first + second if r["event"] == "function_end" and r.get("function") == "insert_rivet" and r["outcome"] == "succeeded"]
    assert sorted(i.split(" > ")[0] for i in inserted) == [f"for_each hole=drill_{n}" for n in range(1, 5)]  # one rivet per hole
    assert second[-1]["event"] == "run_end" and second[-1]["outcome"] == "finished"


def test_a_changed_block_refuses_the_resume_naming_it(tmp_path: Path) -> None:
    app = copy_application(tmp_path)
    err = io.StringIO()
    assert main(["run", str(app), "--speed", "max", "-q", "--no-check", "--trace", str(tmp_path / "a.jsonl")], io.StringIO(), err) == 0, err.getvalue()
    block = tmp_path / "blocks" / "rivet_block.xml"
    block.write_text(block.read_text().replace("Debur one hole", "Debur a hole"))
    before = sorted(p.name for p in tmp_path.iterdir())
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "-q", "--no-check", "--resume", str(tmp_path / "a.checkpoint.sqlite")], out, err)
    assert code == 2 and err.getvalue().count("\n") == 1
    assert f"an application it calls ({block})" in err.getvalue() and "changed since the checkpoint" in err.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_recording_keeps_the_called_blocks_and_the_iterations_and_no_output_overwrites_a_block(tmp_path: Path) -> None:
    app = copy_application(tmp_path)
    block = tmp_path / "blocks" / "rivet_block.xml"
    before = block.read_bytes()
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", str(app), "--speed", "max", "-q", "--no-check", "--trace", str(block)], out, err) == 2
    assert err.getvalue() == (f"error: --trace {block}: is the same file as the called application {block.resolve()}, which this run reads; "
                              "the trace would overwrite it: give another file\n")
    assert block.read_bytes() == before
    record = tmp_path / "run.mcap"
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", str(app), "--speed", "max", "-q", "--no-check", "--record", str(record)], out, err) == 0, err.getvalue()
    recording = Recording(str(record))
    for _ in iter_messages(record, recording, lambda topic, kind: False):
        pass
    assert recording.attachments["calls/rivet_block.xml"] == before
    iterations = recording.metadata["dual_arm_executive_iterations"]
    assert iterations["insert_drill_2"].startswith("for_each hole=drill_2 > call blocks/rivet_block.xml hole=drill_2 slot=rivet_2 at ")
    assert "prepare" not in iterations and len(iterations) == 8
