"""The seed's focus loop (focus_approach) on the live images of the Nextage's wrist camera.

The wrist camera is focused 61 mm away, on the point 50 mm out along the tool axis: the sharpest
image of a hole is taken with the TCP 50 mm above it.  Started 70 mm above, the loop steps
towards the hole while the sharpness of the image rises and steps back once it falls, and must
end within one increment of that position.
"""
from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main
from core_functions.geometry import Pose
from execution_engine.app_model import load_application

ROOT = Path(__file__).resolve().parents[1]

APP = """<?xml version="1.0" encoding="UTF-8"?>
<application name="focus" robot="nextage" cell="cells/rivet_cell.xml">
  <operation id="1" name="far above the hole">
    <left_arm><function name="approach"><params><param value="drill_2"/><param value="{start} mm"/></params></function></left_arm>
  </operation>
  <operation id="2" name="focus">
    <left_arm><function name="focus_approach"><params><param value="drill_2"/><param value="{step} mm"/><param value="50%"/></params></function></left_arm>
  </operation>
</application>
"""


def focus_run(tmp_path: Path, start: float, step: float) -> tuple[list[float], float]:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text((ROOT / "apps_xml" / "cells" / "rivet_cell.xml").read_text())
    app = tmp_path / "focus.xml"
    app.write_text(APP.format(start=start, step=step))
    trace = tmp_path / "trace.jsonl"
    out = io.StringIO()
    code = main(["run", str(app), "--speed", "max", "--trace", str(trace), "--trajectory-db", ":memory:"], out, out)
    assert code == 0, out.getvalue()
    events: list[dict[str, Any]] = [json.loads(line) for line in trace.read_text().splitlines()]
    ends = [e for e in events if e["event"] == "primitive_end" and e.get("result")]
    values = [e["result"]["value"] for e in ends if e["result"]["kind"] == "vision"]
    assert all(e["result"]["report"]["method"] == "sharpness" for e in ends if e["result"]["kind"] == "vision")
    last = [e["result"]["tcp"] for e in ends if e["result"]["kind"] == "motion" and e["result"].get("tcp")][-1]
    cell = load_application(app, full_catalog()).cell
    assert cell is not None
    tcp = Pose(last["x"], last["y"], last["z"], last["qx"], last["qy"], last["qz"], last["qw"])
    height = -cell.true_pose("drill_2").inverse().compose(tcp).z  # hole z points into the hole
    return values, height


@pytest.mark.parametrize(("start", "step"), [(70.0, 2.0), (66.0, 3.0)])
def test_the_focus_loop_ends_within_one_increment_of_the_sharpest_position(tmp_path: Path, start: float, step: float) -> None:
    values, height = focus_run(tmp_path, start, step)
    assert values[-1] < values[-2] and all(a < b for a, b in zip(values[:-2], values[1:-1]))  # rose, then fell once
    assert abs(height - 0.050) <= step / 1000 + 1e-6
