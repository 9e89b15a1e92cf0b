"""The 3D view's scene, without a browser: the robots (the URDFs the bridges publish, placed as the cell says), the
cell's frames in the world, the goals of the primitives the machines send, the dry run's and a run's findings placed
(the two bodies of a collision, an unreachable target), the scene a recording holds, and the routes that serve them.

The browser half (the page draws this and moves it with the joint states and the slider) is test_studio_3d.py.
"""
from __future__ import annotations

import asyncio
import io
import json
import math
import re
import shutil
from pathlib import Path
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.cli import main  # noqa: E402
from cell_runner.dry_run.report import DryRunReport  # noqa: E402
from cell_runner.dry_run.runner import dry_run  # noqa: E402
from core_functions.cell_robots import cell_robot_model  # noqa: E402
from core_functions.geometry import Pose  # noqa: E402
from core_functions.primitives import EndEffector, ExecuteTrajectory, MoveCartesian, MoveJoints  # noqa: E402
from core_functions.robots import NEXTAGE_OPEN  # noqa: E402
from execution_engine.app_model import load_application, load_cell  # noqa: E402
from execution_engine.record_reader import NotARecording, OverLimit  # noqa: E402
from node_transport.carriage import TypedPublisher  # noqa: E402
from node_transport.clock import Clock  # noqa: E402
from node_transport.local import LocalTransport  # noqa: E402
from node_transport.msgs import JointState  # noqa: E402
from node_transport.qos import COMMANDS, LATCHED, SENSOR  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from node_transport.wire import ENGINE_CELL, JOINT_STATES, BridgeCommand, CellSnapshot, LocatedFrames, bridge_topic, sm_topic  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.feed import Feed  # noqa: E402
from operator_station.session import observe  # noqa: E402
from operator_station.scene3d import goal_json, head_scene, robot_views, scene_log  # noqa: E402
from operator_station.scene3d_findings import collision_bodies, dry_run_finding, run_finding  # noqa: E402
from operator_station.scene3d_recording import read_scene  # noqa: E402
from robot_bridges.kuka_rsi.backend import URDF_PATH as KUKA_URDF  # noqa: E402
from robot_bridges.nextage_sim.model import URDF_PATH as NEXTAGE_URDF  # noqa: E402
from test_studio_server import client_for, station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
APPS = ROOT / "apps_xml"
LOCATION = re.compile(r"^(?P<file>.+):(?P<line>\d+):\d+: operation ")


# ------------------------------------------------------------------ the applications the 3D tests use
def cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(args), out, err)
    return code, out.getvalue(), err.getvalue()


def demonstrator(folder: Path, name: str, operations: int, edit: dict[str, str] | None = None) -> Path:
    """The rivet demonstrator (its cell beside it) cut to its first ``operations`` operations, with ``edit``'s
    texts replaced: a working folder as an integrator's."""
    if not (folder / "cells").exists():
        shutil.copytree(APPS / "cells", folder / "cells")
    text = (APPS / "rivet_installation.xml").read_text(encoding="utf-8")
    for old, new in (edit or {}).items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    root = etree.fromstring(text.encode())
    for extra in root.findall("operation")[operations:]:
        root.remove(extra)
    root.set("name", name)
    path = folder / f"{name}.xml"
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return path


#: The demonstrator's third operation with the left arm sent to the hole the right arm inserts its rivet in: the dry
#: run finds the two hands meet there (the zone lets the right arm in once the left arm's call has ended, the left
#: arm still at the hole).
ARMS_MEET = {"""  <operation id='3' name='insert 1'>
    <left_arm>
      <function name='wait'></function>
    </left_arm>""": """  <operation id='3' name='insert 1'>
    <left_arm>
      <function name='approach'>
        <params>
          <param value='drill_1'></param>
        </params>
      </function>
    </left_arm>"""}


def arms_meet(folder: Path) -> Path:
    return demonstrator(folder, "rivet_arms_meet", 3, ARMS_MEET)


def record(folder: Path, app: Path) -> Path:
    """``run --speed max --record`` of ``app``: the recording."""
    recording = folder / f"{app.stem}.mcap"
    code, _, err = cli("run", str(app), "--speed", "max", "--record", str(recording), "-q")
    assert code == 0, err
    return recording


# ------------------------------------------------------------------ robots and cell
def urdf_joints(text: str) -> set[str]:
    return {j.get("name") for j in etree.fromstring(text.encode()).iter("joint") if j.get("type") != "fixed"}


def test_the_robot_is_the_urdf_its_bridge_publishes() -> None:
    views, notes = robot_views(NEXTAGE_OPEN)
    assert notes == [] and len(views) == 1
    view = views[0]
    assert view.urdf == NEXTAGE_URDF.read_text(encoding="utf-8") and view.base == Pose() and view.prefix == ""
    assert set(view.joints) == urdf_joints(view.urdf)  # the joint states name the URDF's joints: the view sets them by name
    assert view.tcps["left_arm"][0] == "LARM_JOINT5_Link" and view.tcps["right_arm"][0] == "RARM_JOINT5_Link"


def test_a_mixed_cell_places_each_robot_where_its_robot_element_says() -> None:
    cell = load_cell(APPS / "examples" / "cells" / "mixed_cell.xml")
    views, notes = robot_views(cell_robot_model(cell.name, cell.robots))
    assert notes == [] and [v.name for v in views] == ["feeder", "assembler"]
    feeder, assembler = views
    assert feeder.urdf == KUKA_URDF.read_text(encoding="utf-8") and feeder.prefix == "feeder/"
    assert feeder.base.position == pytest.approx((0.35, -0.90, -0.10)) and feeder.base.rpy() == pytest.approx((0, 0, 1.5707963))
    assert assembler.base == Pose() and assembler.urdf == NEXTAGE_URDF.read_text(encoding="utf-8")
    for view in views:
        assert set(view.joints) == urdf_joints(view.urdf)


def test_the_cell_is_drawn_in_the_world_frame() -> None:
    path = APPS / "cells" / "rivet_cell.xml"
    robot, cell, notes = head_scene("nextage", path)
    model = load_cell(path)
    assert notes == [] and robot is NEXTAGE_OPEN and cell is not None
    frames = {f["name"]: f for f in cell["frames"]}
    assert set(frames) == set(model.frames) | set(model.zones)
    for name in model.frames:
        world = model.pose(name)
        assert frames[name]["pose"] == pytest.approx([world.x, world.y, world.z, world.qx, world.qy, world.qz, world.qw])
        assert frames[name]["kind"] == model.frame(name).kind
    assert [float(x) for x in frames["part"]["attributes"]["box"].split()] == [0.12, 0.20, 0.01] and frames["drill_1"]["attributes"]["diameter"] == "0.0048"
    assert frames["hands_left"]["kind"] == "zone" and [float(x) for x in frames["hands_left"]["attributes"]["size"].split()] == [0.16, 0.12, 0.14]
    assert frames["hands_left"]["pose"][:3] == pytest.approx([0.34, 0.02, 0.05])  # the zone's centre, in the part


def test_a_cell_that_cannot_be_read_is_said_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad_cell.xml"
    bad.write_text("<cell name='x'><frame name='a' parent='nowhere'/></cell>", encoding="utf-8")
    robot, cell, notes = head_scene("nextage", bad)
    assert robot is NEXTAGE_OPEN and cell is None and len(notes) == 1 and "\n" not in notes[0] and "bad_cell.xml" in notes[0]


# ------------------------------------------------------------------ goals
def test_each_moving_primitive_says_its_goal() -> None:
    target = Pose.from_xyz_rpy(0.3, 0.1, 0.05, math.pi, 0, 0)
    assert goal_json(MoveCartesian(target, "linear", "drill_1 clearance")) == {
        "kind": "pose", "target": [target.x, target.y, target.z, target.qx, target.qy, target.qz, target.qw], "label": "drill_1 clearance", "interpolation": "linear"}
    assert goal_json(MoveJoints((0.1, 0.2), ("A", "B"), relative=True)) == {"kind": "joints", "names": ["A", "B"], "positions": [0.1, 0.2], "relative": True}
    points = tuple((k * 0.001, -k * 0.001) for k in range(1000))
    goal = goal_json(ExecuteTrajectory("wave", ("A", "B"), points, tuple(k * 0.01 for k in range(1000))))
    assert goal is not None and len(goal["points"]) == 200 and goal["points"][0] == [0.0, 0.0] and goal["points"][-1] == list(points[-1])
    assert goal_json(EndEffector("gripper_open")) is None  # a hand opening moves no arm


# ------------------------------------------------------------------ findings
def dry_run_of(path: Path) -> DryRunReport:
    app = load_application(path, full_catalog())
    return dry_run(app, "nextage-sim", BackendOptions(robot=app.robot))


def test_the_dry_runs_collision_of_two_arms_names_both_hands(tmp_path: Path) -> None:
    """Placed from the report's data: the bodies, line and time the diagnostic ``validate --simulate`` prints says."""
    app = arms_meet(tmp_path)
    code, _, err = cli("validate", "--simulate", str(app))
    lines = [line for line in err.splitlines() if LOCATION.match(line)]
    assert code == 1 and len(lines) == 2, err
    report = dry_run_of(app)
    assert sorted(str(f.diagnostic()) for f in report.findings) == sorted(lines)
    for line in lines:
        finding = next(dry_run_finding(f) for f in report.findings if str(f.diagnostic()) == line)
        assert finding is not None and finding["kind"] == "collision" and finding["source"] == "dry run"
        assert [b["name"] for b in finding["bodies"]] == ["LARM_JOINT5_Link", "RARM_JOINT5_Link"]
        assert [b["owner"] for b in finding["bodies"]] == ["left_arm", "right_arm"]
        assert finding["operation"] == "3" and finding["line"] == int(LOCATION.match(line).group("line"))  # type: ignore[union-attr]
        assert round(finding["t"], 2) == pytest.approx(float(re.search(r"\(at (\d+\.\d+) s\)$", line).group(1)))  # type: ignore[union-attr]  # (the line says it to 10 ms)


def test_an_unreachable_target_is_placed_where_the_dry_run_says(tmp_path: Path) -> None:
    shutil.copytree(APPS / "cells", tmp_path / "cells")
    cell = tmp_path / "cells" / "rivet_cell.xml"
    cell.write_text(cell.read_text(encoding="utf-8").replace('name="drill_4" xyz="0.0 -0.06 0.0"', 'name="drill_4" xyz="0.0 0.5 0.0"'), encoding="utf-8")
    app = tmp_path / "far.xml"
    app.write_text("<application name='far' robot='nextage' cell='cells/rivet_cell.xml'><operation id='1'><right_arm>"
                   "<function name='approach'><params><param value='drill_4'/></params></function></right_arm></operation></application>", encoding="utf-8")
    code, _, err = cli("validate", "--simulate", str(app))
    found = [f for finding in dry_run_of(app).findings if (f := dry_run_finding(finding)) is not None]
    assert code == 1 and found and found[0]["kind"] == "unreachable", err
    hole = load_cell(cell).pose("drill_4")
    assert found[0]["target"][:2] == pytest.approx([hole.x, hole.y], abs=1e-3) and found[0]["target"][2] > hole.z  # above the hole it approaches


def test_a_runs_collision_fault_is_placed_at_its_time(tmp_path: Path) -> None:
    """Without the dry run the simulator's own check stops the arm: the error record names both hands, at its time."""
    shutil.copytree(APPS / "cells", tmp_path / "cells")
    app = tmp_path / "meet.xml"
    app.write_text("<application name='meet' robot='nextage' cell='cells/rivet_cell.xml'><operation id='1'>"
                   "<left_arm><function name='approach'><params><param value='drill_2'/></params></function></left_arm>"
                   "<right_arm><function name='approach'><params><param value='drill_2'/></params></function></right_arm>"
                   "</operation></application>", encoding="utf-8")
    trace = tmp_path / "meet.jsonl"
    code, _, _ = cli("run", str(app), "--no-check", "--speed", "max", "--trace", str(trace), "-q")
    errors = [r for line in trace.read_text(encoding="utf-8").splitlines() if (r := json.loads(line))["event"] == "error"]
    placed = [f for r in errors if (f := run_finding(r)) is not None]
    assert code == 1 and placed, errors
    assert {b["name"] for b in placed[0]["bodies"]} == {"LARM_JOINT5_Link", "RARM_JOINT5_Link"} and placed[0]["t"] == errors[0]["t"]


LINK = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,20}(/[A-Za-z0-9_]{1,20})?", fullmatch=True)


@given(st.sampled_from(["left_arm", "right_arm", "arm"]), LINK, st.sampled_from(["right_arm", "cell", "robot"]), LINK, st.booleans())
def test_collision_labels_give_back_their_bodies(owner_a: str, link_a: str, owner_b: str, link_b: str, hand: bool) -> None:
    label_a = f"{owner_a} hand ({link_a})" if hand else f"{owner_a} {link_a}"
    text = f"collision between {label_a} and {owner_b} {link_b}, against right_arm approach of operation 2 (line 6)"
    bodies = collision_bodies(text)
    assert bodies is not None and (bodies[0].owner, bodies[0].name, bodies[1].owner, bodies[1].name) == (owner_a, link_a, owner_b, link_b)


@given(st.text(max_size=300))
def test_any_text_is_a_placed_finding_or_none(text: str) -> None:
    for found in (run_finding({"event": "error", "t": 1.0, "error": text}),):
        assert found is None or (found["kind"] in ("collision", "unreachable", "joint_limit", "singularity") and ("bodies" in found or "target" in found))


# ------------------------------------------------------------------ routes
def test_the_routes_serve_the_start_files_scene_and_refuse_bad_input(tmp_path: Path) -> None:
    app = arms_meet(tmp_path)
    client = client_for(build_station(station_args(file=app.name), full_catalog(), tmp_path))
    scene = client.get("/api/scene3d").json()
    assert scene["ok"] and scene["mode"] == "idle" and [r["model"] for r in scene["robots"]] == ["nextage_open"] and scene["findings"] == []
    assert {f["name"] for f in scene["cell"]["frames"]} >= {"part", "drill_1", "rivet_tray", "hands_left"}
    events = client.get("/api/scene3d/events").json()
    assert events == {"ok": True, "run": scene["run"], "from": 0, "events": [], "total": 0}
    for bad, said in (("x1", "from must be a whole number of events, got 'x1'"), ("-3", "from must be in [0, 1099511627776], got -3")):
        answer = client.get(f"/api/scene3d/events?from={bad}")
        assert answer.status_code == 400 and answer.json() == {"ok": False, "error": said}


# ------------------------------------------------------------------ a live run's scene, from its transport
def test_a_live_cell_of_two_robots_gives_the_view_its_joints_goals_located_frames_and_cell(run_sim: Any) -> None:
    """Each robot's bridge publishes its own joints: the page gets one sample of both once each has spoken; a goal
    sent to the KUKA's bridge, the frames the Nextage's arm located and the engine's cell reach the 3D view's scene."""
    cell = load_cell(APPS / "examples" / "cells" / "mixed_cell.xml")
    robot = cell_robot_model(cell.name, cell.robots)
    feed = Feed()
    feed.begin("live", "mixed", list(robot.group_names))
    target = Pose.from_xyz_rpy(0.33, -0.26, 0.08, math.pi, 0, math.pi / 2)

    async def main(clock: Clock) -> None:
        transport = LocalTransport(clock)
        node, sender = transport.create_node("operator_station"), transport.create_node("cell")
        observe(node, robot, feed, [])
        joints = sender.create_publisher(JointState, JOINT_STATES, SENSOR)
        for member in cell.robots:  # each bridge its own robot's joints
            names = member.model.joint_names
            joints.publish(JointState(name=tuple(names), position=tuple(0.01 * k for k in range(len(names)))))
            await asyncio.sleep(0.2)
        TypedPublisher(sender, BridgeCommand, bridge_topic("arm", "command"), COMMANDS).publish(
            BridgeCommand("c1", "arm", "execute", MoveCartesian(target, "ptp", "buffer_slot approach")))
        TypedPublisher(sender, LocatedFrames, sm_topic("right_arm", "located"), LATCHED).publish(
            LocatedFrames("right_arm", cell.name, {"buffer_slot": target}, clock.now()))
        TypedPublisher(sender, CellSnapshot, ENGINE_CELL, LATCHED).publish(cell.to_snapshot(robot))
        await asyncio.sleep(0.2)
        node.destroy()
        sender.destroy()

    run_sim(main)
    order = list(robot.joint_names)
    expected = {n: 0.01 * k for m in cell.robots for k, n in enumerate(m.model.joint_names)}
    assert feed.snapshot.joint_names == order and len(feed.joints) == 1 and list(feed.joints)[0][1:] == [expected[n] for n in order]
    scene = scene_log(feed)
    goal = next(e for e in scene.events if e["event"] == "goal")
    assert (goal["group"], goal["kind"], goal["label"], goal["t"]) == ("arm", "pose", "buffer_slot approach", pytest.approx(0.4, abs=1e-6))
    assert goal["target"] == pytest.approx([target.x, target.y, target.z, target.qx, target.qy, target.qz, target.qw])
    assert [e["frames"] for e in scene.events if e["event"] == "located"] == [{"buffer_slot": pytest.approx(goal["target"])}]
    assert scene.cell is not None and {f["name"] for f in scene.cell["frames"]} == set(cell.frames) | set(cell.zones)
    assert [r["name"] for r in scene.robots] == ["feeder", "assembler"]


# ------------------------------------------------------------------ recordings
def recorded_joint_states(path: Path) -> list[tuple[int, dict[str, float]]]:
    """Every JointState of a recording, read with the MCAP libraries directly: (header stamp ns, name -> position)."""
    out = []
    with open(path, "rb") as stream:
        for _, channel, _, msg in make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=["/joint_states"]):
            out.append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec, dict(zip(msg.name, msg.position))))
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("recorded")
    return record(folder, demonstrator(folder, "rivet_first_three", 3))


def test_a_recordings_scene_is_its_messages(recording: Path) -> None:
    scene = read_scene(recording)
    states = recorded_joint_states(recording)
    assert scene.notes == [] and scene.robot is NEXTAGE_OPEN and scene.cell is not None and scene.cell["name"] == "rivet_cell"
    assert len(scene.samples) == len(states) > 50
    first = states[0][0]
    for row, (stamp, values) in zip(scene.samples, states):
        assert row[0] == pytest.approx((stamp - first) * 1e-9, abs=1e-6)  # run time: the first state is at run time 0
        assert dict(zip(scene.joint_names, row[1:])) == values
    goals = [e for e in scene.events if e["event"] == "goal"]
    assert {g["group"] for g in goals} == {"left_arm", "right_arm", "torso_head"}
    assert [g["label"] for g in goals if g["group"] == "left_arm" and g["kind"] == "pose"][0] == "drill_1 clearance"
    located = [e for e in scene.events if e["event"] == "located" and e["frames"]]
    assert located and set(located[-1]["frames"]) == {"drill_1"}  # what the left arm's camera found, measured


def test_a_replay_serves_the_recordings_joint_states_and_scene(recording: Path, tmp_path: Path) -> None:
    station = build_station(station_args(replay=str(recording)), full_catalog(), tmp_path)
    scene = read_scene(recording)
    log = scene_log(station.feed)
    assert log.run == station.feed.snapshot.run and log.events == scene.events and log.robots[0]["model"] == "nextage_open"
    client = client_for(station)
    served = client.get("/api/scene3d").json()
    assert served["mode"] == "replay" and served["recorded_joints"] == len(scene.samples) and served["cell"] == scene.cell
    joints = client.get("/api/scene3d/joints?from=10").json()
    assert joints["names"] == scene.joint_names and joints["total"] == len(scene.samples) and joints["samples"] == scene.samples[10:]
    assert client.get("/api/scene3d/events").json()["events"] == scene.events


def test_a_cut_recording_gives_what_came_before_the_cut(recording: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = recording.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    scene = read_scene(cut)
    whole = read_scene(recording)
    assert 0 < len(scene.samples) < len(whole.samples) and scene.samples == whole.samples[: len(scene.samples)]
    text = tmp_path / "notes.mcap"
    text.write_text("not a recording\n", encoding="utf-8")
    with pytest.raises(NotARecording) as refused:
        read_scene(text)
    assert "notes.mcap" in str(refused.value) and "\n" not in str(refused.value)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(1, 255)), min_size=1, max_size=6), keep=st.floats(0.05, 1.0))
def test_a_damaged_recording_gives_a_scene_or_one_line(recording: Path, tmp_path: Path, flips: list[tuple[float, int]], keep: float) -> None:
    """Bytes flipped anywhere, the tail cut: the scene of what could be read, or NotARecording/OverLimit in one line --
    never another exception, never a value that is not a finite number among the joints drawn."""
    data = bytearray(recording.read_bytes())
    for where, xor in flips:
        data[int(where * (len(data) - 1))] ^= xor
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data[: max(1, int(len(data) * keep))]))
    try:
        scene = read_scene(damaged)
    except (NotARecording, OverLimit) as refused:
        assert "\n" not in str(refused) and "damaged.mcap" in str(refused)
        return
    for row in scene.samples:
        assert len(row) == len(scene.joint_names) + 1 and all(isinstance(x, float) for x in row)
        assert all(math.isfinite(x) for x in row[1:] if not math.isnan(x))  # a joint not reported yet is NaN, never inf
    assert all(e["event"] in ("goal", "located") and math.isfinite(e["t"]) for e in scene.events)
