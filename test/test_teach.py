"""Teach this frame (operator_station/teach.py, jog_routes.py): the TCP's pose into the cell as a diff, saved only when confirmed.

Through the station's routes with Starlette's TestClient, on a copy of the rivet application and its cell:
what the diff says, that nothing is written before the confirmation, that the saved cell holds the frame where
the TCP is and validates with the application, that a file changed since the diff is not overwritten; and the
jog's refusals while a run is active and during the safety stop.
"""
from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from starlette.testclient import TestClient  # noqa: E402

from core_functions.geometry import Pose  # noqa: E402
from execution_engine.app_model import read_application  # noqa: E402
from execution_engine.app_model.cell import load_cell, read_cell  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.jog import JogSettings  # noqa: E402
from operator_station.server import Station, create_app  # noqa: E402
from operator_station.teach import TeachRefused, plan_teach  # noqa: E402
from test_audit_jog import LEASE  # noqa: E402
from test_studio_server import BASE, CATALOG, ROOT, station_args, wait_until  # noqa: E402

JOG = "ws://127.0.0.1:8080/ws/jog"



@pytest.fixture
def folder(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    return tmp_path


@pytest.fixture
def station(folder: Path) -> Any:
    made = build_station(station_args(file="rivet_installation.xml"), CATALOG, folder)
    yield made
    made.stop()


def client_for(station: Station) -> tuple[TestClient, dict[str, Any]]:
    client = TestClient(create_app(station), base_url=BASE, client=("127.0.0.1", 50000))
    assert client.get("/").status_code == 200
    document = client.get("/api/document").json()
    return client, {"path": document["path"], "document": document["document"]}


def test_a_taught_frame_is_the_tcp_under_its_parent_shown_as_a_diff_and_saved_only_when_confirmed(station: Station, folder: Path) -> None:
    client, current = client_for(station)
    cell_file = folder / "cells" / "rivet_cell.xml"
    before = cell_file.read_bytes()
    opened = client.post("/api/jog/open", json=current).json()
    assert opened["ok"] and opened["speed"] == 10.0 and "drill_1" in opened["frames"], opened
    answer = client.post("/api/teach", json={**current, "group": "left_arm", "name": "taught_1", "parent": "part"}).json()
    assert answer["ok"] and answer["created"] and answer["problems"] == [], answer
    added = [line for line in answer["diff"] if line.startswith("+") and not line.startswith("+++")]
    assert added == [f'+    <frame name="taught_1" xyz="{" ".join(_n(v) for v in answer["xyz"])}" rpy="{" ".join(_n(v) for v in answer["rpy"])}"/>']
    assert not [line for line in answer["diff"] if line.startswith("-") and not line.startswith("---")]  # nothing else changes
    assert cell_file.read_bytes() == before  # shown, not written
    refused = client.post("/api/teach/save", json={"id": answer["id"]})
    assert refused.status_code == 400 and "confirm it" in refused.json()["error"] and cell_file.read_bytes() == before
    saved = client.post("/api/teach/save", json={"id": answer["id"], "confirm": True}).json()
    assert saved["ok"] and saved["answer"] == "frame taught_1 added to cells/rivet_cell.xml", saved
    text = cell_file.read_text(encoding="utf-8")
    assert added[0][1:] in text.splitlines()  # the line shown is the line saved
    cell = load_cell(cell_file)
    tcp = station.jog._backend.tcp_pose("left_arm")  # noqa: SLF001 - where the jog's robot says the TCP is
    assert cell.pose("taught_1").distance_to(tcp) < 2e-6 and cell.pose("taught_1").angle_to(tcp) < 1e-5
    assert cell.frames["taught_1"].parent == "part"
    app, problems = read_application(folder / "rivet_installation.xml", CATALOG)
    assert app is not None, problems  # the application still validates with the taught cell
    again = client.post("/api/teach/save", json={"id": answer["id"], "confirm": True})
    assert again.status_code == 404  # a plan is saved once
    audited = [(e["what"], e["ok"]) for e in station.audit_log.newest()]
    assert ("teach save", True) in audited and ("teach", True) in audited  # who taught and saved what is in the audit log


def test_an_updated_frame_changes_its_own_line_only_and_a_cell_changed_since_the_diff_is_not_overwritten(station: Station, folder: Path) -> None:
    client, current = client_for(station)
    cell_file = folder / "cells" / "rivet_cell.xml"
    assert client.post("/api/jog/open", json=current).json()["ok"]
    answer = client.post("/api/teach", json={**current, "group": "right_arm", "name": "drill_1", "parent": "part"}).json()
    assert answer["ok"] and not answer["created"]
    removed = [line for line in answer["diff"] if line.startswith("-") and not line.startswith("---")]
    added = [line for line in answer["diff"] if line.startswith("+") and not line.startswith("+++")]
    assert len(removed) == len(added) == 1 and 'name="drill_1"' in removed[0] and 'kind="hole" diameter="0.0048"' in added[0]
    cell_file.write_text(cell_file.read_text(encoding="utf-8").replace("rivet_cell", "rivet_cell_edited", 1), encoding="utf-8")
    edited = cell_file.read_bytes()
    refused = client.post("/api/teach/save", json={"id": answer["id"], "confirm": True})
    assert refused.status_code == 409 and "changed since the diff was made" in refused.json()["error"]
    assert cell_file.read_bytes() == edited  # the other change kept, nothing of the teach written
    assert not list(cell_file.parent.glob(".rivet_cell.xml.teach-*"))  # no temporary left behind


def test_what_cannot_be_taught_is_a_one_line_refusal_and_nothing_is_written(station: Station, folder: Path) -> None:
    client, current = client_for(station)
    cell_file = folder / "cells" / "rivet_cell.xml"
    before = cell_file.read_bytes()
    not_open = client.post("/api/teach", json={**current, "group": "left_arm", "name": "x1", "parent": "world"}).json()
    assert "open the jog panel first" in not_open["error"]
    assert client.post("/api/jog/open", json=current).json()["ok"]
    for body, words in (({"name": "1bad"}, "must be a name"), ({"name": "ref_R10"}, "is an element of"),
                        ({"name": "x1", "parent": "nowhere"}, "parent 'nowhere' is not a frame"),
                        ({"name": "drill_1", "parent": "world"}, "is under 'part', not 'world'"),
                        ({"name": "x1", "group": "torso_head"}, "torso_head has no TCP")):
        answer = client.post("/api/teach", json={**current, "group": "left_arm", "parent": "world", **body}).json()
        assert words in answer["error"], (body, answer)
    assert cell_file.read_bytes() == before


def test_a_teach_for_another_robot_than_the_jog_was_opened_on_is_refused(station: Station, folder: Path) -> None:
    """The pose comes from the jog's back end: a page whose builder has since opened another application (another
    robot, another cell) must not write the first robot's TCP into the second's cell."""
    shutil.copy(ROOT / "apps_xml" / "vplus_pick_inspect.xml", folder / "vplus_pick_inspect.xml")
    client, current = client_for(station)
    assert client.post("/api/jog/open", json=current).json()["ok"]
    other = client.post("/api/open", json={"path": "vplus_pick_inspect.xml"}).json()
    before = (folder / "cells" / "vplus_cell.xml").read_bytes()
    answer = client.post("/api/teach", json={"path": other["path"], "document": other["document"], "group": "arm", "name": "t1", "parent": "world"}).json()
    assert answer["error"] == "teach: the jog panel was opened on another robot or cell (nextage_open); reconnect it to this application first"
    assert (folder / "cells" / "vplus_cell.xml").read_bytes() == before


def test_the_diff_keeps_the_files_units_and_a_frame_under_a_leaf_opens_it(tmp_path: Path) -> None:
    source = (ROOT / "apps_xml" / "cells" / "example_cell.xml").read_text(encoding="utf-8")
    cell_file = tmp_path / "cell.xml"
    cell_file.write_text(source, encoding="utf-8")
    cell = load_cell(cell_file)
    leaf = next(name for name, frame in cell.frames.items() if frame.parent != "world")
    tcp = cell.pose(leaf).compose(Pose.from_xyz_rpy(0.01, 0.0, 0.002, 0.0, 0.0, math.radians(90)))
    plan = plan_teach(cell_file, "cell.xml", cell_file.read_bytes(), cell, "t_leaf", leaf, tcp)
    assert any('name="t_leaf" xyz="10 0 2" rpy="0 0 90"' in line for line in plan.diff)  # mm and deg, as the file writes them
    cell_file.write_text(plan.text, encoding="utf-8")
    taught, problems = read_cell(cell_file)
    assert taught is not None, problems
    assert taught.frames["t_leaf"].parent == leaf and taught.pose("t_leaf").distance_to(tcp) < 1e-6
    with pytest.raises(TeachRefused, match="'t_leaf' of cell.xml is under"):
        plan_teach(cell_file, "cell.xml", cell_file.read_bytes(), taught, "t_leaf", "t_leaf", tcp)  # not its own parent


def test_jogging_is_refused_while_a_run_is_active_and_during_the_safety_stop(folder: Path) -> None:
    station = build_station(station_args(file="rivet_installation.xml", speed=1.0, no_check=True), CATALOG, folder)  # real time: the run lasts
    client, current = client_for(station)
    try:
        refused_while_running(station, client, current)
    finally:
        station.stop()


def refused_while_running(station: Station, client: TestClient, current: dict[str, Any]) -> None:
    station.jog.settings = JogSettings(lease=LEASE)  # a loaded machine's stall between press and release is no lapse
    assert client.post("/api/jog/open", json=current).json()["ok"]
    press = {"type": "start", "group": "left_arm", "mode": "joint", "axis": "LARM_JOINT0", "direction": 1}
    assert client.post("/api/run", json=current).json()["ok"]
    assert not station.jog.ready  # the run took the robot: the jog's back end let go of it
    assert wait_until(lambda: client.post("/api/operator/pause", json={}).json()["ok"])
    assert station.session.running  # paused, not ended
    with client.websocket_connect(JOG, headers={"Origin": BASE}) as socket:
        socket.send_json(press)
        assert socket.receive_json() == {"type": "answer", "ok": False, "answer": "jog: a run is active (paused too): stop it before jogging"}
    assert client.post("/api/jog/open", json=current).json()["error"] == "jog: a run is active (paused too): stop it before jogging"
    assert client.post("/api/operator/stop", json={}).json()["ok"]
    station.session.join(30.0)
    assert not station.session.running
    assert client.post("/api/jog/open", json=current).json()["ok"]  # the run over, the jog may have the robot again
    raised = client.post("/api/safety", json={"active": True}).json()
    assert raised["ok"] and "jogging stopped and refused until the safety stop is cleared" in raised["answer"]
    with client.websocket_connect(JOG, headers={"Origin": BASE}) as socket:
        socket.send_json(press)
        assert socket.receive_json()["answer"] == "jog: the safety stop is raised: clear it before jogging"
    assert client.post("/api/safety/clear", json={"confirm": True}).json()["ok"]
    with client.websocket_connect(JOG, headers={"Origin": BASE}) as socket:
        socket.send_json(press)
        messages = [socket.receive_json() for _ in range(2)]
        assert {"type": "answer", "ok": True, "answer": "jogging left_arm LARM_JOINT0+"} in messages
        socket.send_json({"type": "stop"})
        while True:
            message = socket.receive_json()
            if message["type"] == "state" and not message["state"]["moving"]:
                break
    assert message["state"]["reason"] == "jog released"


def _n(value: float) -> str:
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


CELLS = {name: load_cell(ROOT / "apps_xml" / "cells" / name) for name in ("rivet_cell.xml", "example_cell.xml")}


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(CELLS)), st.text(alphabet=st.characters(codec="utf-8"), max_size=10) | st.sampled_from(["drill_1", "hole_a", "t.1", "_x-2"]),
       st.data(), st.tuples(*[st.floats(-0.5, 0.5)] * 3, *[st.floats(-3.1, 3.1)] * 3))
def test_any_name_parent_and_pose_is_taught_into_a_cell_that_reads_back_with_the_frame_there_or_refused(
        which: str, name: str, data: st.DataObject, pose: tuple[float, ...]) -> None:
    """Whatever the page names (the name is outside input), the edit either is refused in one line or gives a
    cell the reader takes, with the frame under that parent where the TCP was, every other frame unchanged."""
    cell = CELLS[which]
    parent = data.draw(st.sampled_from(["world", *sorted(cell.frames)]))
    tcp = Pose.from_xyz_rpy(*pose)
    source = ROOT / "apps_xml" / "cells" / which
    try:
        plan = plan_teach(source, which, source.read_bytes(), cell, name, parent, tcp)
    except TeachRefused as refused:
        assert "\n" not in str(refused) and str(refused).startswith("teach: ")
        return
    with tempfile.TemporaryDirectory() as folder:
        written = Path(folder) / which
        written.write_text(plan.text, encoding="utf-8")
        taught, problems = read_cell(written)
    assert taught is not None, problems
    assert taught.frames[name].parent == parent
    assert taught.pose(name).distance_to(tcp) < 1e-5 and taught.pose(name).angle_to(tcp) < 1e-4
    assert all(taught.pose(f).distance_to(cell.pose(f)) < 1e-9 for f in cell.frames if f != name and not _under(cell, f, name))


def _under(cell: Any, frame: str, ancestor: str) -> bool:
    parent = cell.frames[frame].parent
    while parent != "world":
        if parent == ancestor:
            return True
        parent = cell.frames[parent].parent
    return False
