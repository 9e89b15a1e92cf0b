"""The run summary the monitor shows after a run (operator_station/run_summary.py), from real runs' traces.

Each run is the rivet demonstrator (or its sync="flags" variant) at simulated time through ``run`` itself,
with a fault injected where the summary has something to say about it.  What is checked is what the
operator reads: the outcome, the cycle against the prediction, each group's busy and idle time adding up to
the cycle, the waits that cost most named as the timeline names them, and every error with whether a retry
recovered it and what to do (the monitor's own action for how the run ended, the fault kind's advice, the
docs/faults.md row the message matches).
"""
from __future__ import annotations

import io
import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from cell_runner.run_report import summarize as report_summary
from execution_engine.timeline import build_timeline
from operator_station.program import main as cli_main
from operator_station.feed import Feed
from operator_station.run_summary import ADVICE, SummaryOnEnd, faults_row, summarize

ROOT = Path(__file__).resolve().parents[1]


def run(tmp_path: Path, app: str, *options: str) -> list[dict[str, Any]]:
    """The records of ``run APP --speed max --no-check`` with ``options``."""
    if not (tmp_path / "cells").exists():
        shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / app, tmp_path / app)
    trace = tmp_path / f"{app}.{len(list(tmp_path.glob('*.jsonl')))}.jsonl"
    cli_main(["run", str(tmp_path / app), "--speed", "max", "--no-check", "-q", "--trace", str(trace), "--trajectory-db", ":memory:", *options],
             out=io.StringIO(), err=io.StringIO())
    return [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]


def test_a_failed_run_names_its_error_once_with_the_monitors_action_the_faults_advice_and_its_faults_row(tmp_path: Path) -> None:
    records = run(tmp_path, "rivet_installation.xml", "--fault", "right_arm:joint_limit@0.5")
    summary = summarize(records, [9.0] * 10)
    end = records[-1]
    assert (summary.outcome, summary.exit_code, summary.operations_done, summary.operations_total) == ("failed", 1, end["operations_done"], 10)
    assert summary.cycle_time == pytest.approx(end["t"] - records[0]["t"])
    assert summary.predicted == 90.0 and summary.deviation == pytest.approx(summary.cycle_time - 90.0)
    failing = [e for e in summary.errors if e.group == "right_arm"]
    assert len(failing) == 1 and not failing[0].recovered and failing[0].kind == "joint_limit"
    assert "Start again" in failing[0].actions[0] and "Open the builder" in failing[0].actions[0]
    assert failing[0].actions[1] == ADVICE["joint_limit"]
    assert failing[0].faults_row == "docs/faults.md row 41: injected fault fails the run"  # the engine's words of it matched row 41
    assert not [e for e in summary.errors if e.group == "engine"]  # the run's failure is that error, not a second item
    stopped = [e for e in summary.errors if e.group == "left_arm"]  # stopped by the engine when right_arm failed
    assert stopped and all(e.kind == "stopped" and "nothing for this group" in e.actions[0] for e in stopped)
    assert any("see docs/faults.md row 41" in line for line in summary.lines())


def test_a_retried_error_is_said_recovered_and_busy_and_idle_add_up_to_the_cycle_as_report_counts_them(tmp_path: Path) -> None:
    records = run(tmp_path, "rivet_installation.xml", "--fault", "left_arm:vision")
    summary = summarize(records)
    assert summary.outcome == "finished" and summary.retries == 1 and summary.predicted is None and summary.deviation is None
    (error,) = summary.errors
    assert error.group == "left_arm" and error.kind == "vision" and error.recovered
    assert error.actions[0].startswith("nothing now: a retry recovered it") and ADVICE["vision"] in error.actions[0]
    timeline = build_timeline(records)
    for share in summary.groups:
        assert share.busy + share.idle == pytest.approx(summary.cycle_time, abs=1e-6)
        assert share.busy == pytest.approx(timeline.lanes[share.group].busy)
    trace = tmp_path / "again.jsonl"  # report reads the same trace to the same busy times
    trace.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    lanes = report_summary(trace).timeline.lanes
    assert {g.group: round(g.busy, 6) for g in summary.groups} == {g: round(lane.busy, 6) for g, lane in lanes.items()}


def test_the_waits_that_cost_most_are_named_flag_and_zone_waits_longest_first(tmp_path: Path) -> None:
    records = run(tmp_path, "rivet_async.xml")
    summary = summarize(records)
    assert summary.outcome == "finished" and summary.waits
    seconds = [w.seconds for w in summary.waits]
    assert seconds == sorted(seconds, reverse=True)
    timeline = build_timeline(records)
    for wait in summary.waits:
        assert wait.what.split(" ", 1)[0] in ("flag", "zone") and wait.label.startswith(f"waiting for {wait.what}")
        gaps = [g for g in timeline.lanes[wait.group].idle if g.waiting == wait.what]
        assert wait.seconds == pytest.approx(sum(g.duration for g in gaps))
    by_group = {g.group: g.waiting for g in summary.groups}
    assert max(by_group.values()) >= summary.waits[0].seconds - 1e-9


def test_a_cut_record_and_text_no_row_matches() -> None:
    records = [{"t": 0.0, "event": "function_start", "group": "left_arm", "operation": "1", "function": "home"},
               {"t": 2.5, "event": "error", "group": "left_arm", "operation": "1", "function": "home", "error": "move_joints(home): controller: drive error 17"}]
    summary = summarize(records, (), ["left_arm"])
    assert summary.outcome == "cut" and summary.exit_code is None and summary.cycle_time == 2.5 and summary.held == 0.0
    (error,) = summary.errors
    assert error.kind == "controller" and error.actions == (ADVICE["controller"],) and error.faults_row is None
    assert faults_row("nothing like any row of the table at all") is None
    assert summary.to_json()["errors"][0]["group"] == "left_arm"


def test_a_watched_cells_summary_comes_when_its_engine_ends_and_goes_when_it_starts_again(tmp_path: Path) -> None:
    """studio --transport ros: no run_end on the graph; the engine's finished state brings the summary."""
    records = [r for r in run(tmp_path, "rivet_installation.xml") if r["event"] != "run_end"]
    feed = Feed()
    feed.begin("live", "rivet_installation", ["left_arm", "right_arm", "torso_head"])
    hook = SummaryOnEnd(feed)
    ended = next(i for i, r in enumerate(records) if r["event"] == "engine_state" and r["to"] == "finished")
    for i, record in enumerate(records):
        feed.append(record)
        hook.see(record)
        assert (feed.snapshot.summary is not None) == (i >= ended)
    assert feed.snapshot.summary is not None and feed.snapshot.summary["outcome"] == "finished"
    hook.see({"t": 99.0, "event": "engine_state", "group": "engine", "to": "running"})
    assert feed.snapshot.summary is None


def test_the_time_paused_or_at_an_alarm_is_said_as_part_of_the_cycle() -> None:
    state = lambda t, to: {"t": t, "event": "engine_state", "group": "engine", "to": to}  # noqa: E731
    records = [state(0.0, "running"), state(2.0, "paused"), state(5.0, "running"), state(6.0, "alarm"), state(6.5, "running"),
               state(8.0, "paused"), {"t": 9.0, "event": "run_end", "group": "engine", "outcome": "stopped", "exit_code": 3}]
    summary = summarize(records)
    assert summary.held == pytest.approx(3.0 + 0.5 + 1.0)  # the last pause lasts until the end
    assert "(4.50 s of it paused or at an alarm)" in summary.lines()[0]
