"""The application model against the real function catalog and the shipped example files."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from execution_engine.app_model import load_application, load_cell, validate_application
from core_functions.resources import share_path

CATALOG = full_catalog()


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "cells").mkdir()
    shutil.copy(share_path("apps_xml", "cells", "rivet_cell.xml"), tmp_path / "cells" / "rivet_cell.xml")
    return tmp_path


def test_the_shipped_rivet_application_is_valid() -> None:
    path = share_path("apps_xml", "rivet_installation.xml")
    assert validate_application(path, CATALOG) == []
    application = load_application(path, CATALOG)
    assert application.robot.name == "nextage_open" and application.cell is not None
    functions = {call.function for op in application.operations for call in op.calls.values()}
    assert {"debur_drilling", "pick_rivet", "insert_rivet", "wait"} <= functions
    # The catalog's wait has an optional duration: implicit and explicit waits carry its default.
    waits = [c for op in application.operations for c in op.calls.values() if c.function == "wait"]
    assert waits and all(c.params == ("0",) for c in waits)


def test_the_shipped_cell_loads() -> None:
    cell = load_cell(share_path("apps_xml", "cells", "rivet_cell.xml"))
    assert cell.frame_kind("drill_1") == "hole" and cell.element_kind("ref_R10") == "rivet"
    assert cell.true_pose("drill_1") != cell.pose("drill_1")


def test_real_functions_are_checked(work: Path) -> None:
    text = """<?xml version="1.0" encoding="UTF-8"?>
<application name="t" robot="nextage" cell="cells/rivet_cell.xml">
  <operation id="1">
    <right_arm><function name="insert_rivet"><params><param value="drill_1"/></params></function></right_arm>
    <left_arm><function name="debur_driling"><params><param value="drill_1"/></params></function></left_arm>
  </operation>
  <operation id="2">
    <right_arm><function name="pick_rivet"><params><param value="drill_2"/><param value="ref_R10"/></params></function></right_arm>
    <torso_head><function name="move_to_joint_pose"><params><param value="look_at_part"/></params></function></torso_head>
    <left_arm><function name="move_to_joint_pose"><params><param value="look_at_part"/></params></function></left_arm>
  </operation>
</application>
"""
    path = work / "app.xml"
    path.write_text(text)
    assert [str(d) for d in validate_application(path, CATALOG)] == [
        f"{path}:4:16: insert_rivet needs the right_arm to hold a part, but nothing was picked since the start of the application",
        f"{path}:5:25: unknown function 'debur_driling' (did you mean 'debur_drilling'?)",
        f"{path}:8:59: param 1 (rivet) of pick_rivet: frame 'drill_2' is a hole, expected rivet_slot",
        f"{path}:10:66: param 1 (pose) of move_to_joint_pose: joint pose 'look_at_part' is for torso_head, not left_arm",
    ]
