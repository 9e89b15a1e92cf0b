"""Pose conventions every part of the project shares: URDF rpy, unit quaternions, composition."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core_functions.geometry import Pose

angles = st.floats(-math.pi, math.pi, allow_nan=False)
coords = st.floats(-2.0, 2.0, allow_nan=False)


@given(coords, coords, coords, angles, st.floats(-1.5, 1.5), angles)
def test_rpy_and_matrix_round_trips(x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> None:
    pose = Pose.from_xyz_rpy(x, y, z, roll, pitch, yaw)
    again = Pose.from_matrix(pose.matrix())
    assert again.distance_to(pose) < 1e-9 and again.angle_to(pose) < 1e-6
    r, p, w = pose.rpy()
    assert Pose.from_xyz_rpy(x, y, z, r, p, w).angle_to(pose) < 1e-6


def test_rpy_is_fixed_axis_xyz_like_urdf() -> None:
    pose = Pose.from_xyz_rpy(0, 0, 0, 0.3, 0.2, 0.1)
    rx = np.array([[1, 0, 0], [0, math.cos(0.3), -math.sin(0.3)], [0, math.sin(0.3), math.cos(0.3)]])
    ry = np.array([[math.cos(0.2), 0, math.sin(0.2)], [0, 1, 0], [-math.sin(0.2), 0, math.cos(0.2)]])
    rz = np.array([[math.cos(0.1), -math.sin(0.1), 0], [math.sin(0.1), math.cos(0.1), 0], [0, 0, 1]])
    assert np.allclose(pose.matrix()[:3, :3], rz @ ry @ rx)


@given(coords, coords, coords, angles, angles, angles)
def test_compose_with_inverse_is_identity(x: float, y: float, z: float, a: float, b: float, c: float) -> None:
    pose = Pose.from_xyz_rpy(x, y, z, a, b, c)
    identity = pose.compose(pose.inverse())
    assert identity.distance_to(Pose()) < 1e-9 and identity.angle_to(Pose()) < 1e-6


def test_offset_local_moves_along_the_frames_own_axes() -> None:
    hole = Pose.from_xyz_rpy(0.3, 0.0, 0.1, math.pi, 0, 0)  # z points down
    above = hole.offset_local(dz=-0.05)
    assert above.z == pytest.approx(0.15) and above.x == pytest.approx(0.3)
    assert hole.translated(dz=0.05).z == pytest.approx(0.15)


@pytest.mark.parametrize("bad", [dict(qw=0.5), dict(x=math.nan), dict(qx=math.inf)])
def test_invalid_poses_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        Pose(**bad)
