"""The operator station's server without a browser (Starlette's TestClient): what the page relies on."""
from __future__ import annotations

import argparse
import asyncio
import io
import json
import re
import shutil
import sys
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from starlette.testclient import TestClient  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.deployment import deploy_local  # noqa: E402
from cell_runner.run_report import summarize  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from execution_engine.record_reader import NotARecording, OverLimit  # noqa: E402
from execution_engine.timeline import build_timeline  # noqa: E402
from node_transport.clock import Clock, scaled_clock  # noqa: E402
from node_transport.local import LocalTransport  # noqa: E402
from node_transport.port import Transport  # noqa: E402
from operator_station.attach import AttachedSession  # noqa: E402
from operator_station.cli import build_station, cmd_studio  # noqa: E402
from operator_station.feed import Feed  # noqa: E402
from operator_station.program import main as cli_main  # noqa: E402
from operator_station.replay import load_replay  # noqa: E402
from operator_station.server import Station, create_app  # noqa: E402
from operator_station.testing import station_args  # noqa: E402,F401 - the other studio tests take it from here
from operator_station.timeline_view import TimelineView  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CATALOG = full_catalog()


@pytest.fixture
def cell_dir(tmp_path: Path) -> Path:
    """A working folder holding the rivet application and its cell, as an integrator's would."""
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    return tmp_path


#: Where the tests' client believes the station is (its Host header and origin): the default address and port.
BASE = "http://127.0.0.1:8080"
FEED = "ws://127.0.0.1:8080/ws"


def client_for(station: Station) -> TestClient:
    """A client that loads the page first, as a browser on loopback does: it holds the station's session cookie."""
    client = TestClient(create_app(station), base_url=BASE, client=("127.0.0.1", 50000))
    assert client.get("/").status_code == 200 and client.cookies
    return client


def rivet(cell_dir: Path, **changes: Any) -> tuple[Station, TestClient, dict[str, Any]]:
    station = build_station(station_args(file="rivet_installation.xml", **changes), CATALOG, cell_dir)
    client = client_for(station)
    document = client.get("/api/document").json()
    assert document["ok"] and document["path"] == "rivet_installation.xml"
    return station, client, document["document"]


def run_to_end(station: Station, client: TestClient, path: str, document: dict[str, Any]) -> dict[str, Any]:
    answer = client.post("/api/run", json={"path": path, "document": document}).json()
    assert answer["ok"], answer
    assert station.session is not None
    station.session.join(120.0)
    assert not station.session.running
    return answer


def wait_until(condition: Callable[[], bool], timeout: float = 60.0) -> bool:
    """Poll a condition of a run on another thread (wall time: that run is real), bounded."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_the_catalog_lists_every_function_grouped_core_then_app() -> None:
    client = client_for(build_station(station_args(), CATALOG, ROOT))
    catalog = client.get("/api/catalog").json()
    listed = [name for library in catalog["libraries"] for name in library["functions"]]
    assert sorted(listed) == sorted(CATALOG.names()) and len(listed) == len(set(listed))
    assert catalog["libraries"][0] == {"name": "core", "kind": "core", "functions": [f for f in listed if CATALOG.functions[f].library == "core"]}
    assert {lib["kind"] for lib in catalog["libraries"][1:]} == {"app"}
    out = io.StringIO()
    cli_main(["functions", "--json"], out=out)
    assert catalog["functions"] == json.loads(out.getvalue())["functions"]  # the same data as functions --json


def test_the_cell_offers_its_frames_with_kinds(cell_dir: Path) -> None:
    _, client, document = rivet(cell_dir)
    names = client.post("/api/cell", json={"path": "rivet_installation.xml", "document": document}).json()
    assert {"name": "drill_1", "kind": "hole"} in names["frames"]
    assert names["groups"] == ["left_arm", "right_arm", "torso_head"] and "initial" in names["robot_poses"]


def test_a_bad_edit_is_shown_at_its_cell_and_nothing_runs(cell_dir: Path) -> None:
    station, client, document = rivet(cell_dir)
    document["operations"][1]["calls"][0]["params"][0]["value"] = "drill_99"  # unknown frame, left_arm of operation 2
    document["operations"][0]["calls"][0]["params"][0]["value"] = "0.8 deg"  # a speed fraction with an angle's unit
    answer = client.post("/api/validate", json={"path": "rivet_installation.xml", "document": document}).json()
    assert not answer["ok"]
    placed = {(m["operation"], m["group"], m["param"]): m["message"] for m in answer["messages"]}
    assert "drill_99" in placed[(1, "left_arm", 0)]
    assert "deg" in placed[(0, "left_arm", 0)]
    run = client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).json()
    assert not run["ok"] and "errors" in run["error"]
    assert station.feed.snapshot.run == 0 and not station.session.running  # type: ignore[union-attr]
    saved = client.post("/api/save", json={"path": "rivet_installation.xml", "document": document}).json()
    assert not saved["ok"]
    assert (cell_dir / "rivet_installation.xml").read_bytes() == (ROOT / "apps_xml" / "rivet_installation.xml").read_bytes()


def test_save_writes_what_validate_accepts_and_opening_it_gives_it_back(cell_dir: Path) -> None:
    _, client, document = rivet(cell_dir)
    document["operations"].append({"id": "11", "name": "look again", "calls": [{"group": "torso_head", "function": "move_to_joint_pose", "params": [{"value": "look_at_part", "name": None}]}], "comments": []})
    saved = client.post("/api/save", json={"path": "built.xml", "document": document}).json()
    assert saved["ok"], saved
    assert cli_main(["validate", str(cell_dir / "built.xml")], out=io.StringIO(), err=io.StringIO()) == 0
    reopened = client.post("/api/open", json={"path": "built.xml"}).json()
    assert reopened["document"] == document
    again = client.post("/api/save", json={"path": "again.xml", "document": reopened["document"]}).json()
    assert again["ok"] and (cell_dir / "again.xml").read_bytes() == (cell_dir / "built.xml").read_bytes()


def test_bad_requests_are_one_line_and_change_nothing(cell_dir: Path) -> None:
    station, client, _ = rivet(cell_dir)
    assert client.post("/api/validate", content=b"{not json", headers={"Content-Type": "application/json"}).status_code == 400
    answer = client.post("/api/save", json={"path": "x.txt", "document": {}})
    assert answer.status_code == 400 and "xml" in answer.json()["error"]
    answer = client.post("/api/save", json={"path": "x.xml", "document": {"name": "a", "robot": "nextage", "operations": "no"}})
    assert answer.status_code == 400 and answer.json()["error"] == "operations: a list is needed"
    assert client.post("/api/operator/launch", json={}).status_code == 404
    assert client.post("/api/operator/pause", json={}).json() == {"ok": False, "answer": "no run is going"}
    assert client.post("/api/safety", json={"active": "yes"}).status_code == 400
    assert not (cell_dir / "x.xml").exists() and station.feed.snapshot.run == 0


def test_a_run_at_max_speed_reaches_finish_and_the_page_gets_the_trace_record_for_record(cell_dir: Path) -> None:
    trace = cell_dir / "run.jsonl"
    station, client, document = rivet(cell_dir, trace=str(trace))
    run_to_end(station, client, "rivet_installation.xml", document)
    lines = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    assert lines[-1]["event"] == "run_end" and lines[-1]["outcome"] == "finished"
    received: list[dict[str, Any]] = []
    with client.websocket_connect(FEED) as socket:
        while len(received) < len(lines):
            message = json.loads(socket.receive_text())
            if message["type"] == "records":
                assert message["from"] == len(received)  # in order, no gap
                received.extend(message["records"])
    assert received == lines  # no dropped state change: event for event
    model = client.get("/api/timeline").json()
    timeline = build_timeline(lines)
    assert model["records"] == len(lines)
    assert model["bars"] == sum(len(lane.bars) for lane in timeline.lanes.values())
    assert [(b["operation"], b["function"]) for b in model["lanes"]["right_arm"]] == [(b.operation, b.function) for b in timeline.lanes["right_arm"].bars]
    starts = [r for r in lines if r["event"] == "operator"]
    assert [(r["command"], r["source"], r["accepted"]) for r in starts] == [("start", "studio", True)]
    assert station.feed.snapshot.plan and len(station.feed.snapshot.plan) == len(document["operations"])  # the ETA's dry-run plan
    assert station.feed.snapshot.structures["left_arm"]["initial"] == "Ready"


def test_the_timeline_shows_debur_and_pick_together_and_the_left_arm_idle_while_the_right_inserts(cell_dir: Path) -> None:
    station, client, document = rivet(cell_dir, no_check=True)
    run_to_end(station, client, "rivet_installation.xml", document)
    model = client.get("/api/timeline").json()
    left = {b["operation"]: b for b in model["lanes"]["left_arm"]}
    right = {b["operation"]: b for b in model["lanes"]["right_arm"]}
    debur, pick, insert = left["2"], right["2"], right["3"]
    assert (debur["function"], pick["function"], insert["function"]) == ("debur_drilling", "pick_rivet", "insert_rivet")
    assert debur["start"] < pick["end"] and pick["start"] < debur["end"]  # overlap
    assert "3" not in left  # the left arm waits while the right inserts
    assert model["idle"]["left_arm"] > insert["end"] - insert["start"]


def test_operator_commands_go_through_the_engine_and_are_traced_with_their_source(cell_dir: Path) -> None:
    trace = cell_dir / "run.jsonl"
    station, client, document = rivet(cell_dir, trace=str(trace), speed=50.0, no_check=True)
    assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).json()["ok"]
    assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).status_code == 409  # one run at a time
    session = station.session
    assert session is not None
    assert session.wait_started(60.0)
    assert client.post("/api/safety", json={"active": True}).json()["ok"]
    assert wait_until(lambda: any(r.get("source", "").startswith("safety stop on") for r in station.feed.records))
    stop = client.post("/api/operator/stop", json={}).json()
    assert stop["ok"], stop
    session.join(120.0)
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    operator = [(r["command"], r["source"]) for r in records if r["event"] == "operator"]
    assert ("start", "studio") in operator and ("stop", "studio") in operator
    assert any(source.startswith("safety stop on") for _, source in operator)
    assert records[-1]["outcome"] == "stopped"


def test_replay_shows_a_trace_with_the_table_2_structure_and_a_slider(cell_dir: Path) -> None:
    trace = cell_dir / "run.jsonl"
    station, client, document = rivet(cell_dir, trace=str(trace), no_check=True)
    run_to_end(station, client, "rivet_installation.xml", document)
    replay = build_station(station_args(replay=str(trace)), CATALOG, cell_dir)
    client = client_for(replay)
    assert replay.feed.snapshot.mode == "replay" and replay.feed.snapshot.groups == ["left_arm", "right_arm", "torso_head"]
    assert set(replay.feed.snapshot.structures["right_arm"]["states"]) >= {"Ready", "Motion", "Pause", "ErrorHandling", "Finish"}
    assert replay.feed.joints and replay.feed.snapshot.joint_names
    whole = client.get("/api/timeline").json()
    halfway = whole["end"] / 2
    part = client.get(f"/api/timeline?until={halfway}").json()
    assert part["end"] == pytest.approx(halfway) and part["total_end"] == pytest.approx(whole["end"])
    assert 0 < part["records"] < whole["records"]
    assert all(b["start"] <= halfway for lane in part["lanes"].values() for b in lane)
    assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).status_code == 409
    assert client.get("/api/timeline?until=soon").status_code == 400


def test_serving_beyond_loopback_warns(capsys: pytest.CaptureFixture[str]) -> None:
    err = io.StringIO()
    code = cli_main(["studio", "--host", "0.0.0.0", "--port", "70000"], out=io.StringIO(), err=err)  # noqa: S104 - the warning is the point
    assert code == 2
    warning, error = err.getvalue().splitlines()
    assert warning.startswith("warning: serving on 0.0.0.0") and error.startswith("error: --port")


_RECORD = st.fixed_dictionaries({"t": st.floats(0, 1e6) | st.text(max_size=3), "event": st.sampled_from(["transition", "function_start", "primitive_end", "run_end", "x"]),
                                 "group": st.sampled_from(["left_arm", "engine", 3]), "result": st.none() | st.dictionaries(st.sampled_from(["joint_names", "positions"]), st.text(max_size=3) | st.lists(st.integers(), max_size=3))})


@settings(max_examples=50, deadline=None)
@given(st.lists(_RECORD, max_size=20).map(lambda rs: "".join(json.dumps(r) + "\n" for r in rs).encode()) | st.binary(max_size=400), st.integers(0, 400))
def test_any_trace_file_even_cut_is_replayed_or_refused_line_by_line(tmp_path_factory: pytest.TempPathFactory, data: bytes, cut: int) -> None:
    path = tmp_path_factory.mktemp("replay") / "trace.jsonl"
    path.write_bytes(data[:cut])
    feed = Feed()
    try:
        count = load_replay(feed, path)
    except (NotARecording, OverLimit) as refusal:  # refused as report refuses it: one line naming the file
        assert str(refusal).startswith(str(path)) and "\n" not in str(refusal)
        with pytest.raises(type(refusal), match=re.escape(str(refusal))):
            summarize(path)
        assert feed.snapshot.mode == "idle" and not feed.records
        return
    assert count == len(feed.records) and feed.snapshot.mode == "replay"
    assert all(isinstance(r["t"], (int, float)) and isinstance(r["event"], str) for r in feed.records)
    timeline = TimelineView(feed).model()
    assert timeline["records"] == count


def cell_elsewhere(app: Any) -> Callable[[Clock], Coroutine[Any, Any, Transport]]:
    """A connect for AttachedSession: the cell (nextage-sim, autostart off) on an in-process transport standing in for
    the ROS graph, its engine already running ``app`` (waiting for the start service)."""

    async def connect(clock: Clock) -> Transport:
        transport = LocalTransport(clock)
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        deployment = await deploy_local(clock, app.robot, backend, transport=transport, engine_parameters={"autostart": False})
        running.append(asyncio.get_running_loop().create_task(deployment.engine.run(app)))  # kept: a task nobody holds may be collected
        return transport

    running: list[Any] = []
    return connect


def test_attached_through_the_transport_port_the_page_sees_and_commands_a_cell_it_does_not_run(cell_dir: Path) -> None:
    """``--transport ros`` with the in-process transport standing in for the ROS graph: the cell is started by
    someone else (autostart off), the station joins as one more node, starts it through the engine's service,
    sees every record, pauses and resumes it and sees it finish."""
    app = load_application(cell_dir / "rivet_installation.xml", CATALOG)
    feed = Feed()
    session = AttachedSession(feed, app.robot, app.name, cell_elsewhere(app), scaled_clock(20.0))  # the cell simulated at 20x
    session.attach()
    client = client_for(Station(CATALOG, feed, session, cell_dir, cell_dir / "rivet_installation.xml"))
    try:
        assert session.wait_started(60.0)
        assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": client.get("/api/document").json()["document"]}).json()["ok"]
        assert wait_until(lambda: any(r["event"] == "function_start" for r in feed.records))
        assert client.post("/api/operator/pause", json={}).json()["ok"]
        assert wait_until(lambda: (feed.snapshot.status or {}).get("state") == "paused")
        assert client.post("/api/operator/resume", json={}).json()["ok"]
        assert wait_until(lambda: (feed.snapshot.status or {}).get("state") == "finished", 120.0)
        operator = [(r["command"], r["source"], r["accepted"]) for r in feed.records if r["event"] == "operator"]
        assert operator == [(c, f"service /execution_engine/{c}", True) for c in ("start", "pause", "resume")]
        assert set(feed.snapshot.structures) == {"left_arm", "right_arm", "torso_head"} and feed.joints
        model = client.get("/api/timeline").json()
        assert model["bars"] == sum(1 for r in feed.records if r["event"] == "function_end")
        # the run summary, though nobody on the graph writes a run_end: from the engine's last state (run_summary.SummaryOnEnd)
        assert wait_until(lambda: (feed.snapshot.summary or {}).get("outcome") == "finished", 30.0)
        assert [g["group"] for g in feed.snapshot.summary["groups"]] == ["left_arm", "right_arm", "torso_head"]  # type: ignore[index]
    finally:
        session.join(30.0)


def test_attaching_without_the_application_is_one_line() -> None:
    err = io.StringIO()
    assert cli_main(["studio", "--transport", "ros"], out=io.StringIO(), err=err) == 2
    assert err.getvalue() == "error: --transport ros needs the application the cell runs (APP.xml): it names the robot and its groups\n"


@pytest.mark.parametrize("module", ["starlette", "uvicorn", "websockets"])
def test_studio_without_its_extra_says_what_to_install(module: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without websockets uvicorn serves the page but refuses the live feed; the command says so at once."""
    monkeypatch.setitem(sys.modules, module, None)  # as if not installed: importing it raises ImportError
    err = io.StringIO()
    assert cmd_studio(argparse.Namespace(file=None), full_catalog(), io.StringIO(), err) == 2
    assert err.getvalue() == (
        "error: studio needs the web server: pip install 'dual_arm_executive[studio]' "
        f"(starlette, uvicorn, websockets; missing {module})\n"
    )
