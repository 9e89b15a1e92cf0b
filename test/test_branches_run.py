"""Outcome branches at run time (issue 24 item 2): a hole vision does not find takes the not_found
branch -- left out, reported, its rivet put back -- and the run ends FINISHED; kill -9 in the second
iteration, then --resume: every function done once, the branches taken before the crash taken again."""
from __future__ import annotations

import io
import json
import re
from collections import Counter
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from cell_runner.cli import main
from execution_engine.app_model import load_application
from execution_engine.checkpoint.resume import sits_out
from execution_engine.timeline import build_timeline
from test_resume_loops import records, start_and_kill  # the kill -9 in the second iteration, as there

ROOT = Path(__file__).resolve().parent.parent
BRANCH = ROOT / "apps_xml" / "rivet_loop_branch.xml"
MISSING = ROOT / "apps_xml" / "examples" / "cells" / "rivet_cell_hole_missing.xml"


def application_in(folder: Path, missing: str) -> Path:
    """The branch demonstrator on the test cell, with ``missing`` the hole that is not drilled."""
    cell = MISSING.read_text().replace('diameter="0.0048" drilled="false">', 'diameter="0.0048">')
    cell = cell.replace(f'<frame name="{missing}" xyz=', f'<frame name="{missing}" drilled="false" xyz=')
    assert len(re.findall(r'<frame [^>]*drilled="false"', cell)) == 1
    (folder / "cell.xml").write_text(cell)
    app = folder / "app.xml"
    app.write_text(BRANCH.read_text().replace('cell="cells/rivet_cell.xml"', 'cell="cell.xml"'))
    return app


def outcomes_error(lines: list[dict[str, Any]]) -> str:
    """The error a not_found outcome ended its function with, as the trace has it."""
    message = next(r["message"] for r in lines if r["event"] == "outcome" and r["outcome"] == "not_found")
    return str(message).split(": ", 1)[1]


def done_functions(trace: list[dict[str, Any]]) -> Counter[tuple[str, str]]:
    """(operation, group) of every function that completed: succeeded, or ended with a named outcome."""
    done = Counter((r["operation"], r["group"]) for r in trace if r["event"] == "function_end" and r["outcome"] == "succeeded")
    done.update((r["operation"], r["group"]) for r in trace if r["event"] == "outcome" and r["outcome"] != "found")
    return done


def test_a_hole_vision_does_not_find_takes_the_not_found_branch_and_the_run_finishes_reporting_it(tmp_path: Path) -> None:
    """As a user runs it: checked first by the default dry run, whose pass assuming drill_3 found meets the cell
    without it (a note, not a finding), then run to FINISHED on the not_found side."""
    app = BRANCH.parent / "rivet_loop_branch.xml"
    run_app = tmp_path / "app.xml"
    run_app.write_text(app.read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{MISSING}"'))
    out, err = io.StringIO(), io.StringIO()
    trace = tmp_path / "run.jsonl"
    code = main(["run", str(run_app), "--speed", "max", "--trace", str(trace)], out, err)
    assert code == 0, err.getvalue()
    text = out.getvalue()
    assert "dry run of rivet_loop_branch on nextage-sim: no problems found; operations checked 22/22" in text
    assert ("  assumed against the simulated cell: look_drill_3 left_arm assumed found where the simulated cell ended it not_found (drill_3: no hole"
            in text), text
    assert ("on that side, the vision of drill_3 by debur_drill_3 left_arm debur_drilling, insert_drill_3 right_arm insert_rivet not checked, "
            "their motions checked at drill_3's nominal pose") in text
    assert "application rivet_loop_branch: FINISHED" in text
    assert "  outcome: left_arm operation look_drill_3 (for_each hole=drill_3): not_found" in text
    assert "  outcome: left_arm operation look_drill_1 (for_each hole=drill_1): found" in text
    assert "left out by their branch: 5 operation(s): put_back_drill_1, put_back_drill_2, debur_drill_3, insert_drill_3, put_back_drill_4" in text
    lines = records(trace)
    ended = {(r["operation"], r["function"]) for r in lines if r["event"] == "function_end" and r["outcome"] == "succeeded"}
    assert ("put_back_drill_3", "place") in ended and ("insert_drill_3", "insert_rivet") not in {(o, f) for o, f in ended}
    assert {r["operation"] for r in lines if r["event"] == "function_end" and r.get("function") == "insert_rivet"} == {
        "insert_drill_1", "insert_drill_2", "insert_drill_4"}
    outcomes = [(r["operation"], r["outcome"]) for r in lines if r["event"] == "outcome"]
    assert outcomes == [("look_drill_1", "found"), ("look_drill_2", "found"), ("look_drill_3", "not_found"), ("look_drill_4", "found")]
    assert "no hole of 4.80 mm" in next(r["message"] for r in lines if r["event"] == "outcome" and r["outcome"] == "not_found")
    marks = [(m.kind, m.group, m.text) for m in build_timeline(lines).marks if m.kind in ("outcome", "branch")]
    assert ("outcome", "left_arm", f"left_arm locate ended not_found: {outcomes_error(lines)}") in marks  # on the left arm's row
    assert [m for m in marks if m[0] == "branch"][2] == (
        "branch", "engine", "debur_drill_3 left out: left_arm look_drill_3 ended not_found; it runs when left_arm look_drill_3 == found")
    # the report of the trace says the same
    out = io.StringIO()
    assert main(["report", str(trace)], out, io.StringIO()) == 0
    assert "  outcome: left_arm locate ended not_found: " in out.getvalue()
    assert "  branch: debur_drill_3 left out: left_arm look_drill_3 ended not_found; it runs when left_arm look_drill_3 == found" in out.getvalue()


def test_in_flags_mode_too_the_not_found_branch_is_taken_and_the_run_finishes(tmp_path: Path) -> None:
    run_app = tmp_path / "app.xml"
    run_app.write_text(BRANCH.read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{MISSING}" sync="flags"'))
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(run_app), "--speed", "max", "--trace", str(tmp_path / "run.jsonl")], out, err)  # checked first, as a user runs it
    assert code == 0, err.getvalue()
    text = out.getvalue()
    assert "dry run of rivet_loop_branch on nextage-sim: no problems found; operations checked 22/22" in text
    assert "application rivet_loop_branch: FINISHED" in text and "zone 'hands_left'" in text  # each group on its own, meeting at zones
    assert "  outcome: left_arm operation look_drill_3 (for_each hole=drill_3): not_found" in text
    assert "left out by their branch: 5 operation(s): put_back_drill_1, put_back_drill_2, debur_drill_3, insert_drill_3, put_back_drill_4" in text
    lines = records(tmp_path / "run.jsonl")
    placed = [r["operation"] for r in lines if r["event"] == "function_end" and r.get("function") == "place" and r["outcome"] == "succeeded"]
    assert placed == ["put_back_drill_3"]  # the right arm waited for the left arm's look before choosing


def test_where_no_if_tests_it_a_hole_not_found_stays_an_error_under_the_policy(tmp_path: Path) -> None:
    run_app = tmp_path / "app.xml"
    run_app.write_text((ROOT / "apps_xml" / "rivet_loop.xml").read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{MISSING}"'))
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", str(run_app), "--speed", "max", "--no-check"], out, err) != 0
    assert "FAILED - left_arm: debur_drilling failed: vision(locate drill_3)" in out.getvalue()


def test_kill_in_the_second_iteration_then_resume_takes_the_same_branches_and_does_every_function_once(tmp_path: Path) -> None:
    app = application_in(tmp_path, "drill_1")  # not found in the first iteration, before the kill
    catalog = full_catalog()
    application = load_application(app, catalog)
    first = records(start_and_kill(app, tmp_path, 2))
    assert ("look_drill_1", "not_found") in {(r["operation"], r["outcome"]) for r in first if r["event"] == "outcome"}
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "--no-check", "--resume", str(tmp_path / "run.sqlite"),
                 "--on-interrupted", "redo", "--trace", str(tmp_path / "resumed.jsonl")], out, err)
    assert code == 0, err.getvalue()
    assert "outcome: left_arm operation look_drill_1 (for_each hole=drill_1): not_found" in out.getvalue()  # kept from before the crash
    second = records(tmp_path / "resumed.jsonl")
    assert second[-1]["event"] == "run_end" and second[-1]["outcome"] == "finished"
    assert not [r for r in second if r.get("iteration", "").startswith("for_each hole=drill_1")], "nothing of the first iteration again"
    done = done_functions(first + second)
    taken = {(op.id, g) for op in application.operations for g, call in op.calls.items() if not sits_out(application, catalog, call)}
    expected = {(o, g) for o, g in taken if o not in ("debur_drill_1", "insert_drill_1", "put_back_drill_2", "put_back_drill_3", "put_back_drill_4")}
    assert set(done) == expected and set(done.values()) == {1}, "every function of the branches taken done exactly once across the two runs"


def test_the_catalog_lists_each_functions_outcomes() -> None:
    out = io.StringIO()
    assert main(["functions", "--json"], out, io.StringIO()) == 0
    functions = {f["name"]: f for f in json.loads(out.getvalue())["functions"]}
    names = {name: [o["name"] for o in f.get("outcomes", [])] for name, f in functions.items()}
    assert names["locate"] == names["debur_drilling"] == names["insert_rivet"] == ["found", "not_found"]
    assert names["check_diameter"] == ["in_range", "out_of_range", "not_found"] and names["move_to"] == []
    assert [o.get("on_fault") for o in functions["check_diameter"]["outcomes"]] == [None, "out_of_range", "vision"]
    out = io.StringIO()
    assert main(["functions"], out, io.StringIO()) == 0
    assert "      outcome out_of_range: the measured value lies outside the range given" in out.getvalue()


MEASURE = """<?xml version="1.0"?>
<application name="measure" robot="nextage" cell="{cell}">
  <operation id="over"><left_arm><function name="approach"><params><param value="drill_1"/><param value="0.05"/></params></function></left_arm></operation>
  <operation id="size_{n}"><left_arm><function name="check_diameter"><params><param value="drill_1"/><param value="{low}"/><param value="{high}"/></params></function></left_arm></operation>
  <if group="left_arm" operation="size_{n}" outcome="out_of_range">
    <operation id="reject"><right_arm><function name="gripper_open"/></right_arm></operation>
  </if>
  <else>
    <operation id="accept"><right_arm><function name="gripper_close"/></right_arm></operation>
  </else>
</application>
"""


def test_a_measured_diameter_chooses_between_in_range_and_out_of_range(tmp_path: Path) -> None:
    """drill_1 is drilled 4.8 mm: within 4.6-5.0 mm it is in_range, against 5.0-5.2 mm out_of_range, with what was measured."""
    for n, (low, high, taken, left) in enumerate((("0.0046", "0.0050", "accept", "reject"), ("0.0050", "0.0052", "reject", "accept"))):
        app = tmp_path / f"measure_{n}.xml"
        app.write_text(MEASURE.format(cell=ROOT / "apps_xml" / "cells" / "rivet_cell.xml", n=n, low=low, high=high))
        out, err = io.StringIO(), io.StringIO()
        assert main(["run", str(app), "--speed", "max", "--no-check", "--trace", str(tmp_path / f"m{n}.jsonl")], out, err) == 0, err.getvalue()
        assert "application measure: FINISHED" in out.getvalue() and f"left out by their branch: 1 operation(s): {left}" in out.getvalue()
        lines = records(tmp_path / f"m{n}.jsonl")
        assert taken in {r["operation"] for r in lines if r["event"] == "function_end" and r["outcome"] == "succeeded"}
        outcome = next(r for r in lines if r["event"] == "outcome")
        if n == 0:
            assert outcome["outcome"] == "in_range"
        else:
            assert outcome["outcome"] == "out_of_range"
            measured = re.search(r"drill_1: diameter (\d\.\d{3}) mm, outside 5 to 5\.2 mm", out.getvalue())
            assert measured is not None and 4.6 < float(measured.group(1)) < 5.0, out.getvalue()


def test_a_hand_left_full_on_one_side_of_an_if_is_refused_where_it_must_be_empty(tmp_path: Path) -> None:
    """The hand-holding check follows both sides of every <if>: a not_found side that keeps the rivet (a move
    instead of the put-back) leaves the right hand full for the next hole's pick -- refused there, naming the side."""
    put_back = '<right_arm><function name="place"><params><param value="rivet_{index}"/></params></function></right_arm>'
    app = tmp_path / "keep.xml"
    app.write_text(BRANCH.read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{ROOT / "apps_xml" / "cells" / "rivet_cell.xml"}"')
                   .replace(put_back, put_back.replace('"place"', '"move_to"')))
    out, err = io.StringIO(), io.StringIO()
    assert main(["validate", str(app)], out, err) == 1
    lines = [line for line in out.getvalue().splitlines() + err.getvalue().splitlines() if "pick_rivet needs" in line]
    assert len(lines) == 3 and lines[0].startswith(f"{app}:29:18: pick_rivet needs the right_arm's hand to be empty, but it still holds what "
                                                   "pick_rivet took in operation over_drill_1 (line 29) (on the side of the <if> where "
                                                   "left_arm look_drill_1 != found) (in for_each hole=drill_2)"), err.getvalue()
    out = io.StringIO()
    assert main(["validate", str(BRANCH)], out, io.StringIO()) == 0, out.getvalue()  # both sides leave the hand empty
