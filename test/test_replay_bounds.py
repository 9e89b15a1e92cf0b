"""``studio --replay`` reads a run's record as ``report`` does: the same bounds, the same one-line refusals, names escaped.

The files are test_report_bounds.py's crafted ones (chunks of zeros, chunks past the unpacked bound,
65 groups in a recording and 20,000 in a trace, times no run has, a right-to-left override in
names) and any file hypothesis makes: the station's replay refuses exactly the files ``report``
refuses, with the same line and exit code, before it serves anything; what it replays is what
``report`` summarises, record for record, with every text escaped; and reading either costs memory
in proportion to the file, never to what the file claims.
"""
from __future__ import annotations

import io
import json
import re
import shutil
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from test_report_bounds import (  # noqa: E402
    ESC,
    RLO,
    WHOLE,
    crafted_chunks,
    flipped,
    peak,
    status_recording,
    trace_line,
    zeros_bomb,
)

from cell_runner.run_report import summarize  # noqa: E402
from core_functions.printable import is_unsafe  # noqa: E402
from execution_engine.record_limits import MAX_GROUPS  # noqa: E402
from execution_engine.record_reader import NotARecording, OverLimit, read_record  # noqa: E402
from execution_engine.recorder.safe_read import MAX_CHUNK  # noqa: E402
from operator_station.feed import Feed  # noqa: E402
from operator_station.program import main  # noqa: E402
from operator_station.replay import load_replay  # noqa: E402
from operator_station.timeline_view import TimelineView  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: What reading a file may hold at most (one chunk at a time, as report): the bound test_report_bounds.py uses.
HELD = MAX_CHUNK + (16 << 20)


def studio_replay(path: Path) -> tuple[int, str, str]:
    """``python -m execution_engine studio --replay PATH`` in-process (a file it refuses returns before anything is served)."""
    out, err = io.StringIO(), io.StringIO()
    code = main(["studio", "--replay", str(path), "--port", "0"], out, err)
    return code, out.getvalue(), err.getvalue()


def report(path: Path) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(["report", str(path), "--no-timeline"], out, err)
    return code, out.getvalue(), err.getvalue()


def no_unsafe_text(value: Any) -> bool:
    """Every text in ``value`` (keys too), however nested, holds no control or bidirectional character."""
    if isinstance(value, str):
        return not any(is_unsafe(c) for c in value)
    if isinstance(value, dict):
        return all(no_unsafe_text(k) and no_unsafe_text(v) for k, v in value.items())
    if isinstance(value, list):
        return all(no_unsafe_text(v) for v in value)
    return True


def groups_trace(count: int) -> str:
    return "".join(trace_line(group=f"g{i}", t=0.01 * i) for i in range(count))


CRAFTED: dict[str, Any] = {
    "zeros.mcap": lambda: zeros_bomb(3),
    "unpacked.mcap": lambda: zeros_bomb(20, 64_000_000, struct.pack("<BQ", 0x80, 64_000_000 - 9) + b"\0" * (64_000_000 - 9)),
    "groups.mcap": lambda: status_recording(MAX_GROUPS + 1),
    "groups.jsonl": lambda: groups_trace(20_000).encode(),
    "empty.jsonl": lambda: b"",
    "garbage.jsonl": lambda: b"\x00\x01 not a trace at all\n",
}


# ------------------------------------------------------------------------------ refusals
@pytest.mark.parametrize("name", list(CRAFTED))
def test_the_replay_refuses_what_report_refuses_in_the_same_line_before_serving(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(CRAFTED[name]())
    code, out, err = studio_replay(path)
    report_code, report_out, report_err = report(path)
    assert (report_code, report_out) == (1, "") and report_err.startswith(f"error: {path}: ") and report_err.count("\n") == 1
    assert (code, out, err) == (1, "", report_err)  # nothing served, nothing printed but the refusal


def test_a_bomb_is_refused_by_the_replay_within_the_memory_report_has(tmp_path: Path) -> None:
    path = tmp_path / "zeros.mcap"
    path.write_bytes(zeros_bomb(3))
    feed = Feed()
    held, outcome = peak(lambda: load_replay(feed, path))
    assert isinstance(outcome, OverLimit) and str(outcome).startswith(f"{path}: refused: it holds more than "), outcome
    assert held < HELD
    assert feed.snapshot.mode == "idle" and not feed.records


def test_a_trace_of_20000_groups_is_refused_at_its_65th_group(tmp_path: Path) -> None:
    path = tmp_path / "groups.jsonl"
    path.write_text(groups_trace(20_000))
    with pytest.raises(OverLimit, match=re.escape(f"{path}: refused: more than {MAX_GROUPS} groups (line 65), the 65th 'g64'")):
        load_replay(Feed(), path)


# -------------------------------------------------------------------------- what is shown
def test_a_recording_is_replayed_record_for_record_as_report_reads_it(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    path.write_bytes(WHOLE)
    feed = Feed()
    count = load_replay(feed, path)
    assert count == 40 and len(feed.records) == 40
    assert feed.snapshot.mode == "replay" and feed.snapshot.groups == ["left_arm"]
    assert [r["t"] - feed.records[0]["t"] for r in feed.records] == pytest.approx([0.1 * i for i in range(40)], abs=1e-6)
    assert TimelineView(feed).model()["records"] == 40
    assert summarize(path).timeline.t_end == pytest.approx(feed.records[-1]["t"])
    # no end record in this crafted recording's run: the page says the run was cut, as report does
    assert summarize(path).cut == any("the run was cut" in m["message"] for m in feed.snapshot.messages)


def test_a_runs_recording_replays_as_its_trace(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One run of the rivet demonstrator, traced and recorded: the station shows the same run from either file."""
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    monkeypatch.chdir(tmp_path)
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", "rivet_installation.xml", "--speed", "max", "-q", "--no-check", "--trace", "run.jsonl", "--record", "run.mcap"], out, err) == 0, err.getvalue()
    traced, recorded = Feed(), Feed()
    assert load_replay(recorded, tmp_path / "run.mcap") == load_replay(traced, tmp_path / "run.jsonl") - 1  # the trace's run_end
    assert traced.snapshot.groups == recorded.snapshot.groups == ["left_arm", "right_arm", "torso_head"]
    assert traced.snapshot.messages == recorded.snapshot.messages == []  # both whole
    assert traced.snapshot.status == recorded.snapshot.status == {"state": "replay", "operation_count": 10, "t": pytest.approx(traced.records[-1]["t"])}
    by_trace, by_recording = TimelineView(traced).model(), TimelineView(recorded).model()
    for key in ("groups", "end", "operations", "lanes", "idle", "busy", "retries"):
        assert by_trace[key] == by_recording[key], key
    assert repr(list(traced.joints)) == repr(list(recorded.joints))  # NaN where a joint was not reported yet: repr compares it
    assert traced.snapshot.joint_names == recorded.snapshot.joint_names and len(traced.joints) > 10


def test_times_no_run_has_are_skipped_and_said_as_report_says_them(tmp_path: Path) -> None:
    trace = tmp_path / "times.jsonl"
    trace.write_text(trace_line(t=1.0) + trace_line(t=2.0).replace('"t": 2.0', '"t": 1e308') + trace_line(event="function_end", t=3.0))
    feed = Feed()
    assert load_replay(feed, trace) == 2
    assert [r["t"] for r in feed.records] == [1.0, 3.0]
    assert any(m["message"].startswith(f"{trace}: 1 line(s) are not trace records and were skipped (first: line 2: t = 1e+308 s")
               for m in feed.snapshot.messages), feed.snapshot.messages
    recording = tmp_path / "times.mcap"
    recording.write_bytes(status_recording(0, times=[1.0, 2e7, 3.0]))
    feed = Feed()
    assert load_replay(feed, recording) == 2
    assert f"{recording}: 1 event(s) at a time no run has (not finite, or past ±10000000 s) skipped" in [m["message"] for m in feed.snapshot.messages]


def test_a_line_nested_thousands_deep_is_skipped_not_a_defect(tmp_path: Path) -> None:
    """A megabyte of '[' made the JSON parser give up with RecursionError: report ended in exit 70."""
    path = tmp_path / "deep.jsonl"
    path.write_text(trace_line(t=0.5) + trace_line(t=1.0, result="DEEP").replace('"DEEP"', "[" * 100_000 + "]" * 100_000)
                    + trace_line(t=1.5, result="SHALLOW").replace('"SHALLOW"', "[" * 150 + "]" * 150))
    code, out, err = report(path)
    assert code == 0, err
    assert "line 2: nested more than 100 levels deep: no record of a run is" in out
    assert "line 3: nested more than 100 levels deep" in out
    feed = Feed()
    assert load_replay(feed, path) == 1


def test_names_from_the_file_reach_the_page_escaped(tmp_path: Path) -> None:
    path = tmp_path / f"spoof{RLO}lnosj.jsonl"
    path.write_text(
        trace_line(group=f"left{RLO}mra", operation=f"1{RLO}gnp.exe", function=f"{ESC}[31mwait")
        + trace_line(event="primitive_end", t=0.5, group=f"left{RLO}mra", outcome="done",
                     result={"joint_names": [f"J{RLO}1", "J2"], "positions": [0.1, 10**400], f"k{ESC}": 1})
        + trace_line(event="error", t=1.0, group=f"left{RLO}mra", error=f"drive {ESC}]0;pwned{ESC}\\ fault")
        + json.dumps({"event": "operator", "t": 1.5, "group": "engine", "command": f"stop{RLO}", "source": f"page{ESC}", "accepted": True}) + "\n"
    )
    feed = Feed()
    assert load_replay(feed, path) == 4
    assert no_unsafe_text(feed.records) and no_unsafe_text(feed.snapshot.groups) and no_unsafe_text(feed.snapshot.app)
    assert feed.snapshot.groups == ["left\\u202emra"] and feed.snapshot.joint_names == ["J\\u202e1", "J2"]
    assert feed.records[2]["error"] == "drive \\x1b]0;pwned\\x1b\\ fault"
    assert no_unsafe_text(TimelineView(feed).model())


# ---------------------------------------------------------------------------- properties
def agree(path: Path) -> str:
    """The replay and report on one file: both refuse it in the same line, or the replay holds every record report reads."""
    feed = Feed()
    held, outcome = peak(lambda: load_replay(feed, path))
    assert held < HELD, f"{held} bytes held replaying a {path.stat().st_size}-byte file"
    try:
        records: list[dict[str, Any]] = []
        read_record(path, records.append)
    except (NotARecording, OverLimit) as refusal:
        assert type(outcome) is type(refusal) and str(outcome) == str(refusal), (outcome, refusal)
        assert str(refusal).startswith(str(path)) and "\n" not in str(refusal)
        assert feed.snapshot.mode == "idle"
        return "refused"
    if isinstance(outcome, Exception):
        raise outcome
    assert outcome == len(records) == len(feed.records) and feed.snapshot.mode == "replay"
    assert [r["t"] for r in feed.records] == [r["t"] for r in records]
    assert no_unsafe_text(feed.records) and no_unsafe_text(feed.snapshot.messages)
    assert TimelineView(feed).model()["records"] == len(records)
    return "replayed"


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, len(WHOLE)), flips=st.lists(st.tuples(st.integers(0, len(WHOLE) - 1), st.integers(1, 255)), max_size=6))
def test_a_recording_cut_or_flipped_anywhere_is_replayed_or_refused_as_report_does(tmp_path: Path, cut: int, flips: list[tuple[int, int]]) -> None:
    path = tmp_path / "flipped.mcap"
    path.write_bytes(flipped(cut, flips))
    agree(path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(claims=st.lists(st.integers(0, MAX_CHUNK), min_size=1, max_size=6), records=st.integers(0, 200_000), kind=st.sampled_from([0x00, 0x05, 0x80]))
@example(claims=[64_000_000] * 3, records=7_100_000, kind=0x00)  # the file: chunks of zeros
def test_crafted_chunks_never_pass_the_bounds_of_the_replay(tmp_path: Path, claims: list[int], records: int, kind: int) -> None:
    path = tmp_path / "crafted.mcap"
    path.write_bytes(crafted_chunks(claims, records, kind))
    agree(path)


TEXT = st.text(st.characters(codec="utf-8"), max_size=6)
VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30), TEXT, st.none(), st.booleans())


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(records=st.lists(st.fixed_dictionaries(
    {"event": st.sampled_from(["function_start", "function_end", "primitive_start", "primitive_end", "error", "operator", "run_end", "transition"]),
     "t": VALUES},
    optional={"group": TEXT, "operation": TEXT, "function": TEXT, "error": TEXT, "operations_total": VALUES,
              "result": st.fixed_dictionaries({}, optional={"joint_names": st.lists(VALUES, max_size=3), "positions": st.lists(VALUES, max_size=3)})},
), max_size=40), tail=st.binary(max_size=40))
def test_any_trace_is_replayed_or_refused_as_report_does(tmp_path: Path, records: list[dict[str, Any]], tail: bytes) -> None:
    path = tmp_path / "crafted.jsonl"
    path.write_bytes(("\n".join(json.dumps(r, allow_nan=True) for r in records) + "\n").encode() + tail)
    agree(path)
