"""A replay shows the dry run's plan the live run showed: planned bars against actual ones, cycle against prediction.

The plan the start check proved is published on the latched ``execution_engine/plan`` topic; the trace keeps it as
``plan`` records and the recording as RunPlan messages (execution_engine/run_plan.py).  Here the station's own run
(RunSession, simulated time) and ``run`` from the command line (its verdict kept from the station's dry run of the
same files) each write their record; every replay of them (trace, recording) puts into its feed the very plan the
live feed had.  A run with ``--no-check`` has no plan and none is shown; an older trace without it, and one whose
plan is damaged, still replay -- the damage said in one line.
"""
from __future__ import annotations

import io
import json
import math
import shutil
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from app_functions.registry import full_catalog
from cell_runner.run_report import summarize as report
from cell_runner.settings import Outputs, RunSettings
from execution_engine.app_model import load_application
from operator_station.feed import Feed
from operator_station.program import main
from operator_station.replay import load_replay
from operator_station.session import RunSession
from operator_station.timeline_view import TimelineView

ROOT = Path(__file__).resolve().parents[1]


def lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]


def replayed(path: Path) -> Feed:
    feed = Feed()
    assert load_replay(feed, path) > 0
    return feed


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The station's run of the rivet demonstrator with a trace, then ``run`` of it with a trace and a recording."""
    folder = tmp_path_factory.mktemp("plan")
    shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
    app_path = folder / "rivet.xml"
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", app_path)
    db = str(folder / "trajectories.sqlite")
    app = load_application(app_path, full_catalog())
    feed = Feed()
    session = RunSession(feed, RunSettings(speed=math.inf, outputs=Outputs(trace=str(folder / "studio.jsonl"), trajectory_db=db)))
    ok, answer = session.start(app, [{"id": op.id, "name": op.name, "calls": {}, "iteration": op.origin} for op in app.operations])
    assert ok, answer
    session.join(120.0)
    assert not session.running and session.report is not None and session.report.ok, feed.snapshot.messages
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app_path), "--speed", "max", "--trajectory-db", db, "--trace", str(folder / "run.jsonl"),
                 "--record", str(folder / "run.mcap")], out=out, err=err)
    assert code == 0, err.getvalue()
    return {"folder": folder, "app": app_path, "db": db, "live": feed, "out": out.getvalue()}


def test_a_checked_runs_trace_and_recording_carry_the_plan_and_each_replay_shows_the_live_one(runs: dict[str, Any]) -> None:
    folder, live = runs["folder"], runs["live"].snapshot
    ops = [op.id for op in load_application(runs["app"], full_catalog()).operations]
    assert len(live.plan) == len(ops) and live.plan_functions and sum(live.plan) > 0  # the live page drew planned bars
    assert "(cached verdict: passed" in runs["out"]  # run took the station's verdict, kept: its plan is carried too
    for trace in ("studio.jsonl", "run.jsonl"):
        (plan,) = [r for r in lines(folder / trace) if r["event"] == "plan"]
        assert [o for o, _ in plan["operations"]] == ops and plan["basis"] == "start"
        assert math.isclose(plan["cycle_time"], sum(live.plan), rel_tol=1e-6)
    with open(folder / "run.mcap", "rb") as stream:  # a RunPlan message on the latched topic, as any MCAP reader sees it
        reader = make_reader(stream)
        channels = [c for c in reader.get_summary().channels.values() if c.topic.endswith("/execution_engine/plan")]
        assert len(channels) == 1 and "transient_local" in channels[0].metadata["offered_qos_profiles"]
        schema = reader.get_summary().schemas[channels[0].schema_id]
        assert (schema.name, schema.encoding) == ("dual_arm_executive_interfaces/msg/RunPlan", "ros2msg")
    for record in ("studio.jsonl", "run.jsonl", "run.mcap"):
        feed = replayed(folder / record)
        shown = feed.snapshot
        assert shown.plan == pytest.approx(live.plan, abs=1e-6), record
        assert sorted((p["group"], p["operation"], round(p["planned"], 6)) for p in shown.plan_functions) == \
            sorted((p["group"], p["operation"], round(p["planned"], 6)) for p in live.plan_functions), record
        assert shown.summary["predicted"] == pytest.approx(live.summary["predicted"], abs=1e-5), record
        assert not [m for m in shown.messages if "plan" in m["message"]], (record, shown.messages)
        assert len(feed.records) == len(lines(folder / record)) if record.endswith(".jsonl") else True  # the page's records are the file's
        bars = [b for lane in TimelineView(feed).model()["lanes"].values() for b in lane]
        assert [b for b in bars if b["planned"] is not None], record  # the replayed timeline has its planned bars
        said = [line for line in report(folder / record).lines() if line.startswith("  predicted: cycle ")]
        assert said == [f"  predicted: cycle {sum(live.plan):.3f} s by the dry run from the simulator's start; "
                        f"the run {shown.summary['cycle_time']:.3f} s ({shown.summary['cycle_time'] - sum(live.plan):+.3f} s)"], record


def test_a_run_without_the_check_has_no_plan_and_says_none(runs: dict[str, Any]) -> None:
    folder = runs["folder"]
    trace = folder / "unchecked.jsonl"
    code = main(["run", str(runs["app"]), "--speed", "max", "--no-check", "--trajectory-db", runs["db"], "--trace", str(trace), "-q"],
                out=io.StringIO(), err=io.StringIO())
    assert code == 0
    assert not [r for r in lines(trace) if r["event"] == "plan"]
    shown = replayed(trace).snapshot
    assert (shown.plan, shown.plan_functions, shown.summary["predicted"]) == ([], [], None)
    assert not [line for line in report(trace).lines()[1:] if "predicted" in line or "plan" in line]  # (the first names the file)


def test_an_older_trace_without_the_plan_replays_without_planned_bars(runs: dict[str, Any]) -> None:
    old = runs["folder"] / "old.jsonl"
    old.write_text("".join(json.dumps(r) + "\n" for r in lines(runs["folder"] / "run.jsonl") if r["event"] != "plan"), encoding="utf-8")
    feed = replayed(old)
    assert (feed.snapshot.plan, feed.snapshot.plan_functions, feed.snapshot.messages) == ([], [], [])
    assert not [b for lane in TimelineView(feed).model()["lanes"].values() for b in lane if b["planned"] is not None]


@pytest.mark.parametrize(("damage", "said"), [
    (lambda r: {**r, "cycle_time": "soon"}, "cycle_time: soon is no run time"),
    (lambda r: {**r, "operations": r["operations"] + r["operations"][:1]}, "listed twice"),
    (lambda r: {**r, "functions": [["left_arm", "1"]]}, "functions[0]: not a list of 3"),
    (lambda r: {**r, "part": 2, "parts": 2}, "part 2 of 2 without the parts before it"),
    (lambda r: {**r, "basis": "hope"}, "basis 'hope'"),
])
def test_a_damaged_plan_is_left_out_in_one_line_and_the_run_still_replays(runs: dict[str, Any], damage: Any, said: str) -> None:
    damaged = runs["folder"] / "damaged.jsonl"
    records = [damage(r) if r["event"] == "plan" else r for r in lines(runs["folder"] / "run.jsonl")]
    damaged.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    feed = replayed(damaged)
    notes = [m["message"] for m in feed.snapshot.messages]
    assert len(notes) == 1 and said in notes[0] and "\n" not in notes[0] and "no planned bars" in notes[0], notes
    assert feed.snapshot.plan == [] and feed.snapshot.summary["outcome"] == "finished"
    lines_said = report(damaged).lines()
    assert [line for line in lines_said if said in line] and not [line for line in lines_said if line.startswith("  predicted:")]
