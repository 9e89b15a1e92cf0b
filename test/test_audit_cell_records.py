"""The audit of what the cell's operators did outside the page, record by record (operator_station/cell_audit.py):
who each entry names, what is left out as the page's own, and that no record the station is given -- the run's
records come from other processes on a ROS graph -- can make it fail or name the page."""
from __future__ import annotations

from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from operator_station.audit import AuditLog
from operator_station.cell_audit import EXPECT_FOR, SAFETY_INPUT, CellAudit, tell
from operator_station.feed import Feed

NOW = 1764230400.0


def audited(ends: bool = False) -> tuple[CellAudit, AuditLog, list[float]]:
    now = [NOW]
    log = AuditLog(wall=lambda: now[0])
    return CellAudit(lambda: log, "studio", lambda: now[0], ends=ends), log, now


def operator(command: str, source: str, **more: Any) -> dict[str, Any]:
    return {"t": 12.5, "event": "operator", "group": "engine", "operation": "4", "command": command, "source": source,
            "state": "running", "accepted": True, "answer": "paused", **more}


def shown(log: AuditLog) -> list[tuple[str, str, bool]]:
    return [(e["who"], e["what"], e["ok"]) for e in log.entries]


def test_each_outside_command_is_audited_under_its_source_and_the_pages_own_are_left_to_their_routes() -> None:
    cell, log, _ = audited()
    for record in (operator("pause", "studio"), operator("pause", "terminal console (key 'p')"),
                   operator("speed_override", "parameter /execution_engine/speed_override", answer="speed override 50 % (was 100 %)", percent=50.0),
                   operator("break", "service /execution_engine/breakpoint", target="7"), operator("stop", "action /execute_application cancel"),
                   operator("pause", "safety stop on /cell/safety_stop"),
                   {"t": 13.0, "event": "swap", "from_digest": "ab", "to_digest": "cd", "from_operation": 5, "file": "app.xml", "source": "studio (anna)"},
                   {"t": 14.0, "event": "swap", "from_digest": "ab", "to_digest": "cd", "from_operation": 5, "file": "app.xml", "source": "terminal console"},
                   {"t": 15.0, "event": "engine_state", "from": "running", "to": "stopped"}):
        cell.see(record)
    assert shown(log) == [("terminal console (key 'p')", "pause", True), ("parameter /execution_engine/speed_override", "speed override", True),
                          ("service /execution_engine/breakpoint", "breakpoint set", True), ("action /execute_application cancel", "stop", True),
                          ("cell", "safety event", True), ("terminal console", "edit paused run", True)]
    entries = list(log.entries)
    assert (entries[0]["t"], entries[0]["operation"], entries[0]["source"], entries[0]["role"], entries[0]["kind"]) == (12.5, "4", "terminal console (key 'p')", "", "cell")
    assert entries[1]["percent"] == 50.0 and entries[2]["target"] == "7"
    assert (entries[5]["before"], entries[5]["after"], entries[5]["from_operation"]) == ("sha256:ab", "sha256:cd", 5)


def test_a_service_call_the_page_said_it_was_making_is_the_pages_once_and_only_for_a_while() -> None:
    cell, log, now = audited()
    cell.expect("pause")
    cell.expect("breakpoint")
    cell.see(operator("pause", "service /execution_engine/pause"))  # the page's: audited by its route
    cell.see(operator("break", "service /ns/execution_engine/breakpoint"))  # a namespaced engine: the same service
    cell.see(operator("pause", "service /execution_engine/pause"))  # someone else's, the same command
    cell.expect("resume")
    now[0] += EXPECT_FOR + 1.0  # the page's call never reached the engine
    cell.see(operator("resume", "service /execution_engine/resume"))
    assert shown(log) == [("service /execution_engine/pause", "pause", True), ("service /execution_engine/resume", "resume", True)]


def test_the_safety_stop_input_is_audited_on_each_change_by_others_and_never_for_the_stations_own() -> None:
    cell, log, _ = audited()
    feed = Feed()
    cell.attach(feed)

    def heard(active: bool, changed: bool, first: bool = False) -> None:
        tell(feed, {"event": SAFETY_INPUT, "active": active, "changed": changed, "first": first, "topic": "/cell/safety_stop"})

    heard(False, False, first=True)  # latched, at joining: nothing happened
    undo = cell.publishing(True)
    heard(True, True)  # the page's raise: its route audited it
    heard(False, True)  # a light curtain's reset, say
    heard(False, False)  # the same again
    heard(True, True)
    cell.publishing(False)
    undo2 = cell.publishing(True)
    undo2()  # not published after all (no run going)
    heard(False, True)  # the page's clear
    assert shown(log) == [("/cell/safety_stop", "safety stop cleared", True), ("/cell/safety_stop", "safety stop raised", True)]
    undo()  # taken already: nothing to undo
    other, log2, _ = audited()
    other.see({"event": SAFETY_INPUT, "active": True, "changed": True, "first": True, "topic": "/cell/safety_stop"})
    assert [e["answer"] for e in log2.entries] == ["seen on joining: the safety stop is active"]
    assert not feed.records  # the input is told to the taps, never stored as a record of the run


def test_a_runs_end_is_audited_from_the_engines_state_only_for_a_cell_the_station_watches() -> None:
    for ends in (False, True):
        cell, log, _ = audited(ends)
        cell.see({"t": 30.0, "event": "engine_state", "from": "running", "to": "running"})
        cell.see({"t": 31.0, "event": "engine_state", "from": "running", "to": "finished", "message": "done"})
        assert shown(log) == ([("cell", "run end", True)] if ends else [])


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=20),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3), max_leaves=6)
RECORD = st.fixed_dictionaries(
    {"event": st.sampled_from(["operator", "swap", "engine_state", SAFETY_INPUT, "transition", "x"]) | JSON},
    optional={"source": st.sampled_from(["studio", "studio (ben)", "service /execution_engine/pause", "safety stop on /x"]) | JSON,
              "command": JSON, "accepted": JSON, "answer": JSON, "t": JSON, "to": JSON, "active": JSON, "changed": JSON,
              "first": JSON, "from_digest": JSON, "to_digest": JSON, "target": JSON, "operation": JSON})


@settings(max_examples=100, deadline=None)
@given(st.lists(RECORD, max_size=12))
def test_any_records_are_audited_without_failing_and_never_under_the_pages_name(records: list[dict[str, Any]]) -> None:
    cell, log, _ = audited(ends=True)
    for record in records:
        cell.see(record)
    for entry in log.entries:
        assert entry["who"] not in ("studio", "") and not entry["who"].startswith("studio (")
        assert isinstance(entry["what"], str) and entry["what"] and isinstance(entry["ok"], bool)
    assert [e["seq"] for e in log.entries] == list(range(1, len(log.entries) + 1))
