"""Viper s850 kinematics and the V+ Z-Y-Z' location convention."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850
from robot_bridges.vplus.kinematics import (
    HOME_DEG,
    VIPER_S850,
    IKError,
    ViperKinematics,
    location_to_matrix,
    location_to_pose,
    matrix_to_zyz,
    pose_to_location,
    zyz_to_matrix,
)

KIN = ViperKinematics()
SEED_ACK_POSE = (480.014, -0.038, 709.975, 0.000, 179.995, 0.004)


def test_home_is_where_the_seed_reports_the_robot() -> None:
    """The seed's ack pose is the arm at AdeptServer's home #PPOINT(0,-90,180,0,90,0)."""
    reached = KIN.forward(np.radians(HOME_DEG))
    seed = location_to_matrix(SEED_ACK_POSE)
    assert np.allclose(reached[:3, 3], seed[:3, 3], atol=0.05e-3)  # 0.05 mm
    assert np.allclose(reached[:3, :3], seed[:3, :3], atol=1e-3)


def _published_flange(q: np.ndarray) -> np.ndarray:
    """Flange position from the arm's published geometry, written out independently of pinocchio."""
    g = VIPER_S850
    c1, s1 = math.cos(q[0]), math.sin(q[0])
    c2, s2 = math.cos(q[1]), math.sin(q[1])
    c23, s23 = math.cos(q[1] + q[2]), math.sin(q[1] + q[2])
    c4, s4 = math.cos(q[3]), math.sin(q[3])
    c5, s5 = math.cos(q[4]), math.sin(q[4])
    radial = -c23 * g.a3 + s23 * g.d4 + g.a1 + g.a2 * c2
    wrist = np.array([c1 * radial, s1 * radial, s23 * g.a3 + c23 * g.d4 - g.a2 * s2 + g.d1])
    approach = np.array([c1 * (c23 * c4 * s5 + s23 * c5) - s1 * s4 * s5, s1 * (c23 * c4 * s5 + s23 * c5) + c1 * s4 * s5, -s23 * c4 * s5 + c23 * c5])
    return wrist + g.d6 * approach


joints = st.tuples(*(st.floats(min_value=j.lower, max_value=j.upper) for j in ADEPT_VIPER_S850.group("arm").joints))


@given(joints)
def test_the_pinocchio_model_matches_the_published_geometry(q: tuple[float, ...]) -> None:
    assert np.allclose(KIN.forward(q)[:3, 3], _published_flange(np.array(q)), atol=1e-12)


def test_the_model_carries_the_robot_descriptions_joint_ranges() -> None:
    arm = ADEPT_VIPER_S850.group("arm")
    assert KIN.joint_names == arm.joint_names
    assert np.allclose(KIN.model.lowerPositionLimit, [j.lower for j in arm.joints])
    assert np.allclose(KIN.model.upperPositionLimit, [j.upper for j in arm.joints])


@given(joints)
@example(q=(1.0, 0.0, 1.5, 0.0, 1e-07, 0.0))  # just off the wrist singularity (CI at 868e7bd: joint 6 from r's third row missed by 1.5e-8)
@example(q=(1.0, 0.0, 1.5, 0.0, 1e-08, 0.0))
def test_inverse_kinematics_reaches_every_reachable_pose(q: tuple[float, ...]) -> None:
    target = KIN.forward(q)
    solved = KIN.inverse(target, seed=q)
    assert np.allclose(KIN.forward(solved), target, atol=1e-9)
    assert KIN.within_limits(solved)


@given(joints)
def test_inverse_kinematics_keeps_the_current_configuration(q: tuple[float, ...]) -> None:
    assume(abs(math.sin(q[4])) > 0.05)  # away from the wrist singularity, where joints 4/6 are not unique
    # and away from the stretched elbow, where the two elbow solutions lie closer together than the seed's offset
    elbow = math.atan2(KIN.geometry.d4, -KIN.geometry.a3) - q[2]
    assume(abs(math.sin(elbow)) > 0.05)
    solved = KIN.inverse(KIN.forward(q), seed=np.array(q) + 0.02)
    assert np.allclose(solved, q, atol=1e-6)


def test_a_target_out_of_reach_is_unreachable() -> None:
    with pytest.raises(IKError) as caught:
        KIN.inverse(location_to_matrix((2000, 0, 0, 0, 180, 0)))
    assert caught.value.reason == "unreachable"


def test_a_target_only_reachable_beyond_a_limit_names_the_joint() -> None:
    q = np.radians(HOME_DEG)
    q[0] = math.radians(175)  # joint 1 range is +-170
    with pytest.raises(IKError, match="joint_1") as caught:
        KIN.inverse(KIN.forward(q), seed=q)
    assert caught.value.reason == "joint_limit"


# ----------------------------------------------------------------------- conventions
def test_yaw_pitch_roll_are_z_y_z_prime_euler_angles() -> None:
    # yaw alone is a turn about z; pitch alone about y; roll turns about the *new* z
    assert np.allclose(zyz_to_matrix(90, 0, 0), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert np.allclose(zyz_to_matrix(0, 180, 0), np.diag([-1, 1, -1]), atol=1e-12)  # tool pointing down
    tilted = zyz_to_matrix(0, 90, 90)
    assert np.allclose(tilted[:, 2], [1, 0, 0], atol=1e-12)  # approach along world x
    assert np.allclose(tilted[:, 0], [0, 1, 0], atol=1e-12)  # roll of 90 about the new z


def test_a_v_plus_location_differs_from_urdf_roll_pitch_yaw() -> None:
    loc = location_to_pose((0, 0, 0, 0, 90, 90))
    rpy = Pose.from_xyz_rpy(0, 0, 0, roll=0, pitch=math.radians(90), yaw=math.radians(90))
    assert loc.angle_to(rpy) > 0.1


angles = st.floats(min_value=-180, max_value=180)


@given(angles, st.floats(min_value=0, max_value=180), angles)
def test_decompose_gives_the_same_rotation_with_pitch_in_0_180(yaw: float, pitch: float, roll: float) -> None:
    r = zyz_to_matrix(yaw, pitch, roll)
    y2, p2, r2 = matrix_to_zyz(r)
    assert 0 <= p2 <= 180 and -180 < y2 <= 180 and -180 < r2 <= 180
    assert np.allclose(zyz_to_matrix(y2, p2, r2), r, atol=1e-9)


def test_the_singular_pitches_put_everything_in_roll() -> None:
    assert matrix_to_zyz(zyz_to_matrix(30, 0, 20)) == pytest.approx((0, 0, 50))
    assert matrix_to_zyz(zyz_to_matrix(30, 180, 20)) == pytest.approx((0, 180, -10))


@given(st.tuples(*(st.floats(min_value=-1000, max_value=1000) for _ in range(3))), angles, st.floats(0, 180), angles)
def test_pose_and_location_convert_both_ways(xyz: tuple[float, float, float], yaw: float, pitch: float, roll: float) -> None:
    pose = location_to_pose((*xyz, yaw, pitch, roll))
    assert (pose.x, pose.y, pose.z) == pytest.approx(tuple(v / 1000 for v in xyz))
    back = location_to_pose(pose_to_location(pose))
    assert back.distance_to(pose) < 1e-9 and back.angle_to(pose) < 1e-6
