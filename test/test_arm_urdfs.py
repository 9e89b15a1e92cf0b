"""The Viper s850 and KR 6 R900 URDFs: pinocchio on the URDF agrees with each bridge's own kinematics.

The bridges compute their flange poses with hand-written models (V+ and KUKA conventions); tf shows
the links from the URDFs.  If the two drifted apart RViz would draw the arm somewhere it is not, so
the flange is composed from the transforms the robot-state publisher would send (fixed joints and
movable joints, through :class:`UrdfTree`) and compared with the kinematics module's FK.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, RobotModel
from node_transport.clock import Clock
from node_transport.transforms import compose_to_root
from robot_bridges.kuka_rsi import kinematics as kuka
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.vplus import kinematics as viper
from core_functions.urdf_tree import UrdfTree
from robot_bridges.vplus.backend import VPlusBackend

VIPER = viper.ViperKinematics()
KUKA = kuka.KukaArm()
ARMS: dict[str, tuple[Path, RobotModel, str, Callable[[Sequence[float]], Any]]] = {
    "viper": (viper.URDF_PATH, ADEPT_VIPER_S850, "flange", VIPER.forward),
    "kuka": (kuka.URDF_PATH, KUKA_KR, "tool0", lambda q: KUKA.fk(tuple(q))),
}
TREES = {name: UrdfTree(path.read_text(encoding="utf-8")) for name, (path, *_rest) in ARMS.items()}


def flange_in_root(name: str, q: Sequence[float]) -> tuple[str, Pose]:
    _, robot, flange, _ = ARMS[name]
    tree = TREES[name]
    placed = tree.fixed_transforms() + tree.movable_transforms(robot.group("arm").joint_names, q)
    return compose_to_root({j.child: (j.parent, pose) for j, pose in placed}, flange)


def joint_values(robot: RobotModel) -> st.SearchStrategy[tuple[float, ...]]:
    return st.tuples(*[st.floats(j.lower, j.upper, allow_nan=False) for j in robot.group("arm").joints])


@given(joint_values(ADEPT_VIPER_S850))
def test_the_viper_urdf_has_the_flange_where_viper_kinematics_puts_it(q: tuple[float, ...]) -> None:
    root, pose = flange_in_root("viper", q)
    assert root == ADEPT_VIPER_S850.world_frame
    assert np.allclose(pose.matrix(), VIPER.forward(q), atol=1e-9)


@given(joint_values(KUKA_KR))
def test_the_kuka_urdf_has_tool0_where_kuka_kinematics_puts_it(q: tuple[float, ...]) -> None:
    root, pose = flange_in_root("kuka", q)
    assert root == KUKA_KR.world_frame
    assert np.allclose(pose.matrix(), KUKA.fk(q), atol=1e-9)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_limits_velocities_and_joint_names_are_the_robot_models(name: str) -> None:
    _, robot, _, _ = ARMS[name]
    tree = TREES[name]
    joints = robot.group("arm").joints
    assert tree.movable_joints == tuple(j.name for j in joints)
    assert tree.root == robot.world_frame
    assert np.allclose(tree.model.lowerPositionLimit, [j.lower for j in joints], atol=1e-12)
    assert np.allclose(tree.model.upperPositionLimit, [j.upper for j in joints], atol=1e-12)
    assert np.allclose(tree.model.velocityLimit, [j.max_velocity for j in joints], atol=1e-12)
    assert [j.name for j in tree.joints if not j.movable]  # the root and flange links hang on fixed joints


def test_the_backends_describe_their_robot_with_these_urdfs() -> None:
    # constructing connects nothing: only start() does
    assert VPlusBackend(Clock(), "127.0.0.1").robot_description() == viper.URDF_PATH.read_text(encoding="utf-8")
    other = viper.ViperKinematics(viper.ViperGeometry(a1=0.1))
    assert VPlusBackend(Clock(), "127.0.0.1", kinematics=other).robot_description() is None  # the URDF would lie
    rsi = KukaRsiBackend()
    assert rsi.robot_description() == kuka.URDF_PATH.read_text(encoding="utf-8")
    rsi.arm = kuka.KukaArm(kuka.ArmGeometry(forearm=0.5))
    assert rsi.robot_description() is None
