"""The station's speed override route: a value for the next run when none is going, refusals that change
nothing, none in a replay; the run started afterwards runs at it (its status says so).  The slider itself
is shown halving a running motion in test_speed_override_browser.py."""
from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station.cli import build_station  # noqa: E402
from test_studio_server import CATALOG, cell_dir, client_for, rivet, run_to_end, station_args  # noqa: E402,F401 - cell_dir: fixture


def test_the_next_run_takes_the_pages_value_and_a_bad_one_changes_nothing(cell_dir: Path) -> None:
    trace = cell_dir / "run.jsonl"
    station, client, document = rivet(cell_dir, trace=str(trace), no_check=True)
    assert client.post("/api/speed", json={"percent": 40}).json() == {"ok": True, "answer": "speed override 40 % for the next run", "percent": 40.0}
    for body, words in (({"percent": 150}, "must be a number in [0, 100] %, got 150"), ({"percent": "fast"}, "got nan"),
                        ({}, 'give {"percent": P}'), ({"percent": True}, "got nan")):
        answer = client.post("/api/speed", json=body)
        assert answer.status_code == 400 and words in (answer.json().get("answer") or answer.json().get("error")), body
    assert client.post("/api/speed", content=b"{not json", headers={"content-type": "application/json"}).status_code == 400
    assert station.session is not None and station.session.speed_percent == 40.0
    run_to_end(station, client, "rivet_installation.xml", document)
    assert station.feed.snapshot.status["speed_override"] == 40.0
    audited = [(e["ok"], e.get("before"), e.get("after")) for e in station.audit_log.entries if e["what"] == "speed override"]
    assert audited[0] == (True, "100 %", "40 %") and all(not ok for ok, _, _ in audited[1:]) and len(audited) == 4  # a body without a value is no request to audit
    replay = client_for(build_station(station_args(replay=str(trace)), CATALOG, cell_dir))
    assert replay.post("/api/speed", json={"percent": 50}).status_code == 409
