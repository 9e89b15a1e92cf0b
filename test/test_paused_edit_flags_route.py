"""The studio's ``POST /api/edit`` on a paused ``sync="flags"`` run, without a browser (as scripts call it, as the page
does): the run started from the page's document holds the left arm at its breakpoint while the right one waits for the
left's flag; an edit that would collide is refused with its finding placed at its cell and changes nothing, a safe one
is swapped with each group where it stands, audited, and the run resumed to its end runs the edited operations."""
from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from test_paused_edit_flags import COLLIDES, OLD, SAFE, WHERE  # noqa: E402
from test_studio_server import CATALOG, client_for, station_args, wait_until  # noqa: E402

from operator_station.cli import build_station  # noqa: E402


def document_of(client: Any, folder: Path, name: str, text: str) -> dict[str, Any]:
    """The builder's document of ``text``, as the page gets it after opening the file."""
    (folder / name).write_text(text)
    opened = client.post("/api/open", json={"path": name}).json()
    assert opened["ok"] and opened["path"] == name, opened
    return copy.deepcopy(opened["document"])


def station_on(tmp_path: Path, name: str, text: str) -> tuple[Any, Any]:
    """A station opened on ``name`` (written with ``text``) and its HTTP client."""
    (tmp_path / name).write_text(text)
    station = build_station(station_args(file=name, trace=str(tmp_path / "run.jsonl")), CATALOG, tmp_path)
    return station, client_for(station)


def held(client: Any, station: Any, name: str, document: dict[str, Any]) -> Callable[[], dict[str, Any]]:
    """``document`` run from the page until it is paused with the right arm waiting for the left's flag; the status."""
    status = lambda: station.feed.snapshot.status or {}  # noqa: E731
    assert client.post("/api/run", json={"path": name, "document": document}).json()["ok"]
    assert wait_until(lambda: status().get("state") == "paused" and (status().get("groups") or {}).get("right_arm", {}).get("state") == "waiting for flag left_done", 120.0), status()
    return status


def test_a_paused_flags_run_refuses_a_colliding_edit_at_its_cell_and_swaps_a_safe_one_that_then_runs(tmp_path: Path) -> None:
    station, client = station_on(tmp_path, "edit_flags.xml", OLD)
    colliding = document_of(client, tmp_path, "collide.xml", COLLIDES)
    safe = document_of(client, tmp_path, "safe.xml", SAFE)
    run = document_of(client, tmp_path, "edit_flags.xml", OLD)
    try:
        status = held(client, station, "edit_flags.xml", run)
        engine = station.session.edit_target.engine  # type: ignore[union-attr]
        old = engine.app

        refused = client.post("/api/edit", json={"path": "edit_flags.xml", "document": colliding})
        assert refused.status_code == 409 and refused.json()["answer"].startswith("edit: not swapped: ")
        placed = {(m["operation"], m["group"]) for m in refused.json()["messages"] if "collision between left_arm hand" in m["message"]}
        assert (2, "left_arm") in placed, refused.json()["messages"]  # the builder's cell: closer's left arm (the third operation)
        assert engine.app is old and status().get("state") == "paused"

        swapped = client.post("/api/edit", json={"path": "edit_flags.xml", "document": safe}).json()
        assert swapped["ok"] and WHERE in swapped["answer"], swapped
        assert [op["id"] for op in swapped["operations"]] == ["reach", "right_wait", "wider", "left_done", "right_more", "right_in", "home"]
        assert client.post("/api/operator/resume", json={}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "finished", 120.0), status()
        started = [(r["operation"], r["group"]) for r in station.feed.records if r["event"] == "function_start"]
        assert ("wider", "left_arm") in started and ("right_more", "right_arm") in started and ("closer", "left_arm") not in started
        (swap,) = [r for r in station.feed.records if r["event"] == "swap"]
        assert f"({WHERE})" in swap["message"]
        audited = [(e["ok"], e["answer"].split(":")[1]) for e in station.audit_log.newest() if e["what"] == "edit paused run"]
        assert sorted(audited) == [(False, " not swapped"), (True, " swapped")]
    finally:
        assert station.session is not None
        station.session.join(60.0)
