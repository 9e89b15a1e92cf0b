"""The studio's ``POST /api/edit`` without a browser (scripts call it with the token, as the page does): what it refuses
before the engine is asked, in one line, with nothing changed -- no run going, a replay, a document with errors, a bad
body -- and that it is audited as an engineer's action."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from test_studio_server import CATALOG, ROOT, client_for, rivet, station_args  # noqa: E402

from operator_station.cli import build_station  # noqa: E402


@pytest.fixture
def cell_dir(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    return tmp_path


def test_an_edit_without_a_run_or_with_errors_or_a_bad_body_is_refused_in_one_line_and_audited(cell_dir: Path) -> None:
    station, client, document = rivet(cell_dir)
    answer = client.post("/api/edit", json={"path": "rivet_installation.xml", "document": document})
    assert answer.status_code == 409
    assert answer.json()["error"] == "edit: no run is going: Start runs the builder's application as it is"
    assert client.post("/api/edit", json={"path": "rivet_installation.xml", "document": 7}).status_code == 400
    bad = client.post("/api/edit", json={"path": "../elsewhere.xml", "document": document})
    assert bad.status_code == 400 and bad.json()["error"].startswith("edit: ../elsewhere.xml: outside the station's folders")
    entries = [e for e in station.audit_log.newest() if e["what"] == "edit paused run"]
    assert [(e["ok"], e["answer"]) for e in entries] == [(False, "edit: no run is going: Start runs the builder's application as it is")]
    assert station.session is not None and not station.session.running


def test_a_replay_has_no_run_to_edit(tmp_path: Path) -> None:
    trace = tmp_path / "run.jsonl"
    trace.write_text('{"t": 0.0, "event": "engine_state", "group": "engine", "operation": null, "from": "idle", "to": "running", "message": ""}\n')
    station = build_station(station_args(replay=str(trace)), CATALOG, tmp_path)
    answer: Any = client_for(station).post("/api/edit", json={"path": "x.xml", "document": {"operations": []}})
    assert answer.status_code in (400, 409) and answer.json()["ok"] is False
