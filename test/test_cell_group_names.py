"""A cell of two robots whose models share a group name (issue 23 item 4): the cell names each robot's groups and
joints for itself (``<robot prefix>``, ``<group name as>``), and everything downstream speaks those names.

apps_xml/examples/side_by_side.xml: a KUKA KR 6 (group ``arm``, joints A1..A6) as ``kuka_arm`` / ``kuka_A1``.., and
an Adept Viper s850 (group ``arm``, joints joint_1..6) as ``inspector`` / ``viper_joint_1``...  Here: the model the
application, the machines and the studio see; the bridges' per-group command topics, FollowJointTrajectory actions
and /joint_states of both robots on one bus (an independent client, simulated time); the collision model; what
``launch`` tells each node.  The example's dry run and run: test_cell_group_names_run.py.
"""
from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import given, strategies as st
from cell_group_names_files import NAMED_FILES
from fjt_client import FJT, RSI, VPLUS, Arm, Kind, goal, make_backend, three_points

from cell_runner.cli import main
from cell_runner.launcher import cell_nodes
from app_functions.registry import full_catalog
from core_functions.cell_robots import CellNames, CellRobotModel, named_model
from core_functions.geometry import Pose
from core_functions.primitives import MotionResult, MoveJoints
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR
from execution_engine.app_model import load_application, validate_application
from node_transport.action import GoalStatus
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.port import poll_until
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.collision.robots import cell_urdf
from robot_bridges.placed import PlacedBackend
from operator_station.scene3d import robot_views

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "apps_xml" / "examples" / "side_by_side.xml"
KUKA_NAMES = CellNames("kuka_")
VIPER_NAMES = CellNames("viper_", (("arm", "inspector"),))
VIPER_BASE = Pose.from_xyz_rpy(1.5, 0.0, 0.0, 0.0, 0.0, math.pi)
BOUND = 30.0


def test_the_application_s_robot_has_the_groups_joints_and_poses_the_cell_names() -> None:
    app = load_application(EXAMPLE, full_catalog())
    robot = app.robot
    assert isinstance(robot, CellRobotModel)
    assert robot.group_names == ("kuka_arm", "inspector")
    assert robot.group("kuka_arm").joint_names == tuple(f"kuka_A{i}" for i in range(1, 7))
    assert robot.group("inspector").joint_names == tuple(f"viper_joint_{i}" for i in range(1, 7))
    assert robot.member_of("inspector").name == "checker" and robot.member_of("kuka_arm").name == "loader"
    assert robot.member_of("inspector").model is ADEPT_VIPER_S850  # its back end is built from the robot's own model
    assert robot.poses["home"]["viper_joint_2"] == ADEPT_VIPER_S850.poses["home"]["joint_2"]
    assert robot.poses["home"]["kuka_A3"] == KUKA_KR.poses["home"]["A3"]
    assert {c.group for op in app.operations for c in op.calls.values()} == {"kuka_arm", "inspector"}
    assert CellNames.parse(VIPER_NAMES.text()) == VIPER_NAMES and CellNames.parse("") == CellNames()


def test_launch_tells_each_bridge_and_machine_the_cell_s_names() -> None:
    """Every node of ``launch`` hears the names: a bridge serves its groups under them, a machine drives its group
    with its robot's model under them (the model's own name still finds the robot)."""
    specs = {spec.name: " ".join(spec.argv) for spec in cell_nodes(EXAMPLE, "dds", 1.0)}
    assert set(specs) >= {"loader_bridge", "checker_bridge", "kuka_arm_machine", "inspector_machine"}
    assert "cell_names:=prefix=kuka_" in specs["loader_bridge"] and "cell_names:=prefix=kuka_" in specs["kuka_arm_machine"]
    assert "cell_names:=prefix=viper_;arm=inspector" in specs["checker_bridge"]
    assert "group:=inspector" in specs["inspector_machine"] and "robot:=adept_viper_s850" in specs["inspector_machine"]
    machine_model = named_model(ADEPT_VIPER_S850, CellNames.parse("prefix=viper_;arm=inspector"))
    assert machine_model.group_names == ("inspector",) and machine_model.name == ADEPT_VIPER_S850.name


def test_the_collision_model_and_the_3d_view_name_the_joints_and_tcps_as_the_cell_does() -> None:
    robot = load_application(EXAMPLE, full_catalog()).robot
    assert isinstance(robot, CellRobotModel)
    urdf, tcps = cell_urdf(robot)
    assert set(tcps) == {"kuka_arm", "inspector"}
    assert 'name="kuka_A1"' in urdf and 'name="viper_joint_6"' in urdf and 'name="A1"' not in urdf and 'name="joint_1"' not in urdf
    views, notes = robot_views(robot)
    assert not notes
    by_name = {v.name: v for v in views}
    assert by_name["checker"].joint_prefix == "viper_" and set(by_name["checker"].tcps) == {"inspector"}
    assert by_name["checker"].joints[0] == "viper_joint_1" and "viper_joint_2" in by_name["checker"].rest


class RobotArm(Arm):
    """The client's view of one robot of the cell: /joint_states carries both robots' messages, each its own joints."""

    def joints(self) -> np.ndarray:
        where = next(state for _, state in reversed(self.states) if self.kind.joints[0] in state)
        return np.array([where[n] for n in self.kind.joints])


async def _named(kind: Kind, clock: Clock, base: Pose, robot: str, names: CellNames, bus: LocalTransport) -> BridgeNode:
    bridge = BridgeNode(bus.create_node(f"{robot}_bridge"), PlacedBackend(await make_backend(kind, clock), base, robot, names))
    await bridge.start()
    return bridge


def test_two_robots_with_one_group_name_serve_their_cell_groups_side_by_side(run_sim: Any) -> None:
    """A Viper and a KUKA, each bridge on the one bus: FollowJointTrajectory at /kuka_arm_controller/... and
    /inspector_controller/... (none at /arm_controller), /joint_states with both robots' joints under the cell's
    names, a goal on each moving only that robot; a goal naming the robot's own joint (joint_1) is refused as an
    unknown joint; a primitive on the cell's group name with the cell's joint names reaches the right robot."""
    kuka_kind = Kind("rsi", "kuka_arm_controller", tuple(f"kuka_{j}" for j in RSI.joints))
    viper_kind = Kind("vplus", "inspector_controller", tuple(f"viper_{j}" for j in VPLUS.joints))

    async def main(clock: Clock) -> dict[str, Any]:
        bus = LocalTransport(clock)
        kuka = await _named(RSI, clock, Pose(), "loader", KUKA_NAMES, bus)
        viper = await _named(VPLUS, clock, VIPER_BASE, "checker", VIPER_NAMES, bus)
        try:
            kuka_arm = RobotArm(bus.create_node("client_kuka"), kuka_kind, clock)
            viper_arm = RobotArm(bus.create_node("client_viper"), viper_kind, clock)
            await kuka_arm.ready(BOUND)
            await viper_arm.ready(BOUND)
            assert await poll_until(clock, lambda: all(any(a.kind.joints[0] in s for _, s in a.states) for a in (kuka_arm, viper_arm)), BOUND, 0.01)
            old = Arm(bus.create_node("client_old"), Kind("old", "arm_controller", VPLUS.joints), clock)
            no_arm_controller = await old.client.send.wait_for_service(0.5)
            names_seen = set().union(*(set(state) for _, state in viper_arm.states))
            kuka_start, viper_start = kuka_arm.joints(), viper_arm.joints()
            kuka_done = await kuka_arm.run(goal(kuka_kind.joints, three_points(kuka_start, (0.1, 0.05, -0.05, 0.0, 0.1, 0.0))), BOUND)
            await clock.sleep(0.2)
            viper_still = viper_arm.joints()
            viper_done = await viper_arm.run(goal(viper_kind.joints, three_points(viper_start, (0.1, 0.05, -0.1, 0.0, -0.1, 0.0))), BOUND)
            await clock.sleep(0.2)
            own_names = await viper_arm.run(goal(VPLUS.joints, [(1.0, viper_arm.joints())]), BOUND)
            target = tuple(float(v) for v in viper_arm.joints() - 0.05)
            moved = await viper.backend.execute("inspector", MoveJoints(target, joint_names=viper_kind.joints))
            limits = viper.backend.joint_limits("inspector")
            return dict(no_arm_controller=no_arm_controller, names=names_seen, kuka_done=kuka_done, viper_done=viper_done,
                        kuka_moved=kuka_arm.joints() - kuka_start, viper_still=viper_still - viper_start,
                        viper_moved=viper_arm.joints() - viper_start, own_names=own_names, target=target, moved=moved,
                        limits=limits, groups=(kuka.backend.groups, viper.backend.groups))
        finally:
            await viper.close()
            await kuka.close()

    got = run_sim(main)
    assert got["groups"] == (("kuka_arm",), ("inspector",))
    assert not got["no_arm_controller"], "a bridge serves the model's own group name"
    assert set(kuka_kind.joints) | set(viper_kind.joints) <= got["names"]
    assert not got["names"] & {"A1", "joint_1"}, got["names"]
    for done in (got["kuka_done"], got["viper_done"]):
        assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.error_code == FJT.Result.SUCCESSFUL, done.result.error_string
    assert np.allclose(got["kuka_moved"], np.array((0.1, 0.05, -0.05, 0.0, 0.1, 0.0)) * 3, atol=2e-3)
    assert np.allclose(got["viper_still"], 0.0, atol=1e-9)  # the KUKA's goal never moved the Viper
    refused = got["own_names"].result
    assert refused.error_code == FJT.Result.INVALID_JOINTS and "joint 'joint_1' is not one of the group's joints (viper_joint_1" in refused.error_string
    moved = got["moved"]
    assert isinstance(moved, MotionResult) and moved.joint_names == viper_kind.joints
    assert np.allclose(moved.positions, got["target"], atol=1e-6)
    assert got["limits"].joint_names == viper_kind.joints


def _problems(tmp_path: Path, robots: str, body: str) -> list[str]:
    (tmp_path / "cell.xml").write_text(f'<?xml version="1.0"?>\n<cell name="named">\n{robots}</cell>\n', encoding="utf-8")
    app = tmp_path / "app.xml"
    app.write_text(f'<?xml version="1.0"?>\n<application name="named" robot="cell" cell="cell.xml">\n{body}</application>\n', encoding="utf-8")
    return [f"{Path(d.file).name}:{d.line}:{d.col}: {d.message}" for d in validate_application(app, full_catalog())]


WAIT = '<function name="wait"><params><param value="0.1"/></params></function>'


def test_an_application_on_a_cell_s_group_names_is_checked_element_by_element(tmp_path: Path) -> None:
    """The schema with the cell's groups added says of a cell group what it says of a model's: two functions in one."""
    robots = '  <robot name="checker" model="viper" xyz="0 0 0" rpy="0 0 0"><group name="arm" as="inspector"/></robot>\n'
    assert _problems(tmp_path, robots, f'  <operation id="1"><inspector>{WAIT}</inspector></operation>\n') == []
    assert _problems(tmp_path, robots, f'  <operation id="1"><inspector>{WAIT}{WAIT}</inspector></operation>\n') == [
        "app.xml:3:102: <function> is not allowed here inside <inspector> (a group runs exactly one <function> per operation; put the next one in a new <operation>)",
    ]


def test_a_robot_s_groups_named_twice_or_onto_one_name_are_refused_at_their_line(tmp_path: Path) -> None:
    body = f'  <operation id="1"><arms>{WAIT}</arms></operation>\n'
    twice = ('  <robot name="twins" model="nextage" xyz="0 0 0" rpy="0 0 0">\n    <group name="left_arm" as="arms"/>\n'
             '    <group name="left_arm" as="hands"/>\n  </robot>\n')
    assert "cell.xml:5:12: robot 'twins': group 'left_arm' is named twice" in _problems(tmp_path, twice, body)
    onto_one = ('  <robot name="twins" model="nextage" xyz="0 0 0" rpy="0 0 0">\n    <group name="left_arm" as="arms"/>\n'
                '    <group name="right_arm" as="arms"/>\n  </robot>\n')
    assert "cell.xml:5:29: robot 'twins': its groups 'left_arm' and 'right_arm' would both be 'arms' in the cell" in _problems(tmp_path, onto_one, body)


def test_a_cell_with_a_name_clash_is_the_one_problem_told(tmp_path: Path) -> None:
    """The cell's error is reported at its line; the application naming the groups that cell gives is not also told
    that they do not exist (the groups are read from the cell file as written)."""
    for name in ("cg_taken_cell.xml", "cg_taken.xml"):
        (tmp_path / name).write_text(NAMED_FILES[name], encoding="utf-8")
    problems = [f"{Path(d.file).name}:{d.line}: {d.message}" for d in validate_application(tmp_path / "cg_taken.xml", full_catalog())]
    assert len(problems) == 2 and problems[1].startswith("cg_taken_cell.xml:4: robot 'checker': group 'kuka_arm' (its 'arm' renamed)"), problems
    assert "has errors" in problems[0]


_name = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,12}", fullmatch=True)


@given(prefix=st.one_of(st.just(""), _name), renamed=st.dictionaries(_name.filter(lambda n: n != "prefix"), _name, max_size=4))
def test_the_names_launch_passes_to_a_node_read_back_as_written(prefix: str, renamed: dict[str, str]) -> None:
    names = CellNames(prefix, tuple(renamed.items()))
    assert CellNames.parse(names.text()) == names


@given(text=st.text(max_size=200))
def test_a_cell_names_parameter_is_read_or_refused_in_one_line(text: str) -> None:
    """Whatever a parameter holds: names, or ValueError naming the entry (a bridge's one-line start-up error)."""
    try:
        names = CellNames.parse(text)
    except ValueError as error:
        assert str(error).startswith("cell names: ") and "\n" not in str(error)
    else:
        assert isinstance(names, CellNames)


@given(joints=st.lists(_name, max_size=8).map(tuple))
def test_a_robot_s_joints_go_out_under_the_cell_s_names_and_come_back_as_its_own(joints: tuple[str, ...]) -> None:
    placed = PlacedBackend.__new__(PlacedBackend)  # the naming alone; no back end behind it
    placed.names = CellNames("viper_")
    assert placed.own_joints(placed.cell_joints(joints)) == joints
    assert all(j.startswith("viper_") for j in placed.cell_joints(joints))


def test_two_robots_of_one_model_share_a_cell_by_their_prefixes(tmp_path: Path) -> None:
    """Two Nextages (every group and joint name the same) side by side, prefixes w_ and e_: the dry run (the
    simulator's own planned paths, told the cell's names, swept in one collision model) and the run in simulated
    time; each motion's joints are its robot's, under its prefix."""
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "nn.xml").write_text(
        '<?xml version="1.0"?>\n<cell name="nn">\n'
        '  <robot name="west" model="nextage" xyz="0 0 0" rpy="0 0 0" prefix="w_"/>\n'
        '  <robot name="east" model="nextage" xyz="0 1.5 0" rpy="0 0 0" prefix="e_"/>\n'
        '  <joint_pose name="w_ready" group="w_left_arm" unit="deg" joints="0.6 0 -100 -15.2 9.4 -3.2"/>\n</cell>\n', encoding="utf-8")
    app = tmp_path / "nn.xml"
    app.write_text(
        '<?xml version="1.0"?>\n<application name="nn" robot="cell" cell="cells/nn.xml">\n  <operation id="1">\n'
        '    <w_left_arm><function name="move_joints"><params><param value="10 0 -100 -15.2 9.4 -3.2 deg"/></params></function></w_left_arm>\n'
        '    <e_left_arm><function name="move_joints"><params><param value="10 0 -100 -15.2 9.4 -3.2 deg"/></params></function></e_left_arm>\n'
        '  </operation>\n  <operation id="2">\n'
        '    <w_left_arm><function name="move_to_joint_pose"><params><param value="w_ready"/></params></function></w_left_arm>\n'
        '  </operation>\n</application>\n', encoding="utf-8")
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "--speed", "max", "-q", "--trace", str(trace), "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 0, out.getvalue() + err.getvalue()
    assert "application nn: FINISHED" in out.getvalue()
    ends = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines() if '"primitive_end"' in line]
    moved = {r["group"]: r["result"]["joint_names"] for r in ends if r["result"].get("joint_names")}
    assert moved["w_left_arm"] == [f"w_LARM_JOINT{i}" for i in range(6)] and moved["e_left_arm"] == [f"e_LARM_JOINT{i}" for i in range(6)]
