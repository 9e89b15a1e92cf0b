"""``launch --speed F``: the simulator is the cell's clock, and the machines and the engine follow it.

One process per node: at another speed than real time only the simulator's bridge is paced, so the
others take their time from its ``/clock`` (``use_sim_time``), and the bridge holds that time while
a group's next step is on its way from another process (robot_bridges/turnaround.py).  The engine's
cycle time is then the dry run's, not wall seconds (12.8 s for an 88.77 s cycle) nor the turnarounds
counted ten times over (93.0 s).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from dds_domain import stop_group

from app_functions.registry import full_catalog
from cell_runner.dry_run.runner import dry_run
from cell_runner.launcher import cell_nodes
from execution_engine.app_model import load_application
from robot_bridges.backend import BackendOptions

ROOT = Path(__file__).resolve().parent.parent
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
KUKA = ROOT / "apps_xml" / "kuka_rsi_demo.xml"


def _follows(argv: tuple[str, ...]) -> bool:
    return "use_sim_time:=true" in argv


def test_at_another_speed_the_machines_and_the_engine_follow_the_simulators_clock() -> None:
    bridge, *machines, engine = cell_nodes(RIVET, "dds", 10.0)
    assert "speed:=10.0" in bridge.argv and not _follows(bridge.argv)  # the bridge is the clock
    assert all(_follows(node.argv) for node in (*machines, engine))
    assert not any(_follows(node.argv) for node in cell_nodes(RIVET, "dds", 1.0))  # real time: wall clocks


def test_a_bridge_on_the_controllers_clock_refuses_another_speed() -> None:
    with pytest.raises(ValueError, match=r"^--speed 2: the kuka-rsi bridge runs in real time, on the controller's clock; only nextage-sim"):
        cell_nodes(KUKA, "dds", 2.0)


def _application(path: Path) -> Path:
    """Thirteen operations of both arms, the left one longer: each turnaround of a group is on the cycle."""
    left = ("0.30,0.06,0.08,180deg,0,90deg", "0.38,0.10,0.05,180deg,0,90deg")
    ops = ["    <left_arm><function name=\"set_speed\"><params><param value=\"0.3\"/></params></function></left_arm>\n"
           "    <right_arm><function name=\"set_speed\"><params><param value=\"0.3\"/></params></function></right_arm>\n"]
    for index in range(2, 14):
        dz = 0.02 if index % 2 else -0.02
        ops.append(
            f"    <left_arm><function name=\"move_to\"><params><param value=\"{left[index % 2]}\"/></params></function></left_arm>\n"
            f"    <right_arm><function name=\"move_relative\"><params><param value=\"0\"/><param value=\"0\"/><param value=\"{dz}\"/>"
            "</params></function></right_arm>\n"
        )
    body = "".join(f"  <operation id=\"{i}\">\n{op}  </operation>\n" for i, op in enumerate(ops, start=1))
    path.write_text(f"<?xml version=\"1.0\"?>\n<application name=\"paced\" robot=\"nextage\">\n{body}</application>\n")
    return path


def test_launch_over_dds_at_ten_times_real_time_reports_the_dry_runs_cycle_time(tmp_path: Path, dds_env: dict[str, str]) -> None:
    """The five processes on loopback DDS: the engine's total is the dry run's prediction within 1 %
    (the report rounds to the simulator's /clock ticks, 0.1 s at x10)."""
    app_file = _application(tmp_path / "paced.xml")
    app = load_application(app_file, full_catalog())
    predicted = dry_run(app, "nextage-sim", BackendOptions(robot=app.robot)).cycle_time
    assert predicted > 30.0  # long enough for 1 % to be more than a tick
    env = {**os.environ, **dds_env, "XDG_DATA_HOME": str(tmp_path / "data")}
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "launch", str(app_file), "--transport", "dds", "--speed", "10"],
        cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True,
    )
    try:
        out, _ = process.communicate(timeout=180)
    finally:
        stop_group(process)
    assert process.returncode == 0, out
    assert "[execution_engine] application paced: FINISHED" in out and "retry" not in out
    total = float(re.search(r"\[execution_engine\]\s+total\s+([\d.]+) s", out).group(1))  # type: ignore[union-attr]
    assert total == pytest.approx(predicted, rel=0.01), out
