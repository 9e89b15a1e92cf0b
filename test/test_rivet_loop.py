"""The demonstrator as a loop (issue 24 item 5 and its must-shows): apps_xml/rivet_loop.xml (for_each over
the cell's holes) and apps_xml/rivet_blocks.xml (a library block called for each hole) run to FINISHED with
the same functions, the same primitives to the same joints and the same cycle time as the flat
apps_xml/rivet_installation.xml; a collision in the third iteration stops the run before anything moves."""
from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
from app_model_support import pos

from cell_runner.cli import main
from execution_engine.timeline import build_timeline

ROOT = Path(__file__).resolve().parents[1]
APPS = ROOT / "apps_xml"


def run(app: Path, folder: Path, *extra: str) -> tuple[int, str, list[dict[str, Any]]]:
    trace = folder / f"{app.stem}.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "--trace", str(trace), "--trajectory-db", str(folder / "t.sqlite"), *extra], out, err)
    events = [json.loads(line) for line in trace.read_text().splitlines()] if trace.exists() else []
    return code, out.getvalue() + err.getvalue(), events


def motions(events: list[dict[str, Any]]) -> dict[str, list[tuple[str, str, Any]]]:
    """Per group, every primitive in order: its function, what it was, and what the robot reported at its end."""
    out: dict[str, list[tuple[str, str, Any]]] = {}
    for record in events:
        if record["event"] == "primitive_end":
            out.setdefault(record["group"], []).append((record.get("function", ""), record["primitive"], record.get("result")))
    return out


@pytest.fixture(scope="module")
def flat(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, str, list[dict[str, Any]]]:
    return run(APPS / "rivet_installation.xml", tmp_path_factory.mktemp("flat"))


@pytest.mark.parametrize("name", ["rivet_loop.xml", "rivet_blocks.xml"])
def test_the_looped_demonstrator_makes_the_same_motions_in_the_same_time(flat: tuple[int, str, list[dict[str, Any]]], tmp_path: Path, name: str) -> None:
    code, output, events = run(APPS / name, tmp_path)
    flat_code, flat_output, flat_events = flat
    assert code == flat_code == 0, output
    assert "FINISHED" in output and "operations: 10/10" in output
    looped, written = motions(events), motions(flat_events)
    assert looped == written and sum(map(len, looped.values())) > 100  # the same primitives, reaching the same joints and poses
    ends = [e for e in events if e["event"] == "run_end"], [e for e in flat_events if e["event"] == "run_end"]
    assert ends[0][0]["t"] == ends[1][0]["t"] and ends[0][0]["outcome"] == "finished"  # the same cycle time
    total = [line for line in output.splitlines() if line.strip().startswith("total")]
    assert total and total == [line for line in flat_output.splitlines() if line.strip().startswith("total")]
    starts = [(e["operation"], e.get("iteration", "")) for e in events if e["event"] == "function_start" and e["group"] == "right_arm"]
    assert ("insert_drill_3", next(i for o, i in starts if o == "insert_drill_3")) in starts
    assert all(i.startswith(f"for_each hole={o.split('_', 1)[1]}") for o, i in starts if o not in ("prepare", "home"))
    spans = {span.id: span.iteration for span in build_timeline(events).operations}  # the timeline (Fig. 12) carries it too
    assert spans["prepare"] == "" and spans["insert_drill_3"].startswith("for_each hole=drill_3")


def test_a_collision_in_the_third_iteration_is_reported_before_anything_moves(tmp_path: Path) -> None:
    """Both hands go to y = +t and -t over the part: 10 and 6 cm apart are free, the third value meets."""
    text = ('<?xml version="1.0"?>\n<application name="closing_in" robot="nextage">\n'
            '  <for_each var="t" in="0.10 0.06 0.0">\n    <operation id="reach_{index}">\n'
            '      <left_arm><function name="move_to"><params><param value="0.34,{t},0.10,180deg,0,90deg"/></params></function></left_arm>\n'
            '      <right_arm><function name="move_to"><params><param value="0.34,-{t},0.10,180deg,0,90deg"/></params></function></right_arm>\n'
            '    </operation>\n  </for_each>\n</application>\n')
    app = tmp_path / "closing_in.xml"
    app.write_text(text)
    code, output, events = run(app, tmp_path)
    assert code == 1 and not [e for e in events if e["event"] == "function_start"]
    left, right = pos(text, "<left_arm><function"), pos(text, "<right_arm><function")
    lines = [line for line in output.splitlines() if ": collision: " in line]
    assert len(lines) == 2
    assert lines[0].startswith(f"{app}:{left[0]}:") and "operation reach_3 (for_each t=0.0) left_arm move_to: collision: collision between" in lines[0]
    assert lines[1].startswith(f"{app}:{right[0]}:") and "operation reach_3 (for_each t=0.0) right_arm move_to: collision: " in lines[1]
    assert f"{app}: not run: 2 problem(s) found by the dry run; use --no-check to run anyway" in output


def test_a_failure_in_a_loop_is_reported_with_its_iteration(tmp_path: Path) -> None:
    code, output, events = run(APPS / "rivet_loop.xml", tmp_path, "--no-check", "--fault", "right_arm:unreachable@0.5")
    assert code == 1 and "application rivet_loop: FAILED" in output
    errors = [line.strip() for line in output.splitlines() if line.strip().startswith("error: right_arm")]
    assert errors and errors[0].startswith("error: right_arm operation debur_drill_1 (for_each hole=drill_1) pick_rivet (attempt 1) at ")
    assert [e["iteration"] for e in events if e["event"] == "function_end" and e["outcome"] == "aborted"] == ["for_each hole=drill_1"]
