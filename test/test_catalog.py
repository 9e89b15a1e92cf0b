"""The catalog: typed params parsed with units, ranges, robot joints and the cell; functions found by name."""
from __future__ import annotations

import math

import pytest

from app_functions.registry import LIBRARIES, full_catalog, functions_class
from core_functions.catalog import BindContext, Catalog, ParamSpec, ParamType, skill
from core_functions.cell_index import CellFrame, CellIndex
from core_functions.functions import CoreFunctions
from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN, find_robot

CELL = CellIndex(
    "c",
    [CellFrame("drill_1", Pose(0.3, 0, 0), "hole"), CellFrame("tray", Pose(0.2, -0.2, 0), "tray")],
    {"ref_R10": {"kind": "rivet"}},
    {"safe": {"CHEST_JOINT0": 0.0}},
)
CTX = BindContext(NEXTAGE_OPEN, "left_arm", CELL)


def spec(name: str) -> ParamSpec:
    return ParamSpec(name, ParamType.NUMBER, "", unit=name)


@pytest.mark.parametrize(
    ("unit", "text", "value"),
    [("m", "0.25", 0.25), ("m", "25mm", 0.025), ("m", "2.5 cm", 0.025), ("rad", "90deg", math.pi / 2), ("rad", "1.5", 1.5),
     ("s", "250ms", 0.25), ("fraction", "50%", 0.5), ("fraction", ".5", 0.5), ("m", "-1e-3", -0.001)],
)
def test_numbers_take_units_of_their_family(unit: str, text: str, value: float) -> None:
    assert spec(unit).parse(text, CTX) == pytest.approx(value)


@pytest.mark.parametrize(("unit", "text", "message"), [("m", "10deg", "unit 'deg' does not fit"), ("m", "ten", "is not a number"), ("s", "1e400", "not a finite number"), ("m", "", "is not a number")])
def test_bad_numbers_say_why(unit: str, text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        spec(unit).parse(text, CTX)


def test_joints_are_counted_and_checked_against_the_robot_limits() -> None:
    joints = ParamSpec("joints", ParamType.JOINTS, "")
    assert joints.parse("0 -30 -100 15 9 3 deg", CTX) == pytest.approx(tuple(math.radians(v) for v in (0, -30, -100, 15, 9, 3)))
    with pytest.raises(ValueError, match="5 joint values for left_arm, which has 6 joints"):
        joints.parse("0 0 0 0 0", CTX)
    with pytest.raises(ValueError, match=r"LARM_JOINT2 = 10.00 deg is outside its limits \[-158.0, 0.0\] deg"):
        joints.parse("0 0 10 0 0 0 deg", CTX)


def test_targets_are_frames_or_literal_poses() -> None:
    target = ParamSpec("t", ParamType.TARGET, "")
    assert target.parse("drill_1", CTX) == "drill_1"
    pose = target.parse("300mm, 0, 0.1, 180deg, 0, 0", CTX)
    assert isinstance(pose, Pose) and pose.x == pytest.approx(0.3) and pose.rpy()[0] == pytest.approx(math.pi)
    with pytest.raises(ValueError, match="unknown frame 'drill_2' in the cell model \\(did you mean 'drill_1'\\?\\)"):
        target.parse("drill_2", CTX)
    with pytest.raises(ValueError, match="neither a frame name nor 6 numbers"):
        target.parse("1 2 3", CTX)


def test_frames_elements_and_poses_check_kind_and_existence() -> None:
    hole = ParamSpec("h", ParamType.FRAME, "", kinds=("hole",))
    assert hole.parse("drill_1", CTX) == "drill_1"
    with pytest.raises(ValueError, match="frame 'tray' is a tray, expected hole"):
        hole.parse("tray", CTX)
    with pytest.raises(ValueError, match="needs a cell model"):
        hole.parse("drill_1", BindContext(NEXTAGE_OPEN, "left_arm", None))
    assert ParamSpec("e", ParamType.ELEMENT, "", kinds=("rivet",)).parse("ref_R10", CTX) == "ref_R10"
    assert ParamSpec("p", ParamType.JOINT_POSE, "").parse("safe", CTX) == "safe"
    assert ParamSpec("p", ParamType.JOINT_POSE, "").parse("initial", CTX) == "initial"
    with pytest.raises(ValueError, match="is the calling group itself"):
        ParamSpec("g", ParamType.GROUP, "").parse("left_arm", CTX)


def test_function_check_reports_count_group_kind_and_each_param() -> None:
    catalog = full_catalog()
    move = catalog.functions["move_relative"]
    assert move.signature() == "move_relative(dx, dy, dz, droll=0, dpitch=0, dyaw=0, reference=world)"
    assert [p.message for p in move.check(("0.1",), CTX)] == ["move_relative(dx, dy, dz, droll=0, dpitch=0, dyaw=0, reference=world) takes 3 to 7 params, got 1"]
    problems = move.check(("0.1", "x", "0", "0", "0", "0", "sideways"), CTX)
    assert [(p.index, p.message) for p in problems] == [
        (1, "param 2 (dy) of move_relative: 'x' is not a number (unit m)"),
        (6, "param 7 (reference) of move_relative: 'sideways' is not one of world, tool"),
    ]
    on_torso = catalog.functions["gripper_open"].check((), BindContext(NEXTAGE_OPEN, "torso_head", CELL))
    assert "cannot run on torso_head (a torso_head group)" in on_torso[0].message
    assert move.bind(("1cm", "0", "0"), CTX) == [0.01, 0.0, 0.0, 0.0, 0.0, 0.0, "world"]


def test_the_catalog_lists_core_and_rivet_functions_with_docs() -> None:
    catalog = full_catalog()
    assert {"debur_drilling", "pick_rivet", "insert_rivet"} <= set(catalog.names())
    assert {"move_joints", "move_to", "move_relative", "set_speed", "gripper_open", "locate", "record_trajectory", "execute_trajectory", "full_body_move", "master_move", "slave_follow", "wait"} <= set(catalog.names())
    for entry in catalog.describe():
        assert entry["doc"] and entry["signature"].startswith(entry["name"])
    assert catalog.functions["pick_rivet"].library == "rivet_installation"
    assert catalog.suggest("pick_rivets") == " (did you mean 'pick_rivet'?)"
    assert set(LIBRARIES) >= {"core", "rivet_installation"}
    assert issubclass(functions_class(), CoreFunctions)


def test_skill_declarations_are_checked_when_defined() -> None:
    with pytest.raises(TypeError, match="do not match arguments"):

        class Bad(CoreFunctions):
            @skill(ParamSpec("a", ParamType.NUMBER, ""))
            def f(self, b: float) -> None:
                """doc"""

    class NoDoc(CoreFunctions):
        @skill()
        def undocumented(self) -> None:
            pass

    with pytest.raises(ValueError, match="has no docstring"):
        Catalog.from_classes({"core": CoreFunctions, "x": NoDoc})

    class Clash(CoreFunctions):
        @skill()
        def gripper_open(self) -> None:
            """Another gripper_open."""

    class Clash2(CoreFunctions):
        @skill()
        def shared(self) -> None:
            """One."""

    class Clash3(CoreFunctions):
        @skill()
        def shared(self) -> None:
            """Two."""

    with pytest.raises(ValueError, match="function 'shared' is defined by both a and b"):
        Catalog.from_classes({"core": CoreFunctions, "a": Clash2, "b": Clash3})


def test_robots_are_found_by_name_or_alias() -> None:
    assert find_robot("nextage") is NEXTAGE_OPEN and find_robot("viper") is ADEPT_VIPER_S850
    with pytest.raises(KeyError, match="unknown robot 'ur5'"):
        find_robot("ur5")
    assert NEXTAGE_OPEN.joint_names[:3] == ("CHEST_JOINT0", "HEAD_JOINT0", "HEAD_JOINT1")
    assert len(NEXTAGE_OPEN.poses["initial"]) == 15


def test_cameras_are_checked_against_the_robot() -> None:
    camera = ParamSpec("camera", ParamType.CAMERA, "")
    assert camera.parse("head_camera_left", CTX) == "head_camera_left"
    assert camera.parse("auto", CTX) == "auto"
    with pytest.raises(ValueError, match="'wrist_cam' is not a camera of nextage_open \\(cameras: head_camera, .*, or auto\\)"):
        camera.parse("wrist_cam", CTX)


def test_joint_values_that_look_like_degrees_get_a_hint() -> None:
    joints = ParamSpec("joints", ParamType.JOINTS, "")
    with pytest.raises(ValueError, match="these look like degrees: write 'deg' after the list"):
        joints.parse("0.6 0 -100 -15.2 9.4 -3.2", CTX)


def test_a_single_group_pose_is_refused_where_a_whole_robot_pose_is_needed() -> None:
    cell = CellIndex("c", [], {}, {"left_clear": {"LARM_JOINT0": 0.1}}, {"left_clear": "left_arm"})
    full_body = full_catalog().functions["full_body_move"]
    problems = full_body.check(("left_clear",), BindContext(NEXTAGE_OPEN, "left_arm", cell))
    assert "joint pose 'left_clear' is for left_arm only; this function needs a whole-robot pose" in problems[0].message
    assert full_body.check(("initial",), BindContext(NEXTAGE_OPEN, "left_arm", cell)) == []


def test_locating_a_fixture_moves_every_frame_below_it() -> None:
    fixture = Pose.from_xyz_rpy(0.34, -0.06, 0.0)
    cell = CellIndex(
        "c",
        [
            CellFrame("fixture", fixture, "fixture"),
            CellFrame("slot_a", fixture.compose(Pose.from_xyz_rpy(0.02, 0.0, 0.0, math.pi, 0, 0)), "slot", parent="fixture"),
            CellFrame("pin", fixture.compose(Pose.from_xyz_rpy(0.0, 0.03, 0.01)), "pin", parent="fixture"),
        ],
    )
    found = fixture.compose(Pose.from_xyz_rpy(0.0015, -0.001, 0.0, 0.0, 0.0, math.radians(0.5)))  # 1.5 mm, -1 mm, 0.5 deg off
    cell.correct("fixture", found)
    expected = found.compose(Pose.from_xyz_rpy(0.02, 0.0, 0.0, math.pi, 0, 0))
    assert cell.pose("slot_a").distance_to(expected) < 1e-12 and cell.pose("slot_a").angle_to(expected) < 1e-9
    assert cell.nominal("slot_a").distance_to(cell.pose("slot_a")) > 0.001
    measured_pin = Pose.from_xyz_rpy(0.5, 0.5, 0.5)
    cell.correct("pin", measured_pin)  # a frame's own measurement wins over its parent's
    assert cell.pose("pin") == measured_pin
    assert cell.pose("fixture") == found
