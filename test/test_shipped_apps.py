"""Every application shipped in apps_xml validates and passes the dry run, and the ones for the embedded simulator run to Finish.

``apps_xml/examples/bin_transfer.xml`` was written by someone who had only the README, the guide
(docs/application_xml.md) and ``python -m execution_engine functions``: it stays here so the catalog
and the guide keep being enough to write a working application.
"""
from __future__ import annotations

import io
from pathlib import Path

import pytest

from cell_runner.cli import main

ROOT = Path(__file__).resolve().parents[1]
APPS = sorted((ROOT / "apps_xml").rglob("*.xml"))
#: apps_xml/blocks/ holds library blocks (docs/application_xml.md, "Sub-applications"): their {variables} are
#: bound by the application that calls them, which is checked and dry-run here with them.
APPLICATIONS = [p for p in APPS if "<application" in p.read_text(encoding="utf-8") and "blocks" not in p.relative_to(ROOT).parts]


@pytest.mark.parametrize("path", APPLICATIONS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_shipped_application_validates(path: Path) -> None:
    out, err = io.StringIO(), io.StringIO()
    assert main(["validate", str(path)], out, err) == 0, err.getvalue()


@pytest.mark.parametrize("path", APPLICATIONS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_shipped_application_passes_the_dry_run(path: Path, tmp_path: Path) -> None:
    """Every shipped application runs on its robot's simulator without a single problem (the KUKA demo on
    the accelerated RSI simulator); so ``run`` starts every one of them."""
    out, err = io.StringIO(), io.StringIO()
    code = main(["validate", "--simulate", str(path), "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 0, err.getvalue()
    assert "no problems found" in out.getvalue()


def test_the_application_written_from_the_catalog_alone_runs_to_finish(tmp_path: Path) -> None:
    out, err = io.StringIO(), io.StringIO()
    path = ROOT / "apps_xml" / "examples" / "bin_transfer.xml"
    code = main(["run", str(path), "--speed", "max", "-q", "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 0, out.getvalue() + err.getvalue()
    assert "application bin_transfer: FINISHED" in out.getvalue()
