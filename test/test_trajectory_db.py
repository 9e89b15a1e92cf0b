"""The trajectory database: the application's own file, wall-clock and cell stamps, no silent overwrite, no silent home."""
from __future__ import annotations

import io
import sqlite3
from pathlib import Path

import pytest

from cell_runner.cli import main
from core_functions.primitives import TrajectoryResult
from core_functions.trajectory_store import TrajectoryExists, TrajectoryStore, application_store

ROOT = Path(__file__).resolve().parent.parent
PATH = TrajectoryResult(("a", "b"), ((0.0, 0.0), (0.1, 0.2)), (0.0, 1.0))


def app(folder: Path, overwrite: str = "") -> Path:
    extra = f'<param value="{overwrite}"/>' if overwrite else ""
    path = folder / "rec.xml"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<application name="rec" robot="nextage" cell="{ROOT / 'apps_xml/cells/rivet_cell.xml'}">
  <operation id="1"><right_arm><function name="record_trajectory"><params><param value="sweep"/><param value="rivet_1 rivet_2"/><param value="ptp"/>{extra}</params></function></right_arm></operation>
  <operation id="2"><right_arm><function name="execute_trajectory"><params><param value="sweep"/></params></function></right_arm></operation>
</application>
""")
    return path


def test_recordings_keep_wall_time_and_cell_and_are_not_overwritten_silently(tmp_path: Path) -> None:
    store = TrajectoryStore(tmp_path / "t.sqlite", wall_time=lambda: 1_700_000_000.0)
    assert not (tmp_path / "t.sqlite").exists()  # nothing recorded, nothing written
    store.cell_sha256 = "ab" * 32
    store.save("right_arm", "sweep", PATH, "teach", 3.0, overwrite=False)
    stored = store.load("right_arm", "sweep")
    assert (stored.recorded_wall, stored.cell_sha256, stored.source, stored.recorded_at) == (1_700_000_000.0, "ab" * 32, "teach", 3.0)
    with pytest.raises(TrajectoryExists, match="already recorded .* overwrite=true"):
        store.save("right_arm", "sweep", PATH, "plan", 4.0, overwrite=False)
    assert store.load("right_arm", "sweep").source == "teach"  # unchanged
    store.save("right_arm", "sweep", PATH, "plan", 4.0, overwrite=True)
    assert store.load("right_arm", "sweep").source == "plan"


def test_a_database_from_before_gains_the_new_columns(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE trajectories (grp TEXT NOT NULL, name TEXT NOT NULL, joint_names TEXT NOT NULL, points TEXT NOT NULL, "
                   "times TEXT NOT NULL, source TEXT NOT NULL, recorded_at REAL NOT NULL, PRIMARY KEY (grp, name))")
        db.execute("INSERT INTO trajectories VALUES ('arm', 'old', '[\"a\"]', '[[0.5]]', '[0.0]', 'plan', 1.0)")
    stored = TrajectoryStore(path).load("arm", "old")
    assert stored.trajectory.points == ((0.5,),) and stored.recorded_wall == 0.0 and stored.cell_sha256 == ""


def test_the_run_keeps_trajectories_next_to_the_application_never_in_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("XDG_DATA_HOME", raising=False)
    path = app(tmp_path)
    err = io.StringIO()
    assert main(["run", str(path), "--speed", "max", "-q"], io.StringIO(), err) == 0, err.getvalue()
    db = application_store(path)
    assert db == tmp_path / "rec.trajectories.sqlite" and db.is_file()
    stored = TrajectoryStore(db).load("right_arm", "sweep")
    assert stored.recorded_wall > 1e9 and len(stored.cell_sha256) == 64
    assert list(home.iterdir()) == []
    out, err = io.StringIO(), io.StringIO()  # the same application again: the recording is refused, before anything moves
    assert main(["run", str(path), "--speed", "max", "-q"], out, err) == 1
    assert "trajectory 'sweep' of right_arm is already recorded" in err.getvalue()
    app(tmp_path, overwrite="true")  # the application says so
    err = io.StringIO()
    assert main(["run", str(path), "--speed", "max", "-q"], io.StringIO(), err) == 0, err.getvalue()
