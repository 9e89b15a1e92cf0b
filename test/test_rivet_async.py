"""The asynchronous rivet demonstrator (apps_xml/rivet_async.xml, issue 15): every rivet in, no collision,
the arms kept apart at the part by the zones where the hands would meet, the work shared, and a clearly
shorter cycle than the lock-step demonstrator."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from execution_engine.app_model import load_application
from execution_engine.timeline import build_timeline
from test_dry_run import cli

ASYNC, LOCK = "apps_xml/rivet_async.xml", "apps_xml/rivet_installation.xml"


def run(app: str, tmp: Path) -> tuple[int, str, list[dict]]:
    trace = tmp / (Path(app).stem + ".jsonl")
    code, out, err = cli("run", app, "--speed", "max", "--trace", str(trace))
    return code, out + err, [json.loads(line) for line in trace.read_text().splitlines()]


def total(text: str) -> float:
    return float(next(x for x in text.splitlines() if x.strip().startswith("total")).split()[1])


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[int, str, list[dict]]]:
    tmp = tmp_path_factory.mktemp("rivet_async")
    return {app: run(app, tmp) for app in (ASYNC, LOCK)}


def holes(app: str) -> dict[tuple[str, str], str]:
    """(operation, group) -> the hole of each debur_drilling / insert_rivet call."""
    loaded = load_application(Path(app), full_catalog())
    return {(op.id, g): c.params[0] for op in loaded.operations for g, c in op.calls.items() if c.function in ("debur_drilling", "insert_rivet")}


def test_every_rivet_goes_in_after_its_hole_is_deburred(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    code, text, records = runs[ASYNC]
    assert code == 0, text
    where = holes(ASYNC)
    ends = {(r["operation"], r["group"]): r for r in records if r["event"] == "function_end" and r.get("function") in ("debur_drilling", "insert_rivet")}
    deburred = {where[k]: r["t"] for k, r in ends.items() if r["function"] == "debur_drilling" and r["outcome"] == "succeeded"}
    inserts = {k: r for k, r in ends.items() if r["function"] == "insert_rivet"}
    assert sorted(where[k] for k in inserts) == ["drill_1", "drill_2", "drill_3", "drill_4"]
    assert all(r["outcome"] == "succeeded" for r in inserts.values())
    assert {g for _, g in inserts} == {"left_arm", "right_arm"}  # the work is shared
    for (operation, group) in inserts:
        first_move = min(r["t"] for r in records if r["event"] == "primitive_start" and r.get("operation") == operation and r.get("group") == group)
        assert first_move >= deburred[where[(operation, group)]]


def test_one_arm_at_a_time_where_the_hands_would_meet(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    """Each zone is held by one arm at a time (entered .. left); the left arm waits for one at
    least once, and the arms do work at the part at once, at holes 1 and 4."""
    _, _, records = runs[ASYNC]
    held: dict[str, list[tuple[float, float, str]]] = {}
    inside: dict[tuple[str, str], float] = {}
    for r in records:
        if r["event"] == "flag" and r.get("kind") == "zone" and r["state"] in ("passed", "left"):
            if r["state"] == "passed":
                inside[(r["flag"], r["group"])] = r["t"]
            else:
                held.setdefault(r["flag"], []).append((inside.pop((r["flag"], r["group"])), r["t"], r["group"]))
    assert set(held) == {"hands_left", "hands_right"} and not inside
    for spans in held.values():
        spans.sort()
        assert all(a_end <= b_start + 1e-6 for (_, a_end, _), (b_start, _, _) in zip(spans, spans[1:]))  # never two at once
    left = [(a, b) for a, b, g in held["hands_left"] if g == "left_arm"]
    right = [(a, b) for a, b, g in held["hands_right"] if g == "right_arm"]
    assert any(a < d and c < b for a, b in left for c, d in right)  # both arms at the part at once
    assert any(r["event"] == "flag" and r.get("kind") == "zone" and r["state"] == "waiting" for r in records)
    lane = build_timeline(records).lanes["left_arm"]  # the Fig. 12 timeline and `report`: the wait is idle, named
    waited = sum(g.duration for g in lane.idle if g.waiting == "zone hands_left")
    assert waited > 1.0 and lane.busy + sum(g.duration for g in lane.idle) == pytest.approx(records[-1]["t"] - records[0]["t"], abs=0.01)


def test_no_collision_and_a_clearly_shorter_cycle_than_lock_step(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    code, out, err = cli("validate", "--simulate", ASYNC)
    assert code == 0, err
    assert "no problems found" in out and "collisions checked: 60 motions" in out
    assert "waits that cost most: zone 'hands_left'" in out and "predicted cycle time" in out
    (code_a, text_a, _), (code_l, text_l, _) = runs[ASYNC], runs[LOCK]
    assert code_a == 0 and code_l == 0
    assert total(text_a) < 0.9 * total(text_l)
