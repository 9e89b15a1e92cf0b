"""A camera on a robot: where it is mounted (hand-eye), what it sees (intrinsics), its lens.

``mount`` is the hand-eye calibration: the pose of the camera's optical frame (x right, y down,
z forward) in the link it is fixed to.  The world pose at capture time is the link's forward
kinematics composed with it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core_functions.geometry import Pose
from core_functions.vision.camera import OPTICAL_IN_BODY, Intrinsics
from robot_bridges.camera.render import Optics


@dataclass(frozen=True)
class CameraSpec:
    name: str
    link: str  # the link the camera is mounted on
    mount: Pose  # optical frame in that link (hand-eye calibration)
    intrinsics: Intrinsics
    optics: Optics
    max_range: float  # m: farther features are not found

    def optical_pose(self, link: Pose) -> Pose:
        """Where the optical frame is when the link is at ``link`` (world): every back end places its cameras so."""
        return link.compose(self.mount)


def body_mount(x: float, y: float, z: float) -> Pose:
    """A camera at (x, y, z) of a link looking along the link's x axis (REP 103 body -> optical)."""
    m = np.eye(4)
    m[:3, :3] = OPTICAL_IN_BODY
    m[:3, 3] = (x, y, z)
    return Pose.from_matrix(m)


def look_at_mount(position: tuple[float, float, float], target: tuple[float, float, float], right: tuple[float, float, float], base: Pose = Pose()) -> Pose:
    """A camera at ``position`` looking at ``target`` with its image x along ``right`` (all in ``base``'s frame)."""
    p, t = np.array(position, dtype=float), np.array(target, dtype=float)
    z = t - p
    z /= np.linalg.norm(z)
    x = np.array(right, dtype=float) - np.dot(right, z) * z
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("a camera's right direction must not be along its view direction")
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, :3] = np.column_stack((x, np.cross(z, x), z))
    m[:3, 3] = p
    return base.compose(Pose.from_matrix(m))


def parse_mount(text: str, what: str) -> Pose:
    """A hand-eye calibration given as text: ``x y z roll pitch yaw`` (m, rad) of the optical frame in its link."""
    parts = text.replace(",", " ").split()
    try:
        x, y, z, roll, pitch, yaw = (float(p) for p in parts)
        return Pose.from_xyz_rpy(x, y, z, roll, pitch, yaw)
    except ValueError:  # not six numbers, or a non-finite one
        raise ValueError(f"{what}: six numbers x y z roll pitch yaw (m, rad) expected, got {text!r}") from None
