"""``python -m execution_engine``: validate, functions, and run's refusals (runs on the simulator: test_rivet_app.py)."""
from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main

ROOT = Path(__file__).resolve().parents[1]
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
DIAGNOSTIC = re.compile(r"^(?P<file>.+):(?P<line>\d+):(?P<col>\d+): (?P<message>.+)$")


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out, err)
    return code, out.getvalue(), err.getvalue()


def write_app(tmp_path: Path, body: str, name: str = "app.xml", cell: bool = True) -> Path:
    cell_attr = f' cell="{ROOT / "apps_xml" / "cells" / "rivet_cell.xml"}"' if cell else ""
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<application name="t" robot="nextage"{cell_attr}>\n{body}</application>\n')
    return path


def op(group: str, function: str, *params: str, op_id: str = "1") -> str:
    inner = "".join(f"<param value='{p}'/>" for p in params)
    return f"  <operation id='{op_id}'>\n    <{group}><function name='{function}'><params>{inner}</params></function></{group}>\n  </operation>\n"


def test_functions_json_is_a_complete_catalog() -> None:
    code, out, _ = cli("functions", "--json")
    assert code == 0
    document = json.loads(out)
    names = {f["name"] for f in document["functions"]}
    assert names == set(full_catalog().names())
    pick = next(f for f in document["functions"] if f["name"] == "pick_rivet")
    assert [p["name"] for p in pick["params"]] == ["rivet", "reference"]
    assert pick["params"][0]["type"] == "frame" and pick["params"][0]["kinds"] == ["rivet_slot"]
    assert set(document["param_types"]) >= {"number", "frame", "joints", "target", "joint_pose"}
    nextage = document["robots"]["nextage_open"]
    assert nextage["groups"]["left_arm"]["joints"][0] == {"name": "LARM_JOINT0", "min_deg": -88.0, "max_deg": 88.0}
    assert nextage["joint_order"][:3] == ["CHEST_JOINT0", "HEAD_JOINT0", "HEAD_JOINT1"]
    assert nextage["joint_poses_deg"]["initial"][3:6] == [-0.6, 0.0, -100.0]
    assert "left_hand_camera" in nextage["cameras"] and "WAIST" in nextage["workspace"]
    target = next(p for f in document["functions"] if f["name"] == "move_to" for p in f["params"] if p["name"] == "target")
    assert {"mm", "deg"} <= set(target["unit_suffixes"])
    assert "<operation" in document["xml_usage"]


def test_functions_text_documents_every_function_and_param() -> None:
    code, out, _ = cli("functions")
    assert code == 0
    for spec in full_catalog().functions.values():
        assert spec.signature() in out
        for param in spec.params:
            assert f"- {param.name}: {param.doc}" in out


def test_the_demonstrator_validates() -> None:
    code, out, err = cli("validate", str(RIVET))
    assert (code, err) == (0, "")
    assert out.strip().endswith("valid")


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (op("left_arm", "debur_drill", "drill_1"), "unknown function 'debur_drill'"),
        (op("left_arm", "pick_rivet", "rivet_1"), "takes 2 params, got 1"),
        (op("left_hand", "gripper_open"), "left_hand"),
        (op("left_arm", "debur_drilling", "drill_9"), "unknown frame 'drill_9'"),
        (op("left_arm", "set_speed", "fast"), "'fast' is not a number"),
        ("  <operation id='1'>\n    <left_arm><function name='wait'></left_arm>\n  </operation>\n", ""),
    ],
    ids=["unknown-function", "param-count", "unknown-group", "unknown-frame", "param-type", "syntax"],
)
def test_invalid_applications_give_located_messages_and_exit_1(tmp_path: Path, body: str, message: str) -> None:
    path = write_app(tmp_path, body)
    code, out, err = cli("validate", str(path))
    assert code == 1 and out == ""
    lines = [line for line in err.splitlines() if DIAGNOSTIC.match(line)]
    assert lines, err
    first = DIAGNOSTIC.match(lines[0])
    assert first is not None and Path(first["file"]) == path and int(first["line"]) >= 3 and int(first["col"]) >= 1
    assert message in err


def test_entity_expansion_is_refused_without_expanding(tmp_path: Path) -> None:
    path = tmp_path / "bomb.xml"
    entities = '<!ENTITY a "aaaaaaaaaa">' + "".join(f'<!ENTITY {chr(98 + i)} "&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};&{chr(97 + i)};">' for i in range(8))
    path.write_text(f'<?xml version="1.0"?>\n<!DOCTYPE application [{entities}]>\n<application name="&i;" robot="nextage"></application>\n')
    code, _, err = cli("validate", str(path))
    assert code == 1
    assert DIAGNOSTIC.match(err.splitlines()[0]) and len(err) < 2000


def test_every_problem_is_reported_at_once(tmp_path: Path) -> None:
    body = op("left_arm", "debur_drill", "drill_1", op_id="1") + op("right_arm", "pick_rivet", "rivet_1", op_id="2") + op("torso_head", "move_to", "drill_9", op_id="3")
    code, _, err = cli("validate", str(write_app(tmp_path, body)))
    assert code == 1
    located = [DIAGNOSTIC.match(line) for line in err.splitlines()]
    lines = sorted({int(m["line"]) for m in located if m})
    assert len(lines) >= 3


def test_run_refuses_an_invalid_application_and_starts_nothing(tmp_path: Path) -> None:
    code, out, err = cli("run", str(write_app(tmp_path, op("left_arm", "debur_drilling", "drill_9"))), "--speed", "max")
    assert code == 1
    assert "unknown frame 'drill_9'" in err and "not run" in err
    assert "RUNNING" not in out and out == ""


@pytest.mark.parametrize("argv", [["run", str(RIVET), "--speed", "0"], ["run", str(RIVET), "--speed", "fast"], ["run", str(RIVET), "--robot", "abb"], ["run", str(RIVET), "--backend-option", "novalue"], ["frobnicate"]])
def test_bad_command_lines_exit_2(argv: list[str]) -> None:
    code, _, _ = cli(*argv)
    assert code == 2


def test_run_of_a_missing_file_exits_1(tmp_path: Path) -> None:
    code, _, err = cli("run", str(tmp_path / "nope.xml"))
    assert code == 1 and "no such file" in err


def test_python_dash_m_entry_point() -> None:
    result = subprocess.run([sys.executable, "-m", "execution_engine", "validate", str(RIVET)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0 and "valid" in result.stdout
