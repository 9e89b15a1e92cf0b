"""A breakpoint in the file, in the trace, the MCAP recording and ``report`` of either, from the command line.

The dry run before the run checks every operation and pauses at none (it would wait for nobody).

``run`` without ``--interactive`` has nobody who could continue a paused run: the breakpoint is passed and
said so (the run does not hang), and that pause that was not is recorded like any other -- a ``breakpoint``
line of the trace, an EngineEvent of the recording -- and ``report`` names it from either record.
"""
from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

from cell_runner.run_report import summarize
from operator_station.program import main

ROOT = Path(__file__).resolve().parents[1]


def test_run_passes_a_breakpoint_it_cannot_hold_and_every_record_says_so(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    app = tmp_path / "app.xml"
    text = (ROOT / "apps_xml" / "rivet_installation.xml").read_text(encoding="utf-8")
    app.write_text(text.replace("<operation id='3' name='insert 1'>", "<operation id='3' name='insert 1' break='true'>", 1), encoding="utf-8")
    assert "break='true'" in app.read_text(encoding="utf-8")
    trace, record = tmp_path / "run.jsonl", tmp_path / "run.mcap"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "--trace", str(trace), "--record", str(record)], out=out, err=err)  # the dry run first
    assert code == 0, err.getvalue()
    said = "breakpoint before operation 3 '3' (line "
    (hit,) = [r for r in map(json.loads, trace.read_text(encoding="utf-8").splitlines()) if r["event"] == "breakpoint"]
    assert (hit["operation"], hit["kind"], hit["held"]) == ("3", "break", False) and hit["message"].startswith(said)
    assert "passed: nobody can continue a paused run here (run --interactive at a terminal" in hit["message"]
    assert any(said in line and "breakpoint at " in line for line in out.getvalue().splitlines())  # the run's summary
    for source in (trace, record):
        lines = summarize(source).lines()
        assert [line for line in lines if line.startswith("  breakpoint: ") and said in line], (source, lines)
