"""The asynchronous rivet demonstrator (apps_xml/rivet_async.xml, issue 15): every rivet in, no collision,
the arms kept apart at the part by the zone, and a shorter cycle than the lock-step demonstrator."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

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


def test_every_rivet_goes_in_after_its_hole_is_deburred(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    code, text, records = runs[ASYNC]
    assert code == 0, text
    ends = {(r["group"], r.get("function"), r.get("operation")): r for r in records if r["event"] == "function_end"}
    inserts = [r for (g, f, _), r in ends.items() if f == "insert_rivet"]
    assert len(inserts) == 4 and all(r["outcome"] == "succeeded" for r in inserts)
    flag_set = {r["flag"]: r["t"] for r in records if r["event"] == "flag" and r["state"] == "set"}
    starts = {r.get("operation"): r["t"] for r in records if r["event"] == "function_start" and r.get("function") == "insert_rivet"}
    for k, operation in zip(range(1, 5), ("4", "7", "10", "13")):
        assert starts[operation] >= flag_set[f"deburred_{k}"]


def test_the_arms_take_turns_at_the_part(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    _, _, records = runs[ASYNC]
    spans = {}
    for r in records:
        if r["event"] in ("function_start", "function_end") and r.get("function") in ("debur_drilling", "insert_rivet"):
            spans.setdefault((r["group"], r["operation"]), {})[r["event"]] = r["t"]
    at_part = sorted((s["function_start"], s["function_end"]) for s in spans.values())
    assert len(at_part) == 8
    assert all(a_end <= b_start + 1e-6 for (_, a_end), (b_start, _) in zip(at_part, at_part[1:]))  # never two at once
    assert any(r["event"] == "flag" and r.get("kind") == "zone" and r["state"] == "waiting" for r in records)


def test_no_collision_and_a_shorter_cycle_than_lock_step(runs: dict[str, tuple[int, str, list[dict]]]) -> None:
    code, out, err = cli("validate", "--simulate", ASYNC)
    assert code == 0, err
    assert "no problems found" in out and "collisions checked: 60 motions" in out
    assert "waits that cost most: zone 'at_part'" in out
    (code_a, text_a, _), (code_l, text_l, _) = runs[ASYNC], runs[LOCK]
    assert code_a == 0 and code_l == 0
    assert total(text_a) < total(text_l)
