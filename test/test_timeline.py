"""The Fig. 12 timeline model: lanes, function bars with their primitives, operations, idle gaps."""
from __future__ import annotations

from typing import Any

from execution_engine.timeline import STATE_COLOURS, TimelineBuilder, build_timeline


def rec(t: float, event: str, group: str, **fields: Any) -> dict[str, Any]:
    return {"t": t, "event": event, "group": group, **fields}


RECORDS = [
    rec(0.0, "function_start", "left_arm", operation="1", function="debur_drilling"),
    rec(0.0, "primitive_start", "left_arm", operation="1", primitive="move", index=1, state="Motion"),
    rec(0.0, "function_start", "right_arm", operation="1", function="pick_rivet"),
    rec(0.0, "primitive_start", "right_arm", operation="1", primitive="gripper", index=1, state="EndEffector"),
    rec(0.5, "primitive_end", "right_arm", operation="1", primitive="gripper", index=1, outcome="done"),
    rec(0.5, "function_end", "right_arm", operation="1", function="pick_rivet", outcome="succeeded"),
    rec(2.0, "primitive_end", "left_arm", operation="1", primitive="move", index=1, outcome="done"),
    rec(2.0, "primitive_start", "left_arm", operation="1", primitive="vision", index=2, state="Vision"),
    rec(2.5, "primitive_end", "left_arm", operation="1", primitive="vision", index=2, outcome="done",
        result={"kind": "vision", "pose": {"x": 0.3}}),
    rec(2.5, "function_end", "left_arm", operation="1", function="debur_drilling", outcome="succeeded"),
    rec(2.5, "function_start", "right_arm", operation="2", function="insert_rivet"),
    rec(2.5, "primitive_start", "right_arm", operation="2", primitive="move", index=1, state="Motion"),
    rec(3.0, "error", "right_arm", operation="2", error="joint limit"),
    rec(3.0, "function_end", "right_arm", operation="2", function="insert_rivet", outcome="aborted"),
    {"t": 3.1, "event": "operator", "group": "engine", "command": "reset", "source": "key x", "accepted": True},
    rec(3.2, "function_start", "right_arm", operation="2", function="insert_rivet"),
    rec(3.2, "primitive_start", "right_arm", operation="2", primitive="move", index=1, state="Motion"),
]


def test_lanes_bars_primitives_and_idle_gaps() -> None:
    timeline = build_timeline(RECORDS, ["left_arm", "right_arm"])
    left, right = timeline.lanes["left_arm"], timeline.lanes["right_arm"]
    [debur] = left.bars
    assert (debur.operation, debur.t_start, debur.t_end, debur.outcome) == ("1", 0.0, 2.5, "succeeded")
    assert [(p.name, p.state, p.t_start, p.t_end) for p in debur.primitives] == [("move", "Motion", 0.0, 2.0), ("vision", "Vision", 2.0, 2.5)]
    assert debur.state == "Motion" and debur.colour == STATE_COLOURS["Motion"]  # where it spent most time
    assert [(g.t_start, g.t_end) for g in left.idle] == [(2.5, 3.2)]
    assert [(g.t_start, g.t_end) for g in right.idle] == [(0.5, 2.5), (3.0, 3.2)]
    assert right.busy == 0.5 + 0.5  # the open retry ends at the last record
    assert right.bars[1].state == "ErrorHandling" and right.bars[1].error == "joint limit"
    assert right.bars[2].attempt == 2 and right.bars[2].t_end is None and timeline.retries == 1
    assert [(o.id, o.t_start, o.t_end) for o in timeline.operations] == [("1", 0.0, 2.5), ("2", 2.5, 3.0)]
    assert [(m.kind, m.t) for m in timeline.marks] == [("error", 3.0), ("operator", 3.1)]


def test_a_live_view_sees_open_bars_grow_up_to_now() -> None:
    builder = TimelineBuilder(["left_arm"])
    builder.add_all(RECORDS[:2])
    early = builder.snapshot(now=1.0)
    assert early.lanes["left_arm"].busy == 1.0 and early.lanes["left_arm"].bars[0].primitives[0].t_end is None
    builder.add_all(RECORDS[2:10])
    assert builder.snapshot().lanes["left_arm"].bars[0].t_end == 2.5
