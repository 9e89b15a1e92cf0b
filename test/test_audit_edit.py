"""An edit of a paused run in the audit log (issue 26 items 3 and 5): the page's edit is audited once, under the
engineer, with the digests of the remainder before and after in the log's ``sha256:`` form -- the very ones the
trace's swap record carries -- and a refused edit with the digest of what it would have replaced; the swap record
the edit itself makes is not audited a second time as someone else's."""
from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from test_paused_edit_flags import COLLIDES, OLD, SAFE  # noqa: E402
from test_paused_edit_flags_route import document_of  # noqa: E402
from test_studio_server import CATALOG, client_for, station_args, wait_until  # noqa: E402

from operator_station.access import ENGINEER  # noqa: E402
from operator_station.cli import build_station  # noqa: E402


def test_the_pages_edit_of_a_paused_run_is_audited_once_with_the_swaps_digests(tmp_path: Path) -> None:
    (tmp_path / "edit_flags.xml").write_text(OLD)
    station = build_station(station_args(file="edit_flags.xml"), CATALOG, tmp_path)
    client = client_for(station)
    texts = {"collide.xml": COLLIDES, "safe.xml": SAFE, "edit_flags.xml": OLD}  # the run's own last: the builder holds it
    documents = {name: document_of(client, tmp_path, name, text) for name, text in texts.items()}
    try:
        assert client.post("/api/run", json={"path": "edit_flags.xml", "document": documents["edit_flags.xml"]}).json()["ok"]
        assert wait_until(lambda: (station.feed.snapshot.status or {}).get("state") == "paused", 120.0)
        for name, status in (("collide.xml", 409), ("safe.xml", 200)):  # refused (a collision), then swapped
            assert client.post("/api/edit", json={"path": "edit_flags.xml", "document": documents[name]}).status_code == status
        assert wait_until(lambda: any(r["event"] == "swap" for r in station.feed.records))
    finally:
        assert client.post("/api/operator/stop", json={}).status_code == 200
        assert station.session is not None
        station.session.join(60.0)
    (swap,) = [r for r in station.feed.records if r["event"] == "swap"]
    edits = [e for e in station.audit_log.entries if e["what"] == "edit paused run"]
    assert [(e["ok"], e["who"], e["role"], e["kind"]) for e in edits] == [(False, "loopback", ENGINEER, "session"), (True, "loopback", ENGINEER, "session")]
    refused, swapped = edits
    assert (swapped["before"], swapped["after"]) == (f"sha256:{swap['from_digest']}", f"sha256:{swap['to_digest']}")
    assert refused["before"] == swapped["before"] and refused["after"] is None
    assert swap["source"].startswith("studio (")  # the page's, named with its requester: not audited again
    assert not [e for e in station.audit_log.entries if e["kind"] == "cell"]
