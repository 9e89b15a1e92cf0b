"""The timeline to read (issue 25 item 3): the critical path across groups, waits named after who they waited on,
the dry run's plan against what each function took, retries and errors kept with their message."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from execution_engine.timeline import TimelineBuilder, build_timeline, plan_deltas, planned_functions
from execution_engine.timeline_path import critical_path, path_ids


def rec(t: float, event: str, group: str, **fields: Any) -> dict[str, Any]:
    return {"t": t, "event": event, "group": group, **fields}


def function(group: str, operation: str, name: str, start: float, end: float | None, outcome: str = "succeeded") -> list[dict[str, Any]]:
    out = [rec(start, "function_start", group, operation=operation, function=name)]
    if end is not None:
        out.append(rec(end, "function_end", group, operation=operation, function=name, outcome=outcome))
    return out


def flag(t: float, group: str, name: str, state: str, kind: str = "flag") -> dict[str, Any]:
    return rec(t, "flag", group, flag=name, kind=kind, state=state)


def ordered(*parts: list[dict[str, Any]] | dict[str, Any]) -> list[dict[str, Any]]:
    records = [r for p in parts for r in (p if isinstance(p, list) else [p])]
    return sorted(records, key=lambda r: r["t"])  # stable: records of one instant keep the order written


# sync="flags": the right arm picks quickly, then waits for the left arm's flag 'hole_ready' (set when its long
# debur ends at 8 s) before it inserts; the left arm then moves away (short).  The cycle ends with the right
# arm's insert, so the path runs through the LEFT arm's debur, across the flag, into the right arm's insert.
FLAG_RUN = ordered(
    function("left_arm", "1", "debur_drilling", 0.0, 8.0),
    flag(8.001, "left_arm", "hole_ready", "set"),
    function("left_arm", "3", "move_to_joint_pose", 8.002, 9.0),
    function("right_arm", "1", "pick_rivet", 0.0, 2.0),
    flag(2.001, "right_arm", "hole_ready", "waiting"),
    flag(8.002, "right_arm", "hole_ready", "passed"),
    function("right_arm", "2", "insert_rivet", 8.003, 12.0),
)


def test_a_flag_wait_puts_the_group_that_set_the_flag_on_the_critical_path() -> None:
    timeline = build_timeline(FLAG_RUN, ["left_arm", "right_arm"])
    path = critical_path(timeline)
    assert [(s.bar.group, s.bar.function) for s in path] == [("left_arm", "debur_drilling"), ("right_arm", "insert_rivet")]
    assert path_ids(path) == ["left_arm:0", "right_arm:1"]
    assert path[0].via == "flag hole_ready" and path[0].wait is not None and path[0].wait.group == "right_arm"
    assert path[-1].via == ""  # the last function: the cycle ends with it
    # the right arm's own pick is off the path: shortening it would not shorten the cycle
    assert "right_arm:0" not in path_ids(path)


def test_waits_are_named_after_what_and_whom_they_waited_for() -> None:
    timeline = build_timeline(FLAG_RUN, ["left_arm", "right_arm"])
    [wait] = [g for g in timeline.lanes["right_arm"].idle if g.waiting]
    assert (wait.waiting, wait.by, wait.outcome, wait.t_start, wait.t_end) == ("flag hole_ready", "left_arm", "passed", 2.001, 8.002)
    assert wait.label == "waiting for flag hole_ready set by left_arm"
    # mid-wait (a live view, or a replay's slider at 5 s) the flag is not set yet: the wait says so
    early = TimelineBuilder(["left_arm", "right_arm"]).add_all(r for r in FLAG_RUN if r["t"] <= 5.0).snapshot(5.0)
    [open_wait] = [g for g in early.lanes["right_arm"].idle if g.waiting]
    assert (open_wait.t_end, open_wait.label) == (5.0, "waiting for flag hole_ready (not set yet)")


def test_a_zone_wait_names_the_group_that_held_the_zone_and_the_path_crosses_it() -> None:
    records = ordered(
        # on a simulated clock the call's end, its leaving the zone and the next call's start are one instant
        function("left_arm", "1", "insert_rivet", 0.0, 6.0),
        flag(0.01, "left_arm", "shared_table", "passed", "zone"),
        flag(6.0, "left_arm", "shared_table", "left", "zone"),
        function("left_arm", "3", "move_to_joint_pose", 6.0, 7.0),
        function("right_arm", "2", "debur_drilling", 1.0, 11.0),  # its motion into the zone waits inside the function
        flag(1.01, "right_arm", "shared_table", "waiting", "zone"),
        flag(6.0, "right_arm", "shared_table", "passed", "zone"),
    )
    timeline = build_timeline(records, ["left_arm", "right_arm"])
    [wait] = [g for g in timeline.lanes["right_arm"].idle if g.waiting]
    assert wait.label == "waiting for zone shared_table held by left_arm" and (wait.t_start, wait.t_end) == (1.01, 6.0)
    assert timeline.lanes["right_arm"].busy == pytest.approx(10.0 - (6.0 - 1.01))  # the wait is idle time, not work
    path = critical_path(timeline)
    assert path_ids(path) == ["left_arm:0", "right_arm:0"] and path[0].via == "zone shared_table"


def test_in_lock_step_the_slowest_group_of_each_operation_is_on_the_path() -> None:
    records = ordered(
        function("left_arm", "1", "debur_drilling", 0.0, 5.0),
        function("right_arm", "1", "pick_rivet", 0.0, 2.0),  # quick: idle until the operation's barrier
        function("left_arm", "2", "move_to_joint_pose", 5.01, 6.0),
        function("right_arm", "2", "insert_rivet", 5.01, 9.0),
    )
    path = critical_path(build_timeline(records, ["left_arm", "right_arm"]))
    assert [(s.bar.id, s.via) for s in path] == [("left_arm:0", "barrier"), ("right_arm:1", "")]


def test_a_timeline_without_functions_has_no_path() -> None:
    assert critical_path(build_timeline([rec(0.0, "engine_state", "engine", to="running")], ["left_arm"])) == []


def test_planned_against_actual_per_function_with_its_retries() -> None:
    spans = [SimpleNamespace(group="left_arm", operation="1", function="debur_drilling", start=s, end=e) for s, e in ((0.0, 3.0), (3.0, 6.5))]
    spans.append(SimpleNamespace(group="right_arm", operation="2", function="insert_rivet", start=1.0, end=4.0))
    planned = planned_functions(spans)
    assert planned == {("left_arm", "1"): 6.5, ("right_arm", "2"): 3.0}
    records = ordered(
        function("left_arm", "1", "debur_drilling", 0.0, 8.0),
        function("right_arm", "2", "insert_rivet", 0.0, 1.0, outcome="aborted"),
        rec(1.0, "error", "right_arm", operation="2", error="vision: drill_1 not found"),
        function("right_arm", "2", "insert_rivet", 1.5, 4.5),  # the retry
        function("right_arm", "3", "move_to_joint_pose", 4.6, 5.0),  # not in the plan: no planned bar, no delta
    )
    timeline = build_timeline(records, ["left_arm", "right_arm"], planned)
    first, retry, unplanned = timeline.lanes["right_arm"].bars
    assert (first.planned, retry.planned, unplanned.planned) == (3.0, 3.0, None)
    assert (first.error, first.outcome, retry.attempt, timeline.retries) == ("vision: drill_1 not found", "aborted", 2, 1)
    assert [(m.kind, m.group, m.t, m.text) for m in timeline.marks] == [("error", "right_arm", 1.0, "vision: drill_1 not found")]
    deltas = {(d.group, d.operation): d for d in plan_deltas(timeline)}
    assert set(deltas) == {("left_arm", "1"), ("right_arm", "2")}
    assert (deltas["left_arm", "1"].actual, deltas["left_arm", "1"].delta) == (8.0, pytest.approx(1.5))
    insert = deltas["right_arm", "2"]  # both attempts count: from the first start to the retry's end
    assert (insert.actual, insert.attempts, insert.delta, insert.done) == (4.5, 2, pytest.approx(1.5), True)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(
    st.sampled_from(["function_start", "function_end", "flag", "error"]),
    st.sampled_from(["left_arm", "right_arm", "torso_head"]),
    st.floats(0.0, 20.0),
    st.sampled_from(["1", "2", "3"]),
    st.sampled_from(["flag", "zone"]),
    st.sampled_from(["waiting", "passed", "set", "left", "timeout", "stopped"]),
    st.sampled_from(["a", "b"]),
), max_size=60))
def test_any_trace_gives_a_path_that_ends_with_the_last_function_and_named_waits(events: list[tuple[Any, ...]]) -> None:
    """Whatever order a (cut, replayed, hostile) trace gives its records in, the path is a chain of distinct bars ending
    with the function that ended last, and every wait has a name."""
    records = [rec(t, event, group, operation=operation, function=f"f{operation}", flag=name, kind=kind, state=state, outcome="succeeded", error="e")
               for event, group, t, operation, kind, state, name in sorted(events, key=lambda e: e[2])]
    timeline = build_timeline(records)
    path = critical_path(timeline)
    bars = [bar for lane in timeline.lanes.values() for bar in lane.bars]
    assert len(path_ids(path)) == len(set(path_ids(path)))
    if bars:
        assert path and path[-1].bar.end(timeline.t_end) == max(bar.end(timeline.t_end) for bar in bars) and path[-1].via == ""
    else:
        assert path == []
    for lane in timeline.lanes.values():
        for gap in lane.idle:
            assert gap.label.startswith("waiting for ") if gap.waiting else gap.label == "idle"


def test_the_reports_plot_names_the_waits_and_shows_the_path_and_the_plan(tmp_path: Path) -> None:
    from execution_engine.timeline_plot import plot_timeline  # matplotlib is slow to load (0.4 s): only this test draws

    planned = {("left_arm", "1"): 7.0, ("right_arm", "2"): 4.5}
    svg = plot_timeline(build_timeline(FLAG_RUN, ["left_arm", "right_arm"], planned), tmp_path / "t.svg").read_text(encoding="utf-8")
    assert "waiting for flag hole_ready set by left_arm" in svg
    assert "critical path" in svg and "planned (dry run)" in svg
    plain = plot_timeline(build_timeline(FLAG_RUN[:3], ["left_arm"]), tmp_path / "plain.svg").read_text(encoding="utf-8")
    assert "planned (dry run)" not in plain  # no plan, no legend for it
