"""``break="true"`` on an ``<operation>``: read into the application model, refused in one line anywhere else.

A breakpoint is the file's word that the run pauses before an operation (docs/application_xml.md,
"Breakpoints"); an operation a loop makes from one breaks in every iteration.  A value other than
true/false, or the attribute on anything but an operation, is one line naming the file, the line
and the attribute, and nothing runs.
"""
from __future__ import annotations

from pathlib import Path

from app_model_support import pos

from app_functions.registry import full_catalog
from cell_runner.dry_run.app_digest import app_digest
from execution_engine.app_model import load_application, validate_application

ROOT = Path(__file__).resolve().parents[1]
CATALOG = full_catalog()


def written(tmp_path: Path, source: str, old: str, new: str) -> tuple[Path, str]:
    """A copy of an application of apps_xml with ``old`` written as ``new``, in ``tmp_path`` with the cells it names."""
    tmp_path.mkdir(exist_ok=True)
    text = (ROOT / "apps_xml" / source).read_text(encoding="utf-8").replace(old, new, 1)
    assert new in text
    (tmp_path / "cells").symlink_to(ROOT / "apps_xml" / "cells")  # the cell is named relative to the file
    path = tmp_path / source
    path.write_text(text, encoding="utf-8")
    return path, text


def test_break_true_marks_the_operation_and_every_iteration_a_loop_makes_of_it(tmp_path: Path) -> None:
    path, _ = written(tmp_path, "rivet_loop.xml", '<operation id="insert_{hole}" name="insert {index}">',
                      '<operation id="insert_{hole}" name="insert {index}" break="true">')
    app = load_application(path, CATALOG)
    assert [op.id for op in app.operations if op.breakpoint] == [f"insert_drill_{i}" for i in range(1, 5)]
    flat = load_application(ROOT / "apps_xml" / "rivet_installation.xml", CATALOG)
    assert not any(op.breakpoint for op in flat.operations)


def test_break_false_is_no_breakpoint(tmp_path: Path) -> None:
    path, _ = written(tmp_path, "rivet_installation.xml", "<operation id='2' name='debur and pick 1'>", "<operation id='2' name='debur and pick 1' break='false'>")
    app = load_application(path, CATALOG)
    assert not any(op.breakpoint for op in app.operations)


def test_a_break_that_is_not_true_or_false_or_not_on_an_operation_is_one_line_naming_file_line_and_attribute(tmp_path: Path) -> None:
    path, text = written(tmp_path, "rivet_installation.xml", "<operation id='2' name='debur and pick 1'>", "<operation id='2' name='debur and pick 1' break='yes'>")
    (problem,) = map(str, validate_application(path, CATALOG))
    line = pos(text, "break='yes'")[0]
    assert problem.startswith(f"{path}:{line}:") and problem.endswith("attribute break='yes' of <operation>: expected true or false")
    path, text = written(tmp_path / "loop", "rivet_loop.xml", '<for_each var="hole" in="kind:hole">', '<for_each var="hole" in="kind:hole" break="true">')
    (problem,) = map(str, validate_application(path, CATALOG))
    line = pos(text, '<for_each var="hole"')[0]
    assert problem.startswith(f"{path}:{line}:")
    assert problem.endswith('<for_each> has no attribute break (a breakpoint goes on an <operation>: break="true" on the first operation inside); it takes: in, index, var')


def test_a_breakpoint_changes_nothing_a_kept_dry_run_verdict_depends_on(tmp_path: Path) -> None:
    path, text = written(tmp_path, "rivet_loop.xml", '<operation id="insert_{hole}" name="insert {index}">',
                         '<operation id="insert_{hole}" name="insert {index}" break="true">')
    marked = load_application(path, CATALOG)
    path.write_text(text.replace(' break="true"', ""), encoding="utf-8")  # the same file, its breakpoint cleared
    plain = load_application(path, CATALOG)
    assert any(op.breakpoint for op in marked.operations)
    assert app_digest(marked.operations) == app_digest(plain.operations)  # the verdict's key (cell_runner/dry_run/app_digest.py)
