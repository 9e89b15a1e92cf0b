"""Adept Viper s850 kinematics (pinocchio) and the V+ location convention.

The arm is written from its published geometry (the Adept Viper s850 user's guide figures, as
used by ViSP's ``vpViper850``): a1 = 75 mm, d1 = 335 mm, a2 = 365 mm, a3 = 90 mm, d4 = 405 mm and
d6 = 80 mm from the wrist centre to the tool flange, with V+'s joint zeros.  Two published
facts pin the convention down and are tested: at the AdeptServer home ``#PPOINT(0,-90,180,0,90,0)``
the flange is at (480, 0, 710) mm pointing straight down, which is the seed's ack
``480.014,-0.038,709.975,0.000,179.995,0.004``; and the joint ranges are those of
:data:`core_functions.robots.ADEPT_VIPER_S850`.

**Locations.** V+ writes a Cartesian location as x, y, z (mm) and yaw, pitch, roll (deg), which
are Z-Y-Z' Euler angles: ``R = Rz(yaw) @ Ry(pitch) @ Rz(roll)`` (V+ Language User's Guide,
"Location Variables").  ``DECOMPOSE`` returns pitch in [0, 180]; where pitch is 0 or 180 only
yaw + roll (or roll - yaw) is defined, and we put it all in roll, as V+ does for SCARAs.  The
project's :class:`~core_functions.geometry.Pose` is metres and a quaternion; the conversions here
are the only place the two meet.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, JointSpec

Matrix = NDArray[np.float64]
Location = tuple[float, float, float, float, float, float]

#: AdeptServer ``movehome``: ``MOVE #PPOINT(0,-90,180,0,90,0)`` (deg); also the seed's init_move.
HOME_DEG: tuple[float, ...] = (0.0, -90.0, 180.0, 0.0, 90.0, 0.0)
_SINGULAR = 1e-9


@dataclass(frozen=True)
class ViperGeometry:
    """Link lengths (m) of a Viper-type arm: offset shoulder, offset elbow, spherical wrist."""

    a1: float = 0.075
    d1: float = 0.335
    a2: float = 0.365
    a3: float = 0.090
    d4: float = 0.405
    d6: float = 0.080


VIPER_S850 = ViperGeometry()
#: The same arm as a URDF (root ``world``, flange link ``flange``), for robot_description and tf.
URDF_PATH = Path(__file__).resolve().parent / "urdf" / "adept_viper_s850.urdf"


class IKError(ValueError):
    """No joint solution: ``reason`` is ``"unreachable"`` or ``"joint_limit"``."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


# --------------------------------------------------------------------- V+ locations
def _rz(a: float) -> Matrix:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> Matrix:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def zyz_to_matrix(yaw: float, pitch: float, roll: float) -> Matrix:
    """Rotation from V+ yaw, pitch, roll in degrees (Z-Y-Z', intrinsic)."""
    return _rz(math.radians(yaw)) @ _ry(math.radians(pitch)) @ _rz(math.radians(roll))


def matrix_to_zyz(r: Matrix) -> tuple[float, float, float]:
    """V+ yaw, pitch, roll (deg) of a rotation: pitch in [0, 180], yaw and roll in (-180, 180]."""
    sp = math.hypot(r[0, 2], r[1, 2])
    pitch = math.atan2(sp, r[2, 2])
    if sp > _SINGULAR:
        yaw = math.atan2(r[1, 2], r[0, 2])
        roll = math.atan2(r[2, 1], -r[2, 0])
    elif r[2, 2] > 0:  # pitch 0: R = Rz(yaw + roll)
        yaw, roll = 0.0, math.atan2(r[1, 0], r[0, 0])
    else:  # pitch 180: R = Ry(180) Rz(roll - yaw)
        yaw, roll = 0.0, math.atan2(r[1, 0], -r[0, 0])
    return _wrap_deg(math.degrees(yaw)), math.degrees(pitch), _wrap_deg(math.degrees(roll))


def _wrap_deg(a: float) -> float:
    a = math.fmod(a, 360.0)
    if a <= -180.0:
        a += 360.0
    elif a > 180.0:
        a -= 360.0
    return 0.0 if a == 0.0 else a


def location_to_matrix(loc: Sequence[float]) -> Matrix:
    """4x4 transform (metres) of a V+ location (x, y, z mm; yaw, pitch, roll deg)."""
    x, y, z, yaw, pitch, roll = loc
    m = np.eye(4)
    m[:3, :3] = zyz_to_matrix(yaw, pitch, roll)
    m[:3, 3] = (x / 1000.0, y / 1000.0, z / 1000.0)
    return m


def matrix_to_location(m: Matrix) -> Location:
    yaw, pitch, roll = matrix_to_zyz(m[:3, :3])
    return (float(m[0, 3] * 1000.0), float(m[1, 3] * 1000.0), float(m[2, 3] * 1000.0), yaw, pitch, roll)


def pose_to_location(pose: Pose) -> Location:
    """Our Pose (m, quaternion) as a V+ location (mm, Z-Y-Z' deg)."""
    return matrix_to_location(pose.matrix())


def location_to_pose(loc: Sequence[float]) -> Pose:
    """A V+ location (mm, Z-Y-Z' deg) as our Pose (m, quaternion)."""
    return Pose.from_matrix(location_to_matrix(loc))


# ------------------------------------------------------------------------- the arm
class ViperKinematics:
    """Forward and inverse kinematics of the flange in the robot base (V+ world) frame.

    Inverse kinematics is damped least squares from a seed -- the current joints -- so it keeps
    the arm's configuration (lefty/righty, above/below, flip) the way a V+ ``MOVE`` does, and
    falls back to the home configuration when the seed does not converge.
    """

    def __init__(self, geometry: ViperGeometry = VIPER_S850, joints: Sequence[JointSpec] | None = None) -> None:
        self.geometry = g = geometry
        self.joints = tuple(joints if joints is not None else ADEPT_VIPER_S850.group("arm").joints)
        if len(self.joints) != 6:
            raise ValueError(f"a Viper arm has 6 joints, got {len(self.joints)}")
        self.lower = np.array([j.lower for j in self.joints])
        self.upper = np.array([j.upper for j in self.joints])
        self.max_velocity = np.array([j.max_velocity for j in self.joints])
        model = pin.Model()
        model.name = "adept_viper_s850"
        placements = [(0, 0, 0), (g.a1, 0, g.d1), (g.a2, 0, 0), (-g.a3, 0, g.d4), (0, 0, 0), (0, 0, 0)]
        axes = [pin.JointModelRZ, pin.JointModelRY, pin.JointModelRY, pin.JointModelRZ, pin.JointModelRY, pin.JointModelRZ]
        parent = 0
        for spec, xyz, axis in zip(self.joints, placements, axes):
            parent = model.addJoint(parent, axis(), pin.SE3(np.eye(3), np.array(xyz, dtype=float)), spec.name)
        model.lowerPositionLimit = self.lower.copy()
        model.upperPositionLimit = self.upper.copy()
        self._wrist = parent
        self._flange = pin.SE3(np.eye(3), np.array([0.0, 0.0, g.d6]))
        self.model = model
        self.data = model.createData()
        self.home = np.radians(HOME_DEG)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def forward(self, q: Sequence[float]) -> Matrix:
        """Flange pose (4x4, metres) for joints ``q`` (rad)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return (self.data.oMi[self._wrist] * self._flange).homogeneous

    def within_limits(self, q: Sequence[float], tolerance: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower - tolerance) and np.all(q <= self.upper + tolerance))

    def limit_violations(self, q: Sequence[float]) -> list[str]:
        """Readable list of the joints of ``q`` outside their range."""
        out = []
        for spec, value in zip(self.joints, q):
            if not spec.contains(value):
                out.append(
                    f"{spec.name} {math.degrees(value):.3f} deg outside "
                    f"[{math.degrees(spec.lower):.0f}, {math.degrees(spec.upper):.0f}]"
                )
        return out

    def inverse(self, target: Matrix, seed: Sequence[float] | None = None) -> NDArray[np.float64]:
        """Joints (rad) that put the flange at ``target``, closest to ``seed``; raises :class:`IKError`."""
        target = np.asarray(target, dtype=float)
        near = np.asarray(seed, dtype=float) if seed is not None else self.home
        candidates = self._solutions(target, near)
        if not candidates:
            raise IKError("unreachable", "target outside the workspace (no joint solution)")
        inside = [q for q in candidates if self.within_limits(q)]
        if not inside:
            closest = min(candidates, key=lambda q: float(np.sum((q - near) ** 2)))  # the configuration asked for
            raise IKError("joint_limit", "target reachable only beyond joint limits: " + "; ".join(self.limit_violations(closest)))
        best = min(inside, key=lambda q: float(np.sum((q - near) ** 2)))
        if not np.allclose(self.forward(best), target, atol=1e-6):  # the closed form must agree with the model
            raise IKError("unreachable", "no exact joint solution for the target (numerically singular)")
        return best

    def _solutions(self, target: Matrix, near: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        """Every closed-form solution (shoulder x elbow x wrist), each joint shifted by whole turns
        to the value nearest ``near``.

        The wrist centre fixes joints 1-3 (a planar two-link problem once joint 1 points the arm
        at it); joints 4-6 are then the Z-Y-Z Euler angles of the wrist rotation.
        """
        g = self.geometry
        rot = target[:3, :3]
        wrist = target[:3, 3] - g.d6 * rot[:, 2]
        link2 = math.hypot(g.a3, g.d4)
        beta = math.atan2(g.d4, -g.a3)
        out: list[NDArray[np.float64]] = []
        radial = math.hypot(wrist[0], wrist[1])
        shoulders = [(math.atan2(wrist[1], wrist[0]), radial), (math.atan2(wrist[1], wrist[0]) + math.pi, -radial)]
        if radial < 1e-9:  # wrist on the base axis: joint 1 is free, keep it
            shoulders = [(near[0], 0.0), (near[0] + math.pi, 0.0)]
        for q1, r in shoulders:
            x, y = r - g.a1, wrist[2] - g.d1
            cos_gamma = (x * x + y * y - g.a2**2 - link2**2) / (2 * g.a2 * link2)
            if abs(cos_gamma) > 1 + 1e-12:
                continue
            cos_gamma = max(-1.0, min(1.0, cos_gamma))
            for gamma in {math.acos(cos_gamma), -math.acos(cos_gamma)}:
                phi2 = math.atan2(y, x) - math.atan2(link2 * math.sin(gamma), g.a2 + link2 * math.cos(gamma))
                q2, q3 = -phi2, beta - gamma
                r36 = (_rz(q1) @ _ry(q2 + q3)).T @ rot
                for q4, q5, q6 in _wrist_solutions(r36, near[3]):
                    out.append(self._into_limits(np.array([q1, q2, q3, q4, q5, q6]), near))
        return out

    def _into_limits(self, q: NDArray[np.float64], near: NDArray[np.float64]) -> NDArray[np.float64]:
        """Shift each joint by whole turns to the in-range value closest to ``near``."""
        out = q.copy()
        for i in range(6):
            candidates = [q[i] + k * 2 * math.pi for k in range(-2, 3)]
            inside = [c for c in candidates if self.lower[i] - 1e-9 <= c <= self.upper[i] + 1e-9]
            out[i] = min(inside or candidates, key=lambda c: abs(c - near[i]))
        return out


def _wrist_solutions(r: Matrix, q4_near: float) -> list[tuple[float, float, float]]:
    """Joints 4-6 for the wrist rotation ``r = Rz(q4) Ry(q5) Rz(q6)``: both flips, or the
    singular case (q5 = 0) with joint 4 kept where it is."""
    s5 = math.hypot(r[0, 2], r[1, 2])
    if s5 < 1e-9:
        total = math.atan2(r[1, 0], r[0, 0])
        if r[2, 2] > 0:
            return [(q4_near, 0.0, total - q4_near)]
        return [(q4_near, math.pi, -math.atan2(r[1, 0], -r[0, 0]) + q4_near)]
    q5 = math.atan2(s5, r[2, 2])
    q4 = math.atan2(r[1, 2], r[0, 2])
    # Joint 6 from what joints 4 and 5 leave of the rotation, not from r's third row: near q5 = 0 joint 4's
    # angle is known only to about eps / sin(q5), and joint 6 taken this way absorbs that error (q4 + q6 is
    # what the rotation fixes there), so the flange lands on the target to rounding at any q5.
    rest = (_rz(q4) @ _ry(q5)).T @ r
    q6 = math.atan2(rest[1, 0], rest[0, 0])
    return [(q4, q5, q6), (q4 + math.pi, -q5, q6 + math.pi)]
