"""apps_xml/examples/side_by_side.xml end to end: a KUKA KR 6 over RSI (its simulated KR C4) and a Viper on the V+
simulator, both models calling their arm 'arm', in one cell that names them kuka_arm and inspector.

The dry run of the whole cell finds no problem (both robots placed in the cell's world frame, one collision model
under the cell's joint names); the run, one bridge per robot, ends FINISHED with the hand-over ordered across the
robots by the flag and the zone, every record naming the cell's groups.  A cell with a KUKA over RSI runs in real
time (RSI keeps the robot's clock; --speed max is refused for it): these are the slow tests of the feature.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import sys
from pathlib import Path

from dds_domain import run_group
from lxml import etree

from cell_runner.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "apps_xml" / "examples" / "side_by_side.xml"


def test_the_side_by_side_example_passes_its_dry_run() -> None:
    out, err = io.StringIO(), io.StringIO()
    code = main(["validate", "--simulate", str(EXAMPLE)], out, err)
    assert code == 0, out.getvalue() + err.getvalue()
    assert "dry run of side_by_side on cell: no problems found; operations checked 8/8" in err.getvalue() + out.getvalue()


def test_the_side_by_side_example_runs_to_finished_and_hands_the_part_over_by_the_cell_s_group_names(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(EXAMPLE), "-q", "--trace", str(trace), "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 0, out.getvalue() + err.getvalue()
    assert "application side_by_side: FINISHED" in out.getvalue()
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines() if line.strip()]
    assert {r["group"] for r in records if "group" in r} - {"engine"} == {"kuka_arm", "inspector"}

    def flag(group: str, name: str, state: str) -> float:
        return next(float(r["t"]) for r in records if r.get("event") == "flag" and r.get("group") == group
                    and r.get("flag") == name and r.get("state") == state)

    def start(group: str, operation: str) -> float:
        return next(float(r["t"]) for r in records if r.get("event") == "function_start" and r.get("group") == group and r.get("operation") == operation)

    assert flag("inspector", "part_ready", "waiting") < flag("kuka_arm", "part_ready", "set") <= flag("inspector", "part_ready", "passed")
    assert flag("inspector", "part_ready", "passed") <= start("inspector", "6")  # the Viper takes the part only once it is there
    assert flag("kuka_arm", "handover", "left") <= flag("inspector", "handover", "passed")  # one hand at a time above the buffer
    motions = [r["result"] for r in records if r.get("event") == "primitive_end" and r.get("result", {}).get("joint_names")]
    assert motions and all(all(n.startswith(("kuka_", "viper_")) for n in m["joint_names"]) for m in motions)


def without_the_picks(folder: Path) -> Path:
    """The example without its picks and places (operations 2, 3, 6, 7), its cell beside it: each robot still moves
    under the cell's names and the flag still crosses from one robot's process to the other's, in half the real time
    (the whole example runs in-process above and in the studio's test)."""
    shutil.copytree(EXAMPLE.parent / "cells", folder / "cells")
    root = etree.parse(str(EXAMPLE)).getroot()
    for operation in root.findall("operation"):
        if operation.get("id") in ("2", "3", "6", "7"):
            root.remove(operation)
    path = folder / "side_by_side.xml"
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return path


def test_launch_gives_each_process_the_cell_s_names_and_the_example_runs_to_finished_over_dds(tmp_path: Path, dds_env: dict[str, str]) -> None:
    """launch: each robot's bridge process serves its groups under the cell's names (parameter cell_names), each
    machine process drives its group by them, the engine checks the whole cell first: FINISHED over DDS."""
    env = {**os.environ, **dds_env, "XDG_DATA_HOME": str(tmp_path / "data")}
    app = without_the_picks(tmp_path)
    code, out = run_group([sys.executable, "-m", "execution_engine", "launch", str(app), "--transport", "dds"], ROOT, env, 240)
    assert code == 0, out
    assert "[execution_engine] application side_by_side: FINISHED" in out
    assert "serving checker: " in out and "for inspector" in out, out
    for node in ("loader_bridge", "checker_bridge", "kuka_arm_machine", "inspector_machine"):
        assert f"[launch] {node} stopped (exit code 0)" in out, out
