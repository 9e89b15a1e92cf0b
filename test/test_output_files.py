"""One rule for every file a command writes: an output is never an input nor another output, whatever
its spelling (a symbolic or hard link, ``./``, ``..``, an SQLite sidecar); the refusal is one line naming
both, exit 2, and nothing is written; a write that fails during the run ends with exit 4."""
from __future__ import annotations

import argparse
import io
import math
import os
import sqlite3
import stat
import threading
import time
from contextlib import closing
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from cell_runner.output_files import FilePlan, Output, Refused, same_file
from cell_runner.record_hook import record_node
from execution_engine.app_model import load_application
from execution_engine.checkpoint.resume import app_meta
from execution_engine.checkpoint.store import CheckpointStore
from operator_station.cli import build_station
from operator_station.program import main

ROOT = Path(__file__).resolve().parents[1]
RIVET = (ROOT / "apps_xml" / "rivet_installation.xml").read_text().replace(
    'cell="cells/rivet_cell.xml"', f'cell="{ROOT / "apps_xml" / "cells" / "rivet_cell.xml"}"'
)


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "rivet.xml").write_text(RIVET)
    return tmp_path


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file of the folder and its bytes: what 'nothing written' is checked against."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", *argv], out, err)
    return code, out.getvalue(), err.getvalue()


def plan_with(inputs: dict[str, Path], outputs: list[Output]) -> FilePlan:
    plan = FilePlan("run")
    for named, path in inputs.items():
        plan.read(named, path)
    for output in outputs:
        plan.write(output)
    return plan


# ------------------------------------------------------------------------ identity, not names
@pytest.mark.parametrize("spelling", ["same", "dot", "dotdot", "symlink", "hardlink", "symlinked_folder"])
def test_an_output_is_refused_as_the_input_it_is_whatever_its_spelling(folder: Path, spelling: str) -> None:
    app = folder / "rivet.xml"
    (folder / "sub").mkdir()
    os.symlink(folder, folder / "link_to_folder")
    os.symlink(app, folder / "link.xml")
    os.link(app, folder / "hard.xml")
    given = {
        "same": str(app), "dot": f"{folder}/./rivet.xml", "dotdot": f"{folder}/sub/../rivet.xml", "symlink": str(folder / "link.xml"),
        "hardlink": str(folder / "hard.xml"), "symlinked_folder": str(folder / "link_to_folder" / "rivet.xml"),
    }[spelling]
    with pytest.raises(Refused) as refused:
        plan_with({f"the application {app}": app}, [Output("--record", given, "the recording", "run.mcap")]).check()
    assert str(refused.value) == (f"--record {given}: is the same file as the application {app}, which this run reads; "
                                  "the recording would overwrite it: give another file")


def test_two_outputs_still_to_be_made_are_one_file_when_their_real_paths_are(folder: Path) -> None:
    (folder / "sub").mkdir()
    os.symlink(folder / "sub", folder / "alias")
    os.symlink(folder / "sub" / "later.jsonl", folder / "dangling.jsonl")  # a link to a file not made yet
    for a, b in [("sub/run.jsonl", "alias/run.jsonl"), ("sub/run.jsonl", "sub/../sub/run.jsonl"), ("dangling.jsonl", "sub/later.jsonl")]:
        assert same_file(folder / a, folder / b)
        with pytest.raises(Refused, match=r"^--record .*: is the same file as --trace .*; the recording and the trace would overwrite each other"):
            plan_with({}, [Output("--trace", str(folder / a), "the trace"), Output("--record", str(folder / b), "the recording")]).check()
    assert not (folder / "sub" / "run.jsonl").exists() and not (folder / "sub" / "later.jsonl").exists()


def test_sqlite_makes_files_beside_a_database_and_they_count(folder: Path) -> None:
    outputs = [Output("--trace", str(folder / "cp.sqlite-journal"), "the trace"),
               Output("--checkpoint", str(folder / "cp.sqlite"), "the checkpoint", sqlite=True)]
    with pytest.raises(Refused) as refused:
        plan_with({}, outputs).check()
    assert str(refused.value) == (f"--checkpoint {folder}/cp.sqlite: SQLite's {folder}/cp.sqlite-journal beside it is the same file as "
                                  f"--trace {folder}/cp.sqlite-journal; the checkpoint and the trace would overwrite each other: give each its own file")
    outputs.reverse()  # the other way round: the database given first, the trace on its journal
    with pytest.raises(Refused) as refused:
        plan_with({}, outputs).check()
    assert str(refused.value).startswith(f"--trace {folder}/cp.sqlite-journal: is the same file as SQLite's {folder}/cp.sqlite-journal beside --checkpoint {folder}/cp.sqlite;")


def test_files_that_store_nothing_may_be_shared_but_a_disk_or_a_pipe_nobody_reads_is_refused(folder: Path) -> None:
    plan_with({}, [Output("--trace", "/dev/null", "the trace"), Output("--record", "/dev/null", "the recording")]).check()
    with pytest.raises(Refused, match="is not a regular file; give an SQLite file"):
        plan_with({}, [Output("--checkpoint", "/dev/null", "the checkpoint", sqlite=True)]).check()
    os.mkfifo(folder / "pipe")
    started = time.monotonic()
    with pytest.raises(Refused, match=r"cannot be written \(a named pipe nobody reads\)"):
        plan_with({}, [Output("--trace", str(folder / "pipe"), "the trace")]).check()
    assert time.monotonic() - started < 5  # refused, not waiting for a reader
    disks = [d for d in Path("/dev").iterdir() if d.exists() and stat.S_ISBLK(d.stat().st_mode)]
    if disks:  # a machine without block devices cannot show this one
        with pytest.raises(Refused, match=r"is a block device \(a disk\), not a file"):
            plan_with({}, [Output("--record", str(disks[0]), "the recording")]).check()


def test_nothing_is_left_behind_by_the_checks(folder: Path) -> None:
    before = snapshot(folder)
    plan_with({}, [Output("--trace", str(folder / "new.jsonl"), "the trace"),
                   Output("--trajectory-db", str(folder / "a" / "b" / "t.sqlite"), "the trajectory database", sqlite=True, reads=True, makes_folders=True)]).check()
    assert snapshot(folder) == before and not (folder / "a").exists()


def test_the_check_never_makes_or_removes_the_file_it_checks(folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two runs of one application at once: the other may make APP.trajectories.sqlite while this run checks it; a
    check that created and removed that very name could delete the other run's database, or the other run's check
    could find this one's probe and refuse it (seen with two test workers)."""
    made, before = folder / "rivet.trajectories.sqlite", snapshot(folder)
    real_open, real_unlink, touched = os.open, os.unlink, []

    def watched_open(path: object, flags: int, *args: object) -> int:
        if Path(str(path)) == made:
            touched.append(("open", flags))
        return real_open(path, flags, *args)  # type: ignore[arg-type]

    def watched_unlink(path: object, *args: object) -> None:
        if Path(str(path)) == made:
            touched.append(("unlink", 0))
        real_unlink(path, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "open", watched_open)
    monkeypatch.setattr(os, "unlink", watched_unlink)
    plan_with({}, [Output("--trajectory-db", str(made), "the trajectory database", sqlite=True, reads=True)]).check()
    monkeypatch.undo()
    assert touched == [] and not made.exists() and snapshot(folder) == before


def test_two_runs_checking_one_new_database_at_once_both_pass_and_keep_it(folder: Path) -> None:
    made = folder / "rivet.trajectories.sqlite"
    plan = plan_with({}, [Output("--trajectory-db", str(made), "the trajectory database", sqlite=True, reads=True)])
    failures: list[BaseException] = []
    stop = threading.Event()

    def the_other_run() -> None:  # checks, then makes the database, as a run does
        try:
            for _ in range(200):
                plan.check()
            with closing(sqlite3.connect(made)) as db:
                db.execute("CREATE TABLE t (x)")
        except BaseException as error:  # reported below, not lost with the thread
            failures.append(error)
        finally:
            stop.set()

    other = threading.Thread(target=the_other_run)
    other.start()
    checks = 0
    while not stop.is_set() and checks < 100_000:
        plan.check()
        checks += 1
    other.join(timeout=10)
    assert failures == [] and not other.is_alive()
    with closing(sqlite3.connect(f"{made.as_uri()}?mode=ro", uri=True)) as db:
        assert db.execute("SELECT name FROM sqlite_master").fetchall() == [("t",)]


def test_a_name_longer_than_the_folder_allows_is_refused(folder: Path) -> None:
    with pytest.raises(Refused, match=r"--trace .*: cannot be created \(file name too long"):
        plan_with({}, [Output("--trace", str(folder / ("x" * 300 + ".jsonl")), "the trace")]).check()


def test_a_dangling_link_is_checked_where_it_points(folder: Path) -> None:
    (folder / "link.jsonl").symlink_to(folder / "missing" / "run.jsonl")
    with pytest.raises(Refused, match="cannot be created"):
        plan_with({}, [Output("--trace", str(folder / "link.jsonl"), "the trace")]).check()


# -------------------------------------------------------------------------- run, end to end
CLASHES = {
    "recording is the application": (["--record", "{f}/rivet.xml"], "--record {f}/rivet.xml: is the same file as the application {f}/rivet.xml, which this run reads"),
    "checkpoint is the application": (["--checkpoint", "{f}/rivet.xml"], "--checkpoint {f}/rivet.xml: is the same file as the application {f}/rivet.xml"),
    "checkpoint is the trace": (["--trace", "{f}/run.jsonl", "--checkpoint", "{f}/run.jsonl"], "--checkpoint {f}/run.jsonl: is the same file as --trace {f}/run.jsonl"),
    "trace and recording one file": (["--trace", "{f}/run.jsonl", "--record", "{f}/run.jsonl"], "--record {f}/run.jsonl: is the same file as --trace {f}/run.jsonl"),
    "trace is the default trajectory database": (
        ["--trace", "{f}/rivet.trajectories.sqlite"],
        "--trace {f}/rivet.trajectories.sqlite: is the same file as the trajectory database {f}/rivet.trajectories.sqlite (the application's own; --trajectory-db names another)",
    ),
    "recording through a link to the cell": (["--record", "{f}/cell_link.xml"], "--record {f}/cell_link.xml: is the same file as the cell "),
    "checkpoint next to the trace is the given trajectory database": (
        ["--trace", "{f}/night.jsonl", "--trajectory-db", "{f}/night.checkpoint.sqlite"],
        "--trajectory-db {f}/night.checkpoint.sqlite: is the same file as the checkpoint {f}/night.checkpoint.sqlite (next to --trace; --checkpoint names another)",
    ),
    "feedback log is the RSI configuration": (
        ["--backend-option", "config={f}/run.jsonl", "--backend-option", "feedback={f}/run.jsonl"],
        "--backend-option feedback={f}/run.jsonl: is the same file as --backend-option config={f}/run.jsonl, which this run reads",
    ),
}


@pytest.mark.parametrize("case", sorted(CLASHES))
def test_a_run_whose_outputs_clash_is_refused_in_one_line_and_writes_nothing(folder: Path, case: str) -> None:
    argv, says = CLASHES[case]
    (folder / "run.jsonl").write_text('{"event": "run_start", "t": 0}\n')  # an earlier trace: it must survive too
    with sqlite3.connect(folder / "rivet.trajectories.sqlite") as db:  # trajectories recorded on an earlier shift
        db.execute("CREATE TABLE kept(x)")
    os.symlink(ROOT / "apps_xml" / "cells" / "rivet_cell.xml", folder / "cell_link.xml")
    cell_before = (ROOT / "apps_xml" / "cells" / "rivet_cell.xml").read_bytes()
    before = snapshot(folder)
    code, out, err = run(str(folder / "rivet.xml"), "--speed", "max", *(a.replace("{f}", str(folder)) for a in argv))
    assert code == 2 and out == "", err
    assert err.count("\n") == 1 and err.startswith("error: " + says.replace("{f}", str(folder))), err
    assert snapshot(folder) == before  # not a byte: no trace opened, no checkpoint made, no database touched
    assert (ROOT / "apps_xml" / "cells" / "rivet_cell.xml").read_bytes() == cell_before


@pytest.mark.parametrize(("option", "says"), [
    ("--record", "error: --record {f}/no/run.mcap: the directory {f}/no does not exist; create it first or give another path"),
    ("--checkpoint", "error: --checkpoint {f}/no/run.mcap: the directory {f}/no does not exist; create it first or give another path"),
])
def test_each_output_is_named_by_its_own_option(folder: Path, option: str, says: str) -> None:
    code, _, err = run(str(folder / "rivet.xml"), "--speed", "max", option, str(folder / "no" / "run.mcap"))
    assert (code, err) == (2, says.replace("{f}", str(folder)) + "\n")


def test_a_checkpoint_that_fails_during_the_run_ends_it_with_4(folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(*args: object, **kwargs: object) -> None:
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(CheckpointStore, "function_result", full)
    code, out, err = run(str(folder / "rivet.xml"), "--speed", "max", "-q", "--no-check", "--checkpoint", str(folder / "run.sqlite"))
    assert "application rivet_installation: FINISHED" in out
    assert code == 4, err
    assert err.splitlines()[-1] == (
        f"error: --checkpoint {folder}/run.sqlite: could not be written (database or disk is full): later results are not in it: "
        "a resume from it may redo functions that completed; the run itself: FINISHED (summary above); free space or give another --checkpoint"
    )


def resumable(folder: Path) -> Path:
    """A checkpoint of one earlier run of the application, which wrote run.jsonl."""
    checkpoint = folder / "cp.sqlite"
    store = CheckpointStore(checkpoint)
    store.begin_run(app_meta(load_application(str(folder / "rivet.xml"), full_catalog())), str(folder / "run.jsonl"), "", "")
    store.close()
    (folder / "run.jsonl").write_text('{"event": "run_start", "t": 0}\n')
    return checkpoint


def test_a_resumed_run_writes_its_own_checkpoint_only(folder: Path) -> None:
    checkpoint = resumable(folder)
    before = snapshot(folder)
    code, _, err = run(str(folder / "rivet.xml"), "--resume", str(checkpoint), "--checkpoint", str(folder / "other.sqlite"))
    assert (code, err) == (2, f"error: --checkpoint {folder}/other.sqlite: a resumed run goes on writing the checkpoint it resumes "
                              f"(--resume {checkpoint}); leave --checkpoint out\n")
    os.symlink(folder / "run.jsonl", folder / "again.jsonl")
    code, _, err = run(str(folder / "rivet.xml"), "--resume", str(checkpoint), "--trace", str(folder / "again.jsonl"))
    assert code == 2 and err.startswith(f"error: --trace {folder}/again.jsonl: that file holds the run being resumed"), err
    after = {name: data for name, data in snapshot(folder).items() if not name.startswith("cp.sqlite-")}  # SQLite's own, to read it
    assert after == before


def test_the_engine_node_never_records_over_its_application(folder: Path) -> None:
    app = load_application(str(folder / "rivet.xml"), full_catalog())
    with pytest.raises(Refused) as refused:
        record_node(None, str(folder / "rivet.xml"), app, option="parameter record")  # type: ignore[arg-type] # refused before the node is used
    assert str(refused.value).startswith(f"parameter record={folder}/rivet.xml: is the same file as the application {folder}/rivet.xml")
    assert (folder / "rivet.xml").read_text() == RIVET


# ------------------------------------------------------------------------------- report
def test_a_timeline_is_never_the_record_it_is_drawn_from(folder: Path) -> None:
    record = folder / "run.svg"  # a trace, under a name a timeline could have
    record.write_text('{"event": "run_start", "t": 0}\n')
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", str(record), "--timeline", str(folder / "." / "run.svg")], out, err) == 2
    assert err.getvalue() == (f"error: --timeline {record}: is the same file as the record {record}, which this report reads; "
                              "the timeline would overwrite it: give another file\n")
    assert record.read_text() == '{"event": "run_start", "t": 0}\n' and out.getvalue() == ""


def test_a_timeline_that_cannot_be_written_ends_the_report_with_4(folder: Path) -> None:
    trace = folder / "run.jsonl"
    trace.write_text('{"event": "function_start", "t": 0, "group": "arm", "operation": "1", "function": "wait"}\n')
    os.symlink("/dev/full", folder / "full.svg")
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", str(trace), "--timeline", str(folder / "full.svg")], out, err) == 4
    assert f"trace {trace}: 1 record(s)" in out.getvalue()
    assert err.getvalue() == (f"error: --timeline {folder}/full.svg: could not be written (No space left on device); "
                              "the summary above is whole; free space or give another --timeline\n")


# ------------------------------------------------------------------------------- studio
def studio(folder: Path, **settings: object) -> tuple[object, object]:
    pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
    # optional: starlette (pip extra 'studio'), which the station's server is built on
    from starlette.testclient import TestClient

    from operator_station.server import create_app  # optional: starlette

    args = argparse.Namespace(file="rivet.xml", replay=None, controller_host=None, controller_port=None, rsi_listen=None, fault=None, seed=0,
                              backend_option=None, robot=None, speed=math.inf, trace=None, trajectory_db=None, no_check=False)
    for key, value in settings.items():
        setattr(args, key, value)
    station = build_station(args, full_catalog(), folder)
    client = TestClient(create_app(station), base_url="http://127.0.0.1:8080", client=("127.0.0.1", 50000))
    assert client.get("/").status_code == 200
    return station, client


def test_the_studio_never_starts_a_run_whose_trace_is_the_application(folder: Path) -> None:
    station, client = studio(folder, trace=str(folder / "rivet.xml"))
    document = client.get("/api/document").json()["document"]  # type: ignore[attr-defined]
    answer = client.post("/api/run", json={"path": "rivet.xml", "document": document})  # type: ignore[attr-defined]
    assert answer.status_code == 409 and not answer.json()["ok"]
    assert answer.json()["answer"] == (f"not run: --trace {folder}/rivet.xml: is the same file as the application {folder}/rivet.xml, "
                                       "which this studio run reads; the trace would overwrite it: give another file")
    assert not station.session.running and (folder / "rivet.xml").read_text() == RIVET  # type: ignore[attr-defined]


def test_the_studio_saves_no_application_over_its_cell_or_its_runs_files(folder: Path) -> None:
    (folder / "cells").mkdir()
    cell = (ROOT / "apps_xml" / "cells" / "rivet_cell.xml").read_text()
    (folder / "cells" / "rivet_cell.xml").write_text(cell)
    (folder / "rivet.xml").write_text((ROOT / "apps_xml" / "rivet_installation.xml").read_text())
    (folder / "run.xml").write_text("an earlier run's trace, named .xml by mistake\n")
    _, client = studio(folder, trace=str(folder / "run.xml"))
    document = client.get("/api/document").json()["document"]  # type: ignore[attr-defined]
    saved = client.post("/api/save", json={"path": "cells/rivet_cell.xml", "document": {**document, "cell": "rivet_cell.xml"}}).json()  # type: ignore[attr-defined] # its own cell
    assert not saved["ok"] and saved["messages"][-1]["message"].startswith(
        f"save as {folder}/cells/rivet_cell.xml: is the same file as the cell {folder}/cells/rivet_cell.xml, which this application reads")
    saved = client.post("/api/save", json={"path": "run.xml", "document": document}).json()  # type: ignore[attr-defined]
    assert not saved["ok"] and saved["messages"][-1]["message"] == (
        f"save as {folder}/run.xml: is the same file as --trace {folder}/run.xml; the application and the trace would overwrite each other: give each its own file")
    assert (folder / "cells" / "rivet_cell.xml").read_text() == cell and (folder / "run.xml").read_text().startswith("an earlier run")
    assert client.post("/api/save", json={"path": "rivet.xml", "document": document}).json()["ok"]  # type: ignore[attr-defined] # over itself: saving


def test_the_studio_refuses_clashing_settings_before_it_serves(folder: Path) -> None:
    err = io.StringIO()
    done = threading.Event()
    code: list[int] = []

    def serve() -> None:
        code.append(main(["studio", "--port", "0", "--trace", str(folder / "x.sqlite"), "--trajectory-db", str(folder / "x.sqlite")], io.StringIO(), err))
        done.set()

    threading.Thread(target=serve, daemon=True).start()
    assert done.wait(30), "the studio served instead of refusing"
    assert code == [2] and err.getvalue() == (
        f"error: --trajectory-db {folder}/x.sqlite: is the same file as --trace {folder}/x.sqlite; "
        "the trajectory database and the trace would overwrite each other: give each its own file\n")
