"""Every jog in the audit log (issue 26 item 5): who opened the jog, each press and each stop with why it stopped --
released, the dead man's lease lapsed, the page's connection dropped, the safety stop -- and the connection's close,
in the order they happened, under the engineer who held the button.

Through the station's routes with Starlette's TestClient, an engineer logged in.  The jog runs on the station's wall
clock (a person holds the button), so the waits are bounded reads of the states the station sends on the jog socket;
the lapse's own timing is test_jog's, on the simulated clock."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station.access import ENGINEER  # noqa: E402
from operator_station.jog import JogSettings  # noqa: E402
from operator_station.jog_station import stop_cause  # noqa: E402
from operator_station.server import Station  # noqa: E402
from test_studio_roles import body, entries, logged_in, station_for  # noqa: E402
from test_studio_server import BASE, cell_dir, wait_until  # noqa: E402, F401

JOG = "ws://127.0.0.1:8080/ws/jog"
PRESS = {"type": "start", "group": "left_arm", "mode": "joint", "axis": "LARM_JOINT0", "direction": 1}
#: s of the dead man's lease here: the longest there is, so that a loaded machine's stall between a press and its
#: release (or the safety stop) is not taken for a lapse; the lapse itself is still seen, 2 s after a press.
LEASE = 2.0
#: Messages read from the jog socket at most while waiting for a stop (a state every ~0.1 s while it moves).
MAX_MESSAGES = 2000


@pytest.fixture
def station(cell_dir: Path) -> Iterator[Station]:
    made = station_for(cell_dir)
    made.jog.settings = JogSettings(lease=LEASE)
    yield made
    made.stop()


def stopped(socket: Any) -> dict[str, Any]:
    """Read the socket's messages until the jog is still again (bounded); that state."""
    started = False
    for _ in range(MAX_MESSAGES):
        message = socket.receive_json()
        if message["type"] == "answer":
            assert message["ok"], message
            started = True
        elif message["type"] == "state" and started and not message["state"]["moving"]:
            return message["state"]
    raise AssertionError(f"the jog did not stop within {MAX_MESSAGES} messages")


def answer_of(socket: Any) -> dict[str, Any]:
    """The station's answer to the last press (the jog's states may come first), bounded."""
    for _ in range(MAX_MESSAGES):
        message = socket.receive_json()
        if message["type"] == "answer":
            return message
    raise AssertionError(f"no answer within {MAX_MESSAGES} messages")


def jog_entries(station: Station) -> list[dict[str, Any]]:
    return [e for e in entries(station) if e["what"].startswith("jog")]


def test_a_jog_from_the_page_open_press_release_lapse_and_dropped_connection_is_audited_with_the_engineer(station: Station) -> None:
    page = logged_in(station, "ben", "ben-pw")
    opened = page.post("/api/jog/open", json=body(station, page)).json()
    assert opened["ok"], opened
    with page.websocket_connect(JOG, headers={"Origin": BASE}) as socket:
        socket.send_json(PRESS)
        assert stopped_by(socket, {"type": "stop"})["reason"] == "jog released"
        socket.send_json(PRESS)  # held without a heartbeat: the dead man stops it when the lease lapses
        assert "no heartbeat" in stopped(socket)["reason"]
        socket.send_json(PRESS)
        assert answer_of(socket) == {"type": "answer", "ok": True, "answer": "jogging left_arm LARM_JOINT0+"}
    # the page's connection dropped while the button was held: the station stopped the jog and closed it
    assert wait_until(lambda: any(e["what"] == "jog close" for e in entries(station)), 30.0)
    jogs = jog_entries(station)
    assert [(e["what"], e.get("cause")) for e in jogs] == [
        ("jog open", None), ("jog connect", None),
        ("jog start", None), ("jog stop", "released"),
        ("jog start", None), ("jog stop", "heartbeat lapsed"),
        ("jog start", None), ("jog stop", "connection dropped"), ("jog close", None)]
    assert all(e["who"] == "ben" and e["role"] == ENGINEER and e["ok"] for e in jogs)
    assert len({e["session"] for e in jogs}) == 1 and jogs[0]["session"]
    first = jogs[0]
    assert first["path"] == "rivet_installation.xml" and first["application"].startswith("sha256:") and first["backend"]
    start, stop = jogs[2], jogs[3]
    assert (start["group"], start["axis"], start["direction"], start["mode"]) == ("left_arm", "LARM_JOINT0", 1, "joint")
    assert start["answer"] == "jogging left_arm LARM_JOINT0+" and stop["answer"] == "jog released"
    assert stop["group"] == "left_arm" and not stop["by_check"] and stop["travel_after_stop"] >= 0.0
    assert jogs[5]["by_check"] and "no heartbeat from the page" in jogs[5]["answer"]
    assert [e["seq"] for e in jogs] == sorted(e["seq"] for e in jogs)


def stopped_by(socket: Any, message: dict[str, Any]) -> dict[str, Any]:
    """Wait for the jog's start, send ``message`` and wait for it to be still again; that state."""
    assert answer_of(socket)["ok"]
    socket.send_json(message)
    for _ in range(MAX_MESSAGES):
        state = socket.receive_json()
        if state["type"] == "state" and not state["state"]["moving"] and state["state"]["reason"]:
            return state["state"]
    raise AssertionError(f"the jog did not stop within {MAX_MESSAGES} messages")


def test_the_safety_stop_stopping_a_jog_and_refused_presses_are_audited(station: Station) -> None:
    page = logged_in(station, "ben", "ben-pw")
    assert page.post("/api/jog/open", json=body(station, page)).json()["ok"]
    with page.websocket_connect(JOG, headers={"Origin": BASE}) as socket:
        socket.send_json({**PRESS, "axis": "NO_SUCH_JOINT"})
        assert not answer_of(socket)["ok"]
        socket.send_json(PRESS)
        assert answer_of(socket)["ok"]
        assert page.post("/api/safety", json={"active": True}).json()["ok"]
        assert wait_until(lambda: any(e.get("cause") == "safety stop" for e in entries(station)), 30.0)
        socket.send_json(PRESS)
        assert answer_of(socket) == {"type": "answer", "ok": False, "answer": "jog: the safety stop is raised: clear it before jogging"}
        assert page.post("/api/safety/clear", json={"confirm": True}).json()["ok"]
    assert wait_until(lambda: any(e["what"] == "jog close" for e in entries(station)), 30.0)
    done = [(e["what"], e["ok"], e.get("cause")) for e in entries(station) if e["what"].startswith(("jog", "safety"))]
    assert done == [("jog open", True, None), ("jog connect", True, None), ("jog start", False, None), ("jog start", True, None),
                    ("jog stop", True, "safety stop"), ("safety stop raised", True, None), ("jog start", False, None),
                    ("safety stop cleared", True, None), ("jog close", True, None)]
    refused = [e for e in entries(station) if e["what"] == "jog start" and not e["ok"]]
    assert "NO_SUCH_JOINT" in refused[0]["answer"] and refused[1]["answer"] == "jog: the safety stop is raised: clear it before jogging"


def test_an_open_refused_while_a_run_is_going_or_with_a_broken_application_is_audited(station: Station) -> None:
    page = logged_in(station, "ben", "ben-pw")
    current = body(station, page)
    broken = {**current, "document": {**current["document"], "operations": "not a list"}}
    assert not page.post("/api/jog/open", json=broken).json()["ok"]
    opens = [e for e in entries(station) if e["what"] == "jog open"]
    assert len(opens) == 1 and not opens[0]["ok"] and opens[0]["answer"].startswith("jog: ") and opens[0]["who"] == "ben"


@pytest.mark.parametrize(("reason", "cause"), [
    ("jog released", "released"),
    ("jog stopped: no heartbeat from the page for 0.30 s (connection lost or page hidden)", "heartbeat lapsed"),
    ("jog stopped: the page's connection closed", "connection dropped"),
    ("jog stopped: the safety stop was raised", "safety stop"),
    ("jog stopped before a collision: left_arm link 3 and box would touch, within the jog's 2 mm clearance", "refused by the collision check"),
    ("jog left_arm LARM_JOINT0+ stopped: jog: LARM_JOINT0 is at its upper limit (1.5300 rad, 87.66 deg): it goes no further that way", "refused by a limit"),
    ("another jog button", "another button pressed"),
    ("a run starts", "released for a run"),
    ("jog left_arm x+ stopped: the back end refused the motion", "stopped by a check"),
])
def test_each_stop_reason_has_its_cause(reason: str, cause: str) -> None:
    assert stop_cause(reason) == cause


def test_a_page_that_is_not_an_engineer_never_reaches_the_jog_and_its_refusal_is_audited(station: Station) -> None:
    page = logged_in(station, "anna", "anna-pw")
    answer = page.post("/api/jog/open", json=body(station, page))
    assert answer.status_code == 403
    refused = [e for e in entries(station) if e.get("refused")]
    assert [(e["what"], e["who"]) for e in refused] == [("jog", "anna")] and not station.jog.ready
    assert not [e for e in entries(station) if e["what"] == "jog open"]

