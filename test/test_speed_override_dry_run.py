"""A run that starts below 100 % (run --speed-override, the studio's value for its next run): the dry run plans every
motion at that share of its speed, so its predicted cycle time and the page's planned bars are the ones the robot will
keep; the run starts the engine and the back end at it; a kept verdict of another override is not taken for it."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main as cli_main
from cell_runner.dry_run.runner import dry_run
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.verdict_cache import verdict_key
from execution_engine.app_model import load_application
from robot_bridges.backend import BackendOptions

ROOT = Path(__file__).resolve().parents[1]
INITIAL = [math.radians(v) for v in (0.6, 0.0, -100.0, -15.2, 9.4, -3.2)]


def write_app(folder: Path) -> Path:
    def move(first: float) -> str:
        values = ",".join(f"{v:.6f}" for v in [first, *INITIAL[1:]])
        return f"<left_arm><function name='move_joints'><params><param value='{values}'/></params></function></left_arm>"

    shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
    path = folder / "moves.xml"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<application name="moves" robot="nextage" cell="cells/rivet_cell.xml">
  <operation id="1">{move(-0.8)}</operation>
  <operation id="2">{move(0.8)}</operation>
</application>
""", encoding="utf-8")
    return path


def test_the_dry_run_plans_at_the_override_and_a_kept_verdict_is_keyed_by_it(tmp_path: Path) -> None:
    app = load_application(write_app(tmp_path), full_catalog())
    full = dry_run(app, "nextage-sim", BackendOptions(app.robot))
    half = dry_run(app, "nextage-sim", BackendOptions(app.robot, speed_override=0.5))
    assert full.ok and half.ok
    assert full.cycle_time == pytest.approx(0.81 + 2 / 3 + 1.6 + 2 / 3, abs=0.01)  # LARM_JOINT0 at 1 rad/s, 1.5 rad/s^2
    assert half.cycle_time == pytest.approx(2.0 * full.cycle_time, rel=0.02)  # every motion at half its speed, on its path
    keys = {verdict_key(app, setup_for("nextage-sim", BackendOptions(app.robot, speed_override=r)), None) for r in (1.0, 0.5)}
    assert len(keys) == 2


def test_run_starts_at_the_override_it_is_given(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_app(tmp_path)
    trace = tmp_path / "half.jsonl"
    code = cli_main(["run", str(path), "--speed", "max", "--speed-override", "50", "--trace", str(trace), "--quiet"])
    assert code == 0, capsys.readouterr()
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    ends = [r for r in records if r.get("event") == "function_end"]
    starts = [r for r in records if r.get("event") == "function_start"]
    assert ends[-1]["t"] - starts[-1]["t"] == pytest.approx(2 * (1.6 + 2 / 3), abs=0.1)  # the second move at 50 %
