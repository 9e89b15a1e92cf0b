"""The station's breakpoint and run-to routes and the builder's break toggle, without a browser.

A bad request is one line and a 400, nothing changes; with no run going, a replay, or a refusal of the
engine, the answer says why; the builder's document carries ``break`` both ways (opened from the file,
saved as ``break="true"``).  The page itself is driven in test_breakpoints_browser.py.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from execution_engine.app_model import load_application  # noqa: E402
from node_transport.clock import scaled_clock  # noqa: E402
from operator_station.attach import AttachedSession  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.feed import Feed  # noqa: E402
from operator_station.server import Station  # noqa: E402
from test_studio_server import CATALOG, cell_dir, cell_elsewhere, client_for, rivet, run_to_end, station_args, wait_until  # noqa: E402,F401 - cell_dir: fixture


def test_bad_requests_are_one_line_and_change_nothing(cell_dir: Path) -> None:
    station, client, _ = rivet(cell_dir, no_check=True)
    for url, body, words in (
        ("/api/breakpoint", {"action": "flip", "operation": "3"}, "breakpoint: action must be one of set, clear, toggle, clear_all"),
        ("/api/breakpoint", {"action": "set", "operation": 3}, "breakpoint: operation must be an operation's id or #N"),
        ("/api/breakpoint", {"action": "set", "operation": "x" * 500}, "breakpoint: operation must be an operation's id or #N"),
        ("/api/run_to", {}, 'run_to: give {"operation": ID or "#N"}'),
    ):
        answer = client.post(url, json=body)
        assert answer.status_code == 400 and answer.json()["error"].startswith(words), body
    assert client.post("/api/breakpoint", content=b"{not json", headers={"content-type": "application/json"}).status_code == 400
    idle = client.post("/api/breakpoint", json={"action": "set", "operation": "3"})
    assert idle.status_code == 409 and idle.json()["answer"].startswith("no run is going")
    assert [e["what"] for e in station.audit_log.entries if e["what"].startswith("breakpoint")] == ["breakpoint set"]


def test_a_replay_has_no_run_to_command(cell_dir: Path) -> None:
    trace = cell_dir / "run.jsonl"
    station, client, document = rivet(cell_dir, trace=str(trace), no_check=True)
    run_to_end(station, client, "rivet_installation.xml", document)
    replay = client_for(build_station(station_args(replay=str(trace)), CATALOG, cell_dir))
    assert replay.post("/api/run_to", json={"operation": "3"}).status_code == 409


def test_the_builder_saves_its_toggle_as_break_true_and_opens_it_again(cell_dir: Path) -> None:
    station, client, document = rivet(cell_dir, no_check=True)
    steps = document["body"] if "body" in document else document["operations"]
    third = next(s for s in steps if s.get("type", "operation") == "operation" and s["id"] == "3")
    third["break"] = True
    saved = client.post("/api/save", json={"path": "rivet_installation.xml", "document": document}).json()
    assert saved["ok"], saved
    text = (cell_dir / "rivet_installation.xml").read_text(encoding="utf-8")
    assert text.count('break="true"') + text.count("break='true'") == 1
    app = load_application(cell_dir / "rivet_installation.xml", CATALOG)
    assert [op.id for op in app.operations if op.breakpoint] == ["3"]
    reopened = client.get("/api/document").json()["document"]
    steps = reopened["body"] if "body" in reopened else reopened["operations"]
    assert [s["id"] for s in steps if s.get("break")] == ["3"]
    third["break"] = "yes"
    refused = client.post("/api/save", json={"path": "rivet_installation.xml", "document": document})
    assert refused.status_code == 400 and "break must be true or false" in refused.json()["error"]


def test_attached_to_a_cell_the_page_sets_breakpoints_and_runs_to_through_the_engines_services(cell_dir: Path) -> None:
    """``--transport ros`` with the in-process transport standing in for the ROS graph (test_studio_server's
    attached test): the station's routes reach the engine's breakpoint and run-to services."""
    plain = load_application(cell_dir / "rivet_installation.xml", CATALOG)
    app = dataclasses.replace(plain, operations=tuple(dataclasses.replace(op, breakpoint=op.id == "3") for op in plain.operations))
    feed = Feed()
    session = AttachedSession(feed, app.robot, app.name, cell_elsewhere(app), scaled_clock(20.0))
    session.attach()
    client = client_for(Station(CATALOG, feed, session, cell_dir, cell_dir / "rivet_installation.xml"))
    status = lambda: feed.snapshot.status or {}  # noqa: E731
    try:
        assert session.wait_started(60.0)
        assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": client.get("/api/document").json()["document"]}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "paused")
        assert status()["message"] == "paused at breakpoint before operation 3 '3' (line 50)"
        set_ = client.post("/api/breakpoint", json={"action": "set", "operation": "#7"}).json()
        assert set_ == {"ok": True, "answer": "breakpoint set before operation 7 '7' (line 120)", "breakpoints": ["3", "7"]}
        assert client.post("/api/run_to", json={"operation": "5"}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "paused" and status().get("operation_id") == "5", 120.0)
        assert status()["message"] == "paused before operation 5 '5' (line 85): the run-to target is reached"
        assert client.post("/api/breakpoint", json={"action": "clear_all"}).json()["ok"]
        assert client.post("/api/operator/resume", json={}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "finished", 120.0)
        commands = [(r["command"], r.get("target"), r["source"]) for r in feed.records if r["event"] == "operator"]
        assert commands == [("start", None, "service /execution_engine/start"), ("break", "7", "service /execution_engine/breakpoint"),
                            ("run_to", "5", "service /execution_engine/run_to"), ("unbreak_all", None, "service /execution_engine/breakpoint"),
                            ("resume", None, "service /execution_engine/resume")]
    finally:
        session.join(30.0)
