"""What the page marks in a paused ``sync="flags"`` run, without a browser: the engine's status gives each group's
position in its own calls and the snapshot's operations which groups have a step where, so the builder locks exactly
the operations some group has started -- not everything below the engine's one operation count.

The right arm runs ahead of the left one: the left holds at its breakpoint before operation 2 while the right has
done operation 3 and waits inside operation 4 for the left's flag.  The engine's operation count is 4 (the latest
operation any group started), yet operation 2 has been started by no group: it may still change, and the engine takes
an edit of it; operation 3, which the right arm has run, is refused naming it.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from test_paused_edit import REACH, op  # noqa: E402
from test_paused_edit_flags import CLOSER, RIGHT_WAIT, RIGHT_WIDER, WIDER, breaks, flags_app  # noqa: E402
from test_paused_edit_flags_route import document_of, held, station_on  # noqa: E402
from test_studio_server import wait_until  # noqa: E402

RIGHT_SOLO = op("right_solo", right_arm=("move_to", RIGHT_WIDER))
#: The torso's only call is a wait of no time: it sits it out (no step of its own), so it locks nothing.
LEFT_DONE_TORSO = op("left_done", left_arm=("set_flag", "left_done"), torso_head=("wait", "0"))
HOME_LEFT = op("home_left", left_arm=("move_to", "0.30,0.20,0.15,180deg,0,90deg"))
AHEAD = flags_app(REACH, CLOSER, RIGHT_SOLO, RIGHT_WAIT, LEFT_DONE_TORSO, HOME_LEFT)
#: Operation 2, which no group has started, sent elsewhere (renamed, so the run shows it ran).
EDITED = flags_app(REACH, breaks(op("wider", left_arm=("move_to", WIDER))), RIGHT_SOLO, RIGHT_WAIT, LEFT_DONE_TORSO, HOME_LEFT)
#: Operation 3, which the right arm has run, changed.
STARTED = flags_app(REACH, CLOSER, op("right_solo", right_arm=("move_to", "0.30,-0.22,0.10,180deg,0,90deg")), RIGHT_WAIT, LEFT_DONE_TORSO, HOME_LEFT)


def shown(station: Any) -> dict[str, Any]:
    """The snapshot a page connecting now is sent (WS /ws), as JSON."""
    return json.loads(json.dumps(asdict(station.feed.snapshot), default=str))


def test_the_page_gets_each_groups_position_and_locks_only_what_some_group_started(tmp_path: Path) -> None:
    station, client = station_on(tmp_path, "ahead.xml", AHEAD)
    started, edited, run = (document_of(client, tmp_path, name, text) for name, text in (("started.xml", STARTED), ("edited.xml", EDITED), ("ahead.xml", AHEAD)))
    try:
        status = held(client, station, "ahead.xml", run)
        page = shown(station)
        groups = page["status"]["groups"]
        assert {g: p["position"] for g, p in groups.items()} == {"left_arm": "before:2", "right_arm": "in:4", "torso_head": "finished:7"}
        assert page["status"]["operation_index"] == 4  # the count alone would lock operation 2, which nobody started
        assert [(o["id"], o["steps"]) for o in page["operations"]] == [
            ("reach", ["left_arm", "right_arm"]), ("closer", ["left_arm"]), ("right_solo", ["right_arm"]),
            ("right_wait", ["right_arm"]), ("left_done", ["left_arm"]), ("home_left", ["left_arm"])]

        refused = client.post("/api/edit", json={"path": "ahead.xml", "document": started})
        assert refused.status_code == 409, refused.json()
        assert "operation 3 'right_solo' has already run (right_arm started it)" in refused.json()["answer"]
        swapped = client.post("/api/edit", json={"path": "ahead.xml", "document": edited}).json()
        assert swapped["ok"], swapped
        assert [(o["id"], o["steps"]) for o in swapped["operations"]][1] == ("wider", ["left_arm"])
        assert {g: p["position"] for g, p in status()["groups"].items()} == {"left_arm": "before:2", "right_arm": "in:4", "torso_head": "finished:7"}

        assert client.post("/api/operator/resume", json={}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "finished", 120.0), status()
        ran = [(r["operation"], r["group"]) for r in station.feed.records if r["event"] == "function_start"]
        assert ("wider", "left_arm") in ran and ("closer", "left_arm") not in ran
    finally:
        assert station.session is not None
        station.session.join(60.0)


def test_a_lock_step_run_carries_no_positions(tmp_path: Path) -> None:
    """Lock-step: every group's position is "" -- the page keeps the engine's one operation count."""
    text = flags_app(REACH, CLOSER, RIGHT_SOLO, HOME_LEFT).replace(' sync="flags"', "")
    station, client = station_on(tmp_path, "lock.xml", text)
    run = document_of(client, tmp_path, "lock.xml", text)
    status = lambda: station.feed.snapshot.status or {}  # noqa: E731
    try:
        assert client.post("/api/run", json={"path": "lock.xml", "document": run}).json()["ok"]
        assert wait_until(lambda: status().get("state") == "paused", 120.0), status()
        page = shown(station)
        assert page["status"]["operation_index"] == 2 and {p["position"] for p in page["status"]["groups"].values()} == {""}
        assert all("steps" not in o for o in page["operations"])
        assert client.post("/api/operator/stop", json={}).json()["ok"]
    finally:
        assert station.session is not None
        station.session.join(60.0)
