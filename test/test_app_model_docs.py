"""docs/application_xml.md: its example files are shipped as shown, valid and runnable, and its diagnostics are what validate prints."""
from __future__ import annotations

import io
import re
import shutil
import tempfile
from pathlib import Path

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main
from core_functions.cell_robots import cell_robot_model
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import check_joint_poses, read_cell, validate_application

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "application_xml.md"
APP, CELL = ROOT / "apps_xml" / "example.xml", ROOT / "apps_xml" / "cells" / "example_cell.xml"
BLOCKS: list[tuple[str, str]] = re.findall(r"```(\w+)\n(.*?)```", DOC.read_text(), re.S)


def example(start: str) -> str:
    return next(body for lang, body in BLOCKS if lang == "xml" and body.lstrip().startswith("<?xml") and start in body)


@pytest.fixture
def example_tree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the shipped walk-through files, for the guide's mistakes to be made in."""
    (tmp_path / "apps_xml" / "cells").mkdir(parents=True)
    shutil.copy(CELL, tmp_path / "apps_xml" / "cells" / "example_cell.xml")
    shutil.copy(APP, tmp_path / "apps_xml" / "example.xml")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_walk_through_files_are_shipped_exactly_as_the_guide_shows_them() -> None:
    """Section 1 names apps_xml/example.xml and apps_xml/cells/example_cell.xml: a reader opens them, runs
    them, and finds what the guide shows, line for line (its diagnostics quote those lines)."""
    assert APP.read_text(encoding="utf-8") == example("<application ")
    assert CELL.read_text(encoding="utf-8") == example("<cell ")


def test_the_documented_example_is_valid(example_tree: Path) -> None:
    assert validate_application("apps_xml/example.xml", full_catalog()) == []


def test_the_shipped_example_runs_to_finish_after_a_clean_dry_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The walk-through's commands, as a reader types them in the repository."""
    monkeypatch.chdir(ROOT)
    out, err = io.StringIO(), io.StringIO()
    assert main(["validate", "--simulate", "apps_xml/example.xml", "--trajectory-db", str(tmp_path / "t.sqlite")], out, err) == 0, err.getvalue()
    assert "dry run of one_rivet on nextage-sim: no problems found; operations checked 3/3" in out.getvalue()
    out, err = io.StringIO(), io.StringIO()
    assert main(["run", "apps_xml/example.xml", "--speed", "max", "-q", "--trajectory-db", str(tmp_path / "t.sqlite")], out, err) == 0, err.getvalue()
    assert "application one_rivet: FINISHED" in out.getvalue() and "operations: 3/3" in out.getvalue()


def test_the_documented_diagnostics_are_real(example_tree: Path) -> None:
    app = example_tree / "apps_xml" / "example.xml"
    app.write_text(app.read_text().replace("debur_drilling", "debur_driling").replace('value="slot_1"', 'value="hole_a"'))
    cell = example_tree / "apps_xml" / "cells" / "example_cell.xml"
    cell.write_text(cell.read_text().replace('name="hole_b" xyz="0 -40 0" rpy="180 0 90" kind="hole"',
                                             'name="hole_b" xyz="0 -40 0" rpy="180 0 90" knid="hole"'))
    assert [str(d) for d in validate_application("apps_xml/example.xml", full_catalog())] == shown("debur_driling")


def shown(needle: str) -> list[str]:
    return next(body for lang, body in BLOCKS if lang == "text" and needle in body).strip().splitlines()


def test_the_documented_bound_messages_are_real(example_tree: Path) -> None:
    cell = example_tree / "apps_xml" / "cells" / "example_cell.xml"
    cell.write_text(cell.read_text().replace('name="hole_b" xyz="0 -40 0" rpy="180 0 90"', 'name="hole_b" xyz="0 -40 0" rpy="180 0 1e308"')
                    .replace('<frame name="tray" xyz="280 -220 0"', '<frame name="tray" xyz="280 -220000 0"'))
    app = example_tree / "apps_xml" / "example.xml"
    app.write_text(app.read_text().replace('safe_pose="initial"/>', 'safe_pose="initial" alarm_timeout="100000"/>'))
    assert [str(d) for d in validate_application("apps_xml/example.xml", full_catalog())] == shown("outside ±720 deg")


def test_the_documented_param_name_message_is_real(example_tree: Path) -> None:
    app = example_tree / "apps_xml" / "example.xml"
    app.write_text(app.read_text().replace('<param value="slot_1"/>', '<param name="reference" value="slot_1"/>'))
    assert [str(d) for d in validate_application("apps_xml/example.xml", full_catalog())] == shown("is named 'reference'")


def test_the_documented_plausibility_message_is_real(example_tree: Path) -> None:
    app = example_tree / "apps_xml" / "example.xml"
    text = app.read_text()
    third = text[text.index('  <operation id="3"'):text.index("</application>")]
    app.write_text(text.replace("</application>", third.replace('id="3"', 'id="4"') + "</application>"))
    assert [str(d) for d in validate_application("apps_xml/example.xml", full_catalog())] == shown("needs the right_arm to hold")


def test_the_documented_master_slave_operation_is_valid(example_tree: Path) -> None:
    fragment = next(body for lang, body in BLOCKS if lang == "xml" and body.startswith('<operation id="7">'))
    app = example_tree / "apps_xml" / "example.xml"
    app.write_text(app.read_text().replace("</application>", fragment + "</application>"))
    assert validate_application("apps_xml/example.xml", full_catalog()) == []


def test_every_documented_joint_pose_fits_the_nextage() -> None:
    """Each <joint_pose> line shown in the guide is valid for the robot it is written for: the Nextage's groups'
    here; a pose of a cell of several robots is a line of a shipped cell, valid for that cell's robots."""
    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "application_xml.md").read_text()
    poses = [p for p in re.findall(r"<joint_pose [^>]*/>", text) if (m := re.search(r'group="(\w+)"', p)) is None or m[1] in NEXTAGE_OPEN.group_names]
    elsewhere = [p for p in re.findall(r"<joint_pose [^>]*/>", text) if p not in poses]
    for pose in elsewhere:
        shipped = [c for c in (root / "apps_xml").rglob("cells/*.xml") if pose in c.read_text(encoding="utf-8")]
        assert shipped, f"{pose} is in no shipped cell"
        cell, diagnostics = read_cell(shipped[0])
        assert cell is not None and diagnostics == [] and cell.robots
        assert check_joint_poses(cell, cell_robot_model(cell.name, cell.robots)) == []
    assert poses
    with tempfile.TemporaryDirectory() as folder:
        cell_path = Path(folder) / "cell.xml"
        names = [f'name="p{i}"' for i in range(len(poses))]
        body = "\n".join(re.sub(r'name="[^"]*"', n, p) for n, p in zip(names, poses))
        cell_path.write_text(f'<cell name="doc" angle_unit="deg">\n{body}\n</cell>\n')  # as the guide's example cell
        cell, diagnostics = read_cell(cell_path)
        assert cell is not None and diagnostics == []
        assert check_joint_poses(cell, NEXTAGE_OPEN) == []
