"""Cell models: frame trees composed into the world, units, truth, and every mistake at its line."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from app_model_support import CELL_XML, at

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN
from execution_engine.app_model import ApplicationError, Cell, Frame, check_joint_poses, load_cell, validate_cell


def write(tmp_path: Path, text: str, name: str = "cell.xml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def cell_xml(body: str, units: str = "") -> str:
    return f'<?xml version="1.0"?>\n<cell name="c"{units}>\n{body}</cell>\n'


def homogeneous(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> np.ndarray:
    """URDF convention written out: R = Rz(yaw) Ry(pitch) Rx(roll), then translate."""
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    m[:3, 3] = xyz
    return m


CHAIN = (((0.45, 0.0, 0.05), (0.0, 0.0, 0.3)), ((0.02, 0.10, 0.0), (0.1, -0.2, 0.4)), ((0.0, 0.0, 0.01), (math.pi, 0.0, 0.0)))


def chain_xml(length_scale: float = 1.0, angle_scale: float = 1.0, units: str = "") -> str:
    def f(xyz: tuple[float, ...], rpy: tuple[float, ...]) -> str:
        return f'xyz="{" ".join(repr(v * length_scale) for v in xyz)}" rpy="{" ".join(repr(v * angle_scale) for v in rpy)}"'

    (a, ar), (b, br), (c, cr) = CHAIN
    return cell_xml(
        f'  <frame name="part" {f(a, ar)} kind="fixture">\n'
        f'    <frame name="corner" {f(b, br)}>\n'
        f'      <frame name="hole" {f(c, cr)} kind="hole" diameter="0.0048"/>\n'
        "    </frame>\n"
        "  </frame>\n",
        units,
    )


def test_nested_world_pose_is_the_product_of_the_chain(tmp_path: Path) -> None:
    cell = load_cell(write(tmp_path, chain_xml()))
    expected = np.eye(4)
    for name, (xyz, rpy) in zip(("part", "corner", "hole"), CHAIN):
        expected = expected @ homogeneous(xyz, rpy)
        assert np.allclose(cell.pose(name).matrix(), expected, atol=1e-12), name
    assert cell.frame("hole").parent == "corner" and cell.frame("part").parent == "world"
    assert cell.frame_kind("hole") == "hole" and cell.frame("hole").attributes == {"diameter": "0.0048"}
    assert cell.pose("world") == Pose()


def test_a_hand_checkable_composition(tmp_path: Path) -> None:
    text = cell_xml('<frame name="a" xyz="1 0 0" rpy="0 0 90"><frame name="b" xyz="1 0 0"/></frame>\n', ' angle_unit="deg"')
    cell = load_cell(write(tmp_path, text))
    assert cell.pose("b").position == pytest.approx((1.0, 1.0, 0.0))


def test_mm_and_deg_give_the_same_cell_as_m_and_rad(tmp_path: Path) -> None:
    si = load_cell(write(tmp_path, chain_xml(), "si.xml"))
    scaled = load_cell(write(tmp_path, chain_xml(1000.0, 180.0 / math.pi, ' length_unit="mm" angle_unit="deg"'), "mm.xml"))
    for name in ("part", "corner", "hole"):
        assert np.allclose(si.pose(name).matrix(), scaled.pose(name).matrix(), atol=1e-12)


def test_top_level_frame_with_a_parent_attribute(tmp_path: Path) -> None:
    text = cell_xml('<frame name="b" parent="a" xyz="0 0 1"/>\n<frame name="a" xyz="1 0 0"/>\n')
    cell = load_cell(write(tmp_path, text))
    assert cell.pose("b").position == pytest.approx((1.0, 0.0, 1.0))


def test_actual_gives_the_true_pose_of_the_frame_and_its_children(tmp_path: Path) -> None:
    text = cell_xml(
        '<frame name="part" xyz="0.5 0 0">\n'
        '  <actual xyz="0.001 0 0" rpy="0 0 0.01"/>\n'
        '  <frame name="hole" xyz="0 0.1 0"/>\n'
        '</frame>\n'
        '<frame name="tray" xyz="0 -0.3 0"/>\n'
    )
    cell = load_cell(write(tmp_path, text))
    nominal_part = cell.pose("part")
    true_part = nominal_part.compose(Pose.from_xyz_rpy(0.001, 0, 0, 0, 0, 0.01))
    assert cell.true_pose("part") == pytest.approx(true_part)
    assert np.allclose(cell.true_pose("hole").matrix(), true_part.matrix() @ Pose(0, 0.1, 0).matrix())
    assert cell.true_pose("tray") == cell.pose("tray")
    snapshot = cell.to_snapshot()
    assert set(snapshot.truth) == {"part", "hole"}


def test_snapshot_lists_frames_in_document_order_and_joint_poses_by_joint(tmp_path: Path) -> None:
    cell = load_cell(write(tmp_path, CELL_XML))
    with pytest.raises(ValueError, match="needs a robot"):
        cell.to_snapshot()
    snapshot = cell.to_snapshot(NEXTAGE_OPEN)
    assert [f.name for f in snapshot.frames] == ["part", "drill_1", "drill_2", "rivet_tray", "rivet_1", "rivet_2"]
    rivet = next(f for f in snapshot.frames if f.name == "rivet_1")
    assert (rivet.kind, rivet.parent, rivet.attributes) == ("rivet_slot", "rivet_tray", {"element": "ref_R10"})
    assert rivet.pose.position == pytest.approx((0.35, -0.30, 0.02))
    assert snapshot.elements == {"ref_R10": {"kind": "rivet", "diameter": "0.0048", "length": "0.010", "grip_depth": "0.004"}}
    assert list(snapshot.joint_poses["safe"]) == list(NEXTAGE_OPEN.joint_names)
    assert snapshot.joint_poses["left_ready"]["LARM_JOINT3"] == pytest.approx(math.radians(-15.2))
    assert cell.bind(NEXTAGE_OPEN).to_snapshot() == snapshot


def test_joint_pose_unit_defaults_to_the_cell_angle_unit(tmp_path: Path) -> None:
    text = cell_xml('<joint_pose name="p" group="arm" joints="0 -90 180 0 0 0"/>\n', ' angle_unit="deg"')
    cell = load_cell(write(tmp_path, text))
    assert cell.joint_values("p", ADEPT_VIPER_S850)["joint_2"] == pytest.approx(-math.pi / 2)


def test_cell_built_in_code_checks_its_tree() -> None:
    with pytest.raises(ValueError, match="unknown parent 'nowhere'"):
        Cell("c", frames={"a": Frame("a", parent="nowhere")})
    with pytest.raises(ValueError, match="cycle"):
        Cell("c", frames={"a": Frame("a", parent="b"), "b": Frame("b", parent="a")})


# ------------------------------------------------------------------------------ mistakes
def test_unknown_parent_and_cycles(tmp_path: Path) -> None:
    text = cell_xml(
        '<frame name="a" parent="wrld"/>\n'
        '<frame name="b" parent="c"/>\n'
        '<frame name="c" parent="b"/>\n'
    )
    path = write(tmp_path, text)
    # Parents are checked before cycles: the unknown parent is the first thing to fix.
    assert [str(d) for d in validate_cell(path)] == [at(path, text, 'parent="wrld"', "frame 'a': unknown parent frame 'wrld' (did you mean 'world'?)")]
    text = cell_xml(
        '<frame name="b" parent="c"/>\n'
        '<frame name="c" parent="d"/>\n'
        '<frame name="top" parent="inner"><frame name="inner"/></frame>\n'
        '<frame name="d" parent="b"/>\n'
    )
    path = write(tmp_path, text)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'parent="c"', "frames b -> c -> d -> b form a cycle: a frame cannot be its own ancestor"),
        at(path, text, 'parent="inner"', "frames top -> inner -> top form a cycle: a frame cannot be its own ancestor"),
    ]


def test_names_are_unique_and_world_is_reserved(tmp_path: Path) -> None:
    text = cell_xml(
        '<frame name="a"/>\n'
        '<frame name="world"/>\n'
        '<frame name="b"><frame name="a"/></frame>\n'
        '<element name="e"/>\n<element name="e"/>\n'
        '<joint_pose name="j" joints="0"/>\n<joint_pose name="j" joints="0"/>\n'
    )
    path = write(tmp_path, text)
    with pytest.raises(ApplicationError) as caught:
        load_cell(path)
    assert [str(d) for d in caught.value.diagnostics] == [
        at(path, text, 'name="world"', "'world' is the robot base frame and cannot be redefined"),
        at(path, text, 'name="a"', "frame 'a' is defined twice (first on line 3)", occurrence=2),
        at(path, text, 'name="e"', "element 'e' is defined twice (first on line 6)", occurrence=2),
        at(path, text, 'name="j"', "joint pose 'j' is defined twice (first on line 8)", occurrence=2),
    ]


def test_frame_details(tmp_path: Path) -> None:
    text = cell_xml(
        '<frame name="a">\n'
        '  <frame name="b" parent="a"/>\n'
        '  <actual xyz="0 0 0"/><actual xyz="0 0 1"/>\n'
        '</frame>\n'
        '<frame name="slot" element="ref_R11" xyz="INF 0 0"/>\n'
    )
    path = write(tmp_path, text)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'parent="a"', "frame 'b' is inside frame 'a': only top-level frames take a parent attribute"),
        at(path, text, "<actual", "frame 'a' has more than one <actual>", occurrence=2),
        at(path, text, 'element="ref_R11"', "frame 'slot' names element 'ref_R11', which the cell does not define"),
        at(path, text, 'xyz="INF', "xyz of <frame> must be finite numbers, got 'INF 0 0'"),
    ]


def test_schema_errors_in_the_cell(tmp_path: Path) -> None:
    text = cell_xml('<frame name="a" xyz="1 2" rpy="a b c"/>\n<joint_pose name="j" joints="1 x" unit="grad"/>\n<fixture name="f"/>\n', ' length_unit="cm"')
    path = write(tmp_path, text)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, "length_unit=", "attribute length_unit='cm' of <cell>: expected m or mm"),
        at(path, text, "xyz=", "attribute xyz='1 2' of <frame>: expected three numbers separated by spaces"),
        at(path, text, "rpy=", "attribute rpy='a b c' of <frame>: expected three numbers separated by spaces"),
        at(path, text, "joints=", "attribute joints='1 x' of <joint_pose>: expected one or more numbers separated by spaces"),
        at(path, text, 'unit="grad"', "attribute unit='grad' of <joint_pose>: expected rad or deg"),
        at(path, text, "<fixture", "<fixture> is not allowed here inside <cell>; expected <frame>, <element>, <zone>, <joint_pose> or <robot>"),
    ]


def test_a_free_attribute_like_a_known_one_is_a_warning(tmp_path: Path) -> None:
    text = cell_xml('<frame name="a" xzy="1 0 0" part="p1"/>\n<element name="e" knd="rivet"/>\n')
    path = write(tmp_path, text)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, "xzy=", "warning: attribute xzy of <frame> 'a' is kept as a free attribute; did you mean xyz?"),
        at(path, text, "knd=", "warning: attribute knd of <element> 'e' is kept as a free attribute; did you mean kind?"),
    ]
    cell = load_cell(path)  # warnings do not stop loading
    assert cell.frame("a").attributes == {"xzy": "1 0 0", "part": "p1"}


# ------------------------------------------------------------------------------ joint poses and the robot
def test_joint_poses_against_the_robot(tmp_path: Path) -> None:
    text = cell_xml(
        '<joint_pose name="short" joints="0 0 0"/>\n'
        '<joint_pose name="wild" group="right_arm" unit="deg" joints="0 0 10 0 0 0"/>\n'
        '<joint_pose name="gone" group="arm" joints="0 0 0 0 0 0"/>\n'
        '<joint_pose name="initial" group="left_arm" joints="0 0 0 0 0 0"/>\n'
    )
    path = write(tmp_path, text)
    assert validate_cell(path) == []  # no robot yet: nothing to check against
    assert [str(d) for d in validate_cell(path, NEXTAGE_OPEN)] == [
        at(path, text, 'joints="0 0 0"', "joint pose 'short' has 3 values; nextage_open has 15 joints, in this order: "
           + " ".join(NEXTAGE_OPEN.joint_names)),
        at(path, text, 'joints="0 0 10', "joint pose 'wild': RARM_JOINT2 = 10.00 deg is outside its limits [-158.0, 0.0] deg"),
        at(path, text, 'group="arm"', "joint pose 'gone': 'arm' is not a group of nextage_open (left_arm, right_arm, torso_head)"),
        at(path, text, '<joint_pose name="initial"', "warning: joint pose 'initial' has the name of a pose of nextage_open; the name is ambiguous, rename it"),
    ]
    assert check_joint_poses(load_cell(write(tmp_path, CELL_XML, "ok.xml")), NEXTAGE_OPEN) == []
