"""Collision checking of arms, robot body and cell (coal through pinocchio) before and while anything moves.

Must show (issue 15): two arms driven to the same point in one operation are refused by
``validate --simulate`` at FILE:LINE of both calls, naming both groups and saying "collision";
``run`` does not start it; the paper's demonstrator passes.  The scene itself: the robot at its
initial pose touches nothing, hands brought together do, a held part and the cell's boxes count,
and work (a hand at the hole it deburs) is contact, not a collision.
"""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN
from execution_engine.app_model import load_cell, validate_cell
from robot_bridges.collision import CellBox, HeldPart, cell_boxes, scene_for
from robot_bridges.collision.robots import NEXTAGE_HAND
from robot_bridges.nextage_sim.model import NextageModel
from test_dry_run import RIVET_CELL, call, cli, findings, param, write_app

MODEL = NextageModel()
for _arm in MODEL.arms.values():
    _arm.tool = NEXTAGE_HAND  # the simulator's TCP (the hand), as the collision model's
INITIAL = MODEL.named_pose("initial")


@pytest.mark.parametrize("sync", ["operation", "flags"])
def test_two_arms_driven_to_the_same_point_are_refused_at_both_lines(tmp_path: Path, sync: str) -> None:
    """In both modes; the zone at the part lets the right arm in once the left arm's call has
    ended -- with the left arm still at the hole, which the sweep finds."""
    app, where = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("approach", param("drill_2")), "right_arm": call("approach", param("drill_2"))},
    ])
    app.write_text(app.read_text(encoding="utf-8").replace('robot="nextage"', f'robot="nextage" sync="{sync}"', 1), encoding="utf-8")
    code, _, err = cli("validate", "--simulate", str(app))
    found = findings(err)
    assert code == 1
    left = [f for f in found if f.startswith(f"{where[('1', 'left_arm')]}: operation 1 left_arm approach: collision: ")]
    right = [f for f in found if f.startswith(f"{where[('1', 'right_arm')]}: operation 1 right_arm approach: collision: ")]
    assert left and right, err
    assert "collision between left_arm" in left[0] and "right_arm" in left[0]
    assert "against right_arm approach of operation 1" in left[0] and "against left_arm approach of operation 1" in right[0]

    code, out, err = cli("run", str(app), "--speed", "max")
    assert code == 1 and "not run: 2 problem(s) found by the dry run" in err
    assert "Finish" not in out


def test_two_arms_at_different_holes_in_one_operation_pass(tmp_path: Path) -> None:
    app, _ = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("approach", param("drill_1")), "right_arm": call("approach", param("rivet_1"))},
    ])
    code, out, err = cli("validate", "--simulate", str(app))
    assert code == 0, err
    assert "collisions checked: 2 motions" in out and "margin 10 mm" in out


def test_the_papers_demonstrator_passes_with_collisions_checked() -> None:
    code, out, err = cli("validate", "--simulate", "apps_xml/rivet_installation.xml")
    assert code == 0, err
    assert "no problems found" in out and "collisions checked:" in out


def test_an_arm_driven_through_the_part_is_a_collision_with_the_cell(tmp_path: Path) -> None:
    """The forearm swept through the part's plate: arm against cell, at that call's line."""
    app, where = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("move_to", param("0.34,0.06,-0.05,180deg,0,90deg"))},
    ])
    code, _, err = cli("validate", "--simulate", str(app))
    hits = [f for f in findings(err) if f.startswith(f"{where[('1', 'left_arm')]}: operation 1 left_arm move_to: collision: ")]
    assert code == 1 and hits and "cell part" in hits[0], err


# ------------------------------------------------------------------ the scene
def nextage() -> object:
    return scene_for(NEXTAGE_OPEN)


def test_the_initial_pose_touches_nothing_and_every_robot_has_a_model() -> None:
    assert nextage().contacts(INITIAL) == []
    for robot in (ADEPT_VIPER_S850, KUKA_KR):
        scene = scene_for(robot)
        assert len(scene._links) >= 7  # every moving link and the base has geometry
        assert scene.contacts(np.zeros(6)) == []


def arm_at(q: np.ndarray, group: str, target: Pose) -> np.ndarray:
    solution = MODEL.arms[group].solve(target, q)
    out = q.copy()
    out[MODEL.arms[group].indices] = solution.positions
    return out


DOWN = (math.pi, 0.0, math.pi / 2)


def test_hands_at_one_point_collide_and_apart_they_do_not() -> None:
    scene = nextage()
    q = arm_at(INITIAL, "left_arm", Pose.from_xyz_rpy(0.34, 0.02, 0.05, *DOWN))
    together = arm_at(q, "right_arm", Pose.from_xyz_rpy(0.34, 0.02, 0.05, *DOWN))
    hit = [c for c in scene.contacts(together) if {c.a.group, c.b.group} == {"left_arm", "right_arm"}]
    assert hit and min(c.distance for c in hit) <= 0.0
    worst = min(hit, key=lambda c: c.distance)
    assert worst.describe(scene.margin) == "collision between left_arm hand (LARM_JOINT5_Link) and right_arm hand (RARM_JOINT5_Link)"
    apart = arm_at(q, "right_arm", Pose.from_xyz_rpy(0.34, -0.14, 0.05, *DOWN))
    assert [c for c in scene.contacts(apart) if {c.a.group, c.b.group} == {"left_arm", "right_arm"}] == []


def test_a_held_part_and_the_cell_count_and_work_is_contact() -> None:
    scene = nextage()
    plate = CellBox("part", Pose.from_xyz_rpy(0.34, 0.0, -0.005), (0.12, 0.2, 0.01))
    scene.set_cell([plate])
    hole = Pose.from_xyz_rpy(0.34, 0.02, 0.0, *DOWN)
    at_hole = arm_at(INITIAL, "left_arm", hole)
    def hand_on_part(contacts: list) -> list:
        return [c for c in contacts if {c.a.label(), c.b.label()} == {"left_arm hand (LARM_JOINT5_Link)", "cell part"}]

    assert hand_on_part(scene.contacts(at_hole))
    assert hand_on_part(scene.contacts(at_hole, {"left_arm": (hole,)})) == []  # deburring that hole: the hand may touch
    above = arm_at(INITIAL, "left_arm", Pose.from_xyz_rpy(0.34, 0.02, 0.012, *DOWN))
    assert hand_on_part(scene.contacts(above)) == [] and not any("held" in c.describe(0.01) for c in scene.contacts(above))
    scene.set_held("left_arm", HeldPart("ref_R10", 0.0024, 0.004, 0.006))
    held = [c for c in scene.contacts(above) if "held" in c.a.name + c.b.name]
    assert held and "held ref_R10" in held[0].describe(scene.margin) and "below the 10 mm safety margin" in held[0].describe(scene.margin)


@settings(max_examples=25, deadline=None)
@given(st.floats(0.0, 0.05), st.floats(-0.01, 0.01))
def test_a_near_miss_is_reported_exactly_below_the_margin(gap: float, dx: float) -> None:
    """A block ``gap`` under the fingertips (the hand's box ends 5 mm behind the TCP): reported iff
    the hand comes closer than the margin, with the distance."""
    scene = nextage()
    q = arm_at(INITIAL, "left_arm", Pose.from_xyz_rpy(0.34, 0.06, 0.10, *DOWN))
    scene.place(q)
    tcp = scene.tcp_matrix("left_arm")[:3, 3]
    box = CellBox("block", Pose.from_xyz_rpy(tcp[0] + dx, tcp[1], tcp[2] - gap - 0.01), (0.03, 0.03, 0.02))
    scene.set_cell([box])
    hits = [c for c in scene.contacts(q) if {c.a.name, c.b.name} == {"block", "LARM_JOINT5_Link"}]
    distance = gap + 0.005
    if distance < scene.margin - 1e-4:
        assert len(hits) == 1 and hits[0].distance == pytest.approx(distance, abs=1e-4)
    elif distance > scene.margin + 1e-4:
        assert hits == []


def test_the_simulator_stops_the_cell_when_two_arms_collide_at_run_time(tmp_path: Path) -> None:
    """With the dry run skipped (--no-check) the Nextage simulator itself finds the collision and stops."""
    app, _ = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("approach", param("drill_2")), "right_arm": call("approach", param("drill_2"))},
    ])
    code, out, err = cli("run", str(app), "--speed", "max", "--no-check")
    text = out + err
    assert code == 1
    assert "-> ErrorHandling (error)" in text
    assert "collision: " in text and "collision between left_arm hand (LARM_JOINT5_Link) and right_arm hand (RARM_JOINT5_Link)" in text
    assert "not retried: collision is deterministic" in text


# ------------------------------------------------------------------ the cell's boxes and zones, read
def cell_file(folder: Path, body: str, unit: str = "mm") -> Path:
    path = folder / "cell.xml"
    path.write_text(f'<?xml version="1.0"?>\n<cell name="c" length_unit="{unit}">\n{body}</cell>\n', encoding="utf-8")
    return path


def test_boxes_and_zones_are_read_in_the_length_unit_and_reach_the_collision_model(tmp_path: Path) -> None:
    path = cell_file(tmp_path, '<frame name="part" xyz="340 0 0" box="120 200 10" box_xyz="0 0 -5"/>\n<zone name="z" parent="part" xyz="0 0 50" size="160 220 140"/>\n')
    cell = load_cell(path)
    assert [float(v) for v in cell.frame("part").attributes["box"].split()] == pytest.approx([0.12, 0.2, 0.01])
    zone = cell.zones["z"]
    assert zone.size == pytest.approx((0.16, 0.22, 0.14)) and zone.centre == pytest.approx((0.0, 0.0, 0.05))
    assert zone.contains(cell.pose("part"), (0.34, 0.1, 0.1)) and not zone.contains(cell.pose("part"), (0.34, 0.12, 0.1))
    (box,) = cell_boxes(cell.to_snapshot())
    assert box.frame == "part" and box.size == pytest.approx((0.12, 0.2, 0.01)) and box.pose.position == pytest.approx((0.34, 0.0, -0.005))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**9, 10**9)), min_size=0, max_size=4), st.sampled_from(["box", "box_xyz"]))
def test_a_bad_box_is_one_line_at_its_attribute_and_a_good_one_is_metres(values: list[float], attribute: str) -> None:
    """Random numbers: either a box within the bounds (kept in metres) or one error naming the attribute."""
    text = " ".join(str(v) for v in values)
    extra = ' box="1 1 1"' if attribute == "box_xyz" else ""
    with tempfile.TemporaryDirectory() as folder:
        path = cell_file(Path(folder), f'<frame name="f"{extra} {attribute}="{text}"/>\n')
        found = [d for d in validate_cell(path) if d.severity == "error"]
    ok = len(values) == 3 and all(math.isfinite(v) and abs(v) <= 100_000 for v in values) and (attribute == "box_xyz" or min(values) > 0)
    if ok:
        assert found == []
    else:
        assert found and all(d.line == 3 and attribute in d.message for d in found)  # the schema and the bounds may both say it


@settings(max_examples=40, deadline=None)
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**9, 10**9)), min_size=0, max_size=4))
def test_a_bad_zone_size_is_one_line_and_a_good_one_a_zone(values: list[float]) -> None:
    text = " ".join(str(v) for v in values)
    with tempfile.TemporaryDirectory() as folder:
        path = cell_file(Path(folder), f'<zone name="z" size="{text}"/>\n')
        found = [d for d in validate_cell(path) if d.severity == "error"]
        ok = len(values) == 3 and all(math.isfinite(v) and 0 < v <= 100_000 for v in values)
        if ok:
            assert found == [] and load_cell(path).zones["z"].size == pytest.approx(tuple(v / 1000 for v in values))
        else:
            assert found and all(d.line == 3 and "size" in d.message for d in found)
