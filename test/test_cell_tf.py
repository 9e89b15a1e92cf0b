"""The cell's frames on tf_static: nominal at the start of a run, corrected when vision locates them.

Three levels: the engine's broadcaster fed with hand-made ``located`` reports (a located parent
moves its children; a late joiner sees only the corrected set), a machine reporting what its
skills located, and the rivet demonstrator end to end on the Nextage simulator, where robot
links and cell frames must form one tf tree rooted at the robot's ``WAIST``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from machine_harness import CELL, Harness
from scripted_backend import VISION_OFFSET

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from core_functions.geometry import Pose
from core_functions.robots import NEXTAGE_OPEN
from core_functions.urdf_tree import UrdfTree
from execution_engine.app_model import load_application
from execution_engine.engine.cell_tf import CellFramesBroadcaster
from node_transport import typed
from node_transport.clock import Clock, run_with_clock, simulated_clock
from node_transport.local import LocalTransport
from node_transport.msgs import TFMessage, Time
from node_transport.port import Node
from node_transport.qos import LATCHED, TF, TF_STATIC
from node_transport.transforms import compose_to_root, tree_of
from node_transport.wire import ENGINE_CELL, TF_STATIC_TOPIC, TF_TOPIC, CellSnapshot, LocatedFrames, sm_topic
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
URDF = ROOT / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf"
TOL = 1e-9


def rivet_cell() -> CellSnapshot:
    app = load_application(RIVET, full_catalog())
    assert app.cell is not None
    return app.cell.to_snapshot()


def world_poses(message: TFMessage) -> dict[str, tuple[str, Pose]]:
    """Each child frame of one message with (root, pose in the root)."""
    tree = tree_of(message.transforms)
    return {child: compose_to_root(tree, child) for child in tree}


def collect(node: Node, topic: str, qos: Any, into: list[Any], msg_type: type = TFMessage) -> None:
    node.create_subscription(msg_type, topic, into.append, qos)


def same(a: Pose, b: Pose, tol: float = TOL) -> bool:
    return a.distance_to(b) < tol and a.angle_to(b) < 1e-6


# ================================================================ the engine's broadcaster
def test_a_located_parent_moves_its_children_and_a_late_joiner_sees_only_the_corrected_set(run_sim: Any) -> None:
    snapshot = rivet_cell()
    nominal = {f.name: f.pose for f in snapshot.frames}
    moved_part = Pose.from_xyz_rpy(0.345, 0.004, 0.002, 0.0, 0.0, 0.02)
    found_rivet = nominal["rivet_2"].translated(dx=0.0007)

    async def main(clock: Clock) -> tuple[list[TFMessage], list[TFMessage], float]:
        transport = LocalTransport(clock)
        broadcaster = CellFramesBroadcaster(transport.create_node("execution_engine"))
        early: list[TFMessage] = []
        collect(transport.create_node("rviz"), TF_STATIC_TOPIC, TF_STATIC, early)
        broadcaster.publish_cell(snapshot, NEXTAGE_OPEN)
        await clock.sleep(0.5)
        machine = transport.create_node("left_arm_machine")
        located = {g: machine.create_publisher(typed.LocatedFramesMsg, sm_topic(g, "located"), LATCHED) for g in ("left_arm", "right_arm")}
        located["left_arm"].publish(typed.to_msg(LocatedFrames("left_arm", snapshot.name, {"part": moved_part}), clock))
        await clock.sleep(0.5)
        located["right_arm"].publish(typed.to_msg(LocatedFrames("right_arm", snapshot.name, {"rivet_2": found_rivet, "nowhere": Pose()}), clock))
        await clock.sleep(0.5)
        located["right_arm"].publish(typed.to_msg(LocatedFrames("right_arm", "another_cell", {"rivet_3": Pose()}), clock))
        await clock.sleep(0.5)
        late: list[TFMessage] = []
        collect(transport.create_node("late_rviz"), TF_STATIC_TOPIC, TF_STATIC, late)
        await clock.sleep(0.1)
        return early, late, clock.epoch_now()

    early, late, epoch_end = run_sim(main)
    assert len(early) == 3  # nominal, part located, rivet located; another cell's report changes nothing
    first = world_poses(early[0])
    assert set(first) == set(nominal) and all(root == "WAIST" for root, _ in first.values())
    assert all(same(first[name][1], pose) for name, pose in nominal.items())
    parents = {t.child_frame_id: t.header.frame_id for t in early[0].transforms}
    assert parents["part"] == "WAIST" and parents["drill_1"] == "part" and parents["rivet_1"] == "rivet_tray"

    assert len(late) == 1 and late[0] == early[-1]  # the last set only: nothing nominal after a correction
    final = world_poses(late[0])
    assert same(final["part"][1], moved_part)
    shift = moved_part.compose(nominal["part"].inverse())
    for hole in ("drill_1", "drill_2", "drill_3", "drill_4"):  # children follow their located parent
        assert same(final[hole][1], shift.compose(nominal[hole]))
        assert not same(final[hole][1], nominal[hole], 1e-3)
        assert tree_of(late[0].transforms)[hole][0] == "part"  # still hung from their parent
    assert same(final["rivet_2"][1], found_rivet)
    assert same(final["rivet_1"][1], nominal["rivet_1"]) and same(final["rivet_tray"][1], nominal["rivet_tray"])
    stamp = late[0].transforms[0].header.stamp
    assert 0.0 < epoch_end - stamp.to_seconds() < 1.6  # the node's ROS time when the last report came in


# ==================================================================== the machine's reports
def test_a_machine_reports_every_frame_it_located_in_its_cell(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[LocatedFrames]:
        h = await Harness(clock).start()
        reports: list[LocatedFrames] = []
        viewer = h.transport.create_node("viewer")
        viewer.create_subscription(typed.LocatedFramesMsg, sm_topic("left_arm", "located"), lambda m: reports.append(typed.from_msg(LocatedFrames, m, clock)), LATCHED)
        try:
            await clock.sleep(0.1)
            result = await h.result(h.send("left_arm", "locate", "hole_1"))
            assert result.outcome == "succeeded", result.error
            h.cell_pub.publish(typed.to_msg(CELL, clock))  # a new run: the cell model again
            await clock.sleep(0.1)
            return reports
        finally:
            await h.close()

    reports = run_sim(main)
    assert [(r.group, r.cell, sorted(r.frames)) for r in reports] == [
        ("left_arm", "test_cell", []),  # the cell model arrived: nothing located yet
        ("left_arm", "test_cell", ["hole_1"]),
        ("left_arm", "test_cell", []),  # a new cell model starts nominal again
    ]
    nominal = next(f.pose for f in CELL.frames if f.name == "hole_1")
    assert same(reports[1].frames["hole_1"], nominal.translated(dx=VISION_OFFSET))


# ================================================================ the demonstrator, end to end
@pytest.fixture(scope="module")
def rivet_run() -> dict[str, Any]:
    async def main(clock: Clock) -> dict[str, Any]:
        app = load_application(RIVET, full_catalog())
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
        viewer = deployment.transport.create_node("rviz")
        static: list[TFMessage] = []
        collect(viewer, TF_STATIC_TOPIC, TF_STATIC, static)
        located: list[LocatedFrames] = []
        for group in app.robot.arm_groups:
            viewer.create_subscription(typed.LocatedFramesMsg, sm_topic(group, "located"), lambda m: located.append(typed.from_msg(LocatedFrames, m, clock)), LATCHED)
        cells: list[Any] = []
        collect(viewer, ENGINE_CELL, LATCHED, cells, typed.CellSnapshotMsg)
        try:
            report = await deployment.engine.run(app)
            late = deployment.transport.create_node("late_rviz")
            late_static: list[TFMessage] = []
            late_tf: list[TFMessage] = []
            collect(late, TF_STATIC_TOPIC, TF_STATIC, late_static)
            collect(late, TF_TOPIC, TF, late_tf)
            await clock.sleep(0.2)
        finally:
            await deployment.close()
        assert report.ok, report
        snapshot = typed.from_msg(CellSnapshot, cells[-1], clock)
        return {"static": static, "located": located, "late_static": late_static, "late_tf": late_tf, "cell": snapshot}

    return run_with_clock(main, simulated_clock())


def test_vision_corrections_in_the_demonstrator_move_the_published_holes(rivet_run: dict[str, Any]) -> None:
    snapshot: CellSnapshot = rivet_run["cell"]
    nominal = {f.name: f.pose for f in snapshot.frames}
    static = rivet_run["static"]
    assert all(root == "WAIST" for root, _ in world_poses(static[0]).values())
    assert all(same(world_poses(static[0])[n][1], p) for n, p in nominal.items())  # the run starts nominal
    measured: dict[str, Pose] = {}
    for report in rivet_run["located"]:  # in arrival order: the newest measurement of a frame counts
        measured.update(report.frames)
    assert set(measured) == {"drill_1", "drill_2", "drill_3", "drill_4"}
    final = world_poses(static[-1])
    for hole, pose in measured.items():
        assert same(final[hole][1], pose, 1e-7)
        assert final[hole][1].distance_to(nominal[hole]) > 2e-4  # vision moved it (holes are 0.3-0.6 mm off)
        history = [world_poses(m)[hole][1] for m in static]
        assert same(history[0], nominal[hole]) and len({(p.x, p.y) for p in history}) >= 2
    for name in set(nominal) - set(measured):
        assert same(final[name][1], nominal[name])


def test_a_late_joiner_gets_only_the_corrected_cell_and_one_tree_with_the_robot(rivet_run: dict[str, Any]) -> None:
    late = rivet_run["late_static"]
    assert len(late) == 1  # one sender of the cell's frames (the Nextage URDF has no fixed joint)
    assert late[0] == rivet_run["static"][-1]
    tree = tree_of([*late[0].transforms, *rivet_run["late_tf"][-1].transforms])
    frames = set(UrdfTree(URDF.read_text(encoding="utf-8")).links) | {f.name for f in rivet_run["cell"].frames}
    for frame in frames:
        assert compose_to_root(tree, frame)[0] == "WAIST", frame
    assert isinstance(late[0].transforms[0].header.stamp, Time)
