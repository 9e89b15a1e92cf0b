"""KR 6 R900 kinematics: the forward model matches pinocchio, the inverse undoes it, A/B/C are KUKA's."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from hypothesis import given
from hypothesis import strategies as st

from core_functions.geometry import Pose
from robot_bridges.kuka_rsi.kinematics import KR6_R900, KukaArm, abc_to_matrix, matrix_to_abc

ARM = KukaArm()


def _pinocchio_model() -> tuple[pin.Model, int]:
    """The same description built joint by joint (ROS-Industrial kr6r900sixx: origins and axes)."""
    g = KR6_R900
    model = pin.Model()
    joints = [
        ((0, 0, g.base_height), pin.JointModelRZ(), -1.0),
        ((g.shoulder_offset, 0, 0), pin.JointModelRY(), 1.0),
        ((g.upper_arm, 0, 0), pin.JointModelRY(), 1.0),
        ((0, 0, g.forearm_offset), pin.JointModelRX(), -1.0),
        ((g.forearm, 0, 0), pin.JointModelRY(), 1.0),
        ((g.flange, 0, 0), pin.JointModelRX(), -1.0),
    ]
    parent = 0
    for i, (xyz, joint, _sign) in enumerate(joints):
        parent = model.addJoint(parent, joint, pin.SE3(np.eye(3), np.array(xyz, dtype=float)), f"a{i + 1}")
    flange = pin.SE3(pin.utils.rotate("y", math.pi / 2), np.zeros(3))
    frame = model.addFrame(pin.Frame("tool0", parent, 0, flange, pin.FrameType.OP_FRAME))
    return model, frame


MODEL, TOOL0 = _pinocchio_model()
SIGNS = np.array([-1.0, 1.0, 1.0, -1.0, 1.0, -1.0])  # A1, A4, A6 turn about negative axes


def test_home_is_where_a_kr6_r900_flange_is() -> None:
    t = ARM.fk(np.radians([0, -90, 90, 0, 0, 0]))
    assert np.allclose(t[:3, 3], [0.525, 0.0, 0.890])
    assert np.allclose(np.degrees(matrix_to_abc(t[:3, :3])), [0.0, 90.0, 0.0])


joint_values = st.tuples(*[st.floats(j.lower, j.upper) for j in ARM.joints])


@given(joint_values)
def test_forward_kinematics_matches_pinocchio(q) -> None:  # type: ignore[no-untyped-def]
    data = MODEL.createData()
    pin.framesForwardKinematics(MODEL, data, SIGNS * np.array(q))
    expected = data.oMf[TOOL0]
    t = ARM.fk(q)
    assert np.allclose(t[:3, 3], expected.translation, atol=1e-12)
    assert np.allclose(t[:3, :3], expected.rotation, atol=1e-12)


@given(joint_values)
def test_inverse_kinematics_undoes_the_forward_one(q) -> None:  # type: ignore[no-untyped-def]
    q = np.array(q)
    target = ARM.fk(q)
    solution = ARM.ik(target, q)
    assert solution is not None
    assert np.allclose(ARM.fk(solution), target, atol=1e-7)
    assert ARM.within_limits(solution, 1e-7)
    if abs(math.sin(q[4])) > 1e-3:  # away from the wrist singularity the nearest solution is q itself
        assert np.allclose(solution, q, atol=1e-6)


def test_unreachable_poses_have_no_solution() -> None:
    far = np.eye(4)
    far[:3, 3] = (2.0, 0.0, 0.5)
    assert ARM.ik(far, np.zeros(6)) is None


@given(st.floats(-math.pi + 1e-6, math.pi - 1e-6), st.floats(-1.5, 1.5), st.floats(-math.pi + 1e-6, math.pi - 1e-6))
def test_kuka_abc_are_the_projects_yaw_pitch_roll(a: float, b: float, c: float) -> None:
    r = abc_to_matrix(a, b, c)
    assert np.allclose(matrix_to_abc(r), (a, b, c), atol=1e-9)
    pose = Pose.from_xyz_rpy(0, 0, 0, roll=c, pitch=b, yaw=a)
    assert np.allclose(pose.matrix()[:3, :3], r, atol=1e-12)


def test_abc_at_gimbal_lock_still_gives_the_rotation() -> None:
    r = abc_to_matrix(0.3, math.pi / 2, 0.2)
    assert np.allclose(abc_to_matrix(*matrix_to_abc(r)), r, atol=1e-9)
