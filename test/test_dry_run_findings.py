"""A dry run's finding keeps where the robot was when it met it, as data (not only in its message): a view can put the
robot at that instant.  A collision of the two arms: the finding's joints, put through the same collision model the
sweep uses (pinocchio places the URDF, coal measures), bring the two bodies it names into contact, where the pose the
dry run started from keeps them apart; a refused target: the target pose asked for and the joints where the arm stood.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app_functions.registry import full_catalog
from cell_runner.dry_run.collisions import scene_of
from cell_runner.dry_run.report import Finding, JointPositions
from cell_runner.dry_run.runner import dry_run
from execution_engine.app_model import load_application
from robot_bridges.backend import BackendOptions
from robot_bridges.collision import CollisionScene
from test_dry_run import FAR, RIVET_CELL, call, param, write_app


def report_of(path: Path) -> tuple[object, object]:
    app = load_application(path, full_catalog())
    return app, dry_run(app, "nextage-sim", BackendOptions(robot=app.robot))


def pair_distance(scene: CollisionScene, joints: JointPositions, a: str, b: str) -> float | None:
    """The distance of bodies ``a`` and ``b`` with the robot at ``joints`` (by name), None: farther than the margin."""
    q = np.zeros(len(scene.joint_names))
    index = {name: k for k, name in enumerate(scene.joint_names)}
    for name, value in zip(*joints):
        q[index[name]] = value
    return next((c.distance for c in scene.contacts(q) if {c.a.name, c.b.name} == {a, b}), None)


def test_a_collisions_finding_holds_the_joints_at_which_its_two_bodies_touch(tmp_path: Path) -> None:
    path, _ = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("approach", param("drill_2")), "right_arm": call("approach", param("drill_2"))},
    ])
    app, report = report_of(path)
    found: list[Finding] = [f for f in report.findings if f.kind == "collision"]
    assert {f.group for f in found} == {"left_arm", "right_arm"}, report.findings
    scene = scene_of(app)
    assert scene is not None and report.start is not None
    for finding in found:
        assert finding.joints is not None and set(finding.joints[0]) == set(scene.joint_names)  # every joint of every group
        a, b = finding.bodies
        assert (a.owner, a.name, b.owner, b.name) == ("left_arm", "LARM_JOINT5_Link", "right_arm", "RARM_JOINT5_Link")
        assert finding.message.startswith(f"collision between {a.label} and {b.label}")  # the message as it was, the labels its own
        touching = pair_distance(scene, finding.joints, a.name, b.name)
        assert touching is not None and touching <= 0.0 < scene.margin  # a collision, at the finding's instant
        assert pair_distance(scene, report.start, a.name, b.name) is None  # apart where the run starts
        assert 0.0 < finding.t <= report.cycle_time  # (the hands meet as the arms arrive)
        assert finding.target is None


def test_a_refused_targets_finding_holds_the_target_and_where_the_arm_stood(tmp_path: Path) -> None:
    path, _ = write_app(tmp_path, "nextage", RIVET_CELL, [{"left_arm": call("move_to", FAR)}])
    _, report = report_of(path)
    refused = [f for f in report.findings if f.kind == "unreachable"]
    assert refused and refused[0].target is not None, report.findings
    assert (refused[0].target.x, refused[0].target.y, refused[0].target.z) == pytest.approx((1.2, 0.3, 0.2))
    assert refused[0].joints is not None and report.start is not None
    stood = dict(zip(*refused[0].joints))
    assert stood == pytest.approx(dict(zip(*report.start)))  # refused before it moved: where the run started
    assert refused[0].bodies == ()
