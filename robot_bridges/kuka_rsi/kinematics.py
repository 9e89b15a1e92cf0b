"""Kinematics of a KUKA KR 6 R900 sixx (KR AGILUS): forward, analytic inverse, KUKA's A/B/C angles.

The simulator needs them to turn Cartesian corrections (``RKorr``) into joint motion and to
report ``RIst``/``RSol``; the bridge needs the inverse to run a point-to-point move to a pose.
The geometry is the published one of ROS-Industrial's ``kuka_kr6_support`` description
(``kr6r900sixx_macro.xacro``): A1 at 0.400 m above the base turning about -z, A2 0.025 m ahead of
it, an upper arm of 0.455 m, a forearm offset of 0.035 m and length 0.420 m, a spherical wrist and
0.080 m to the flange.  The flange frame is that description's ``tool0``, which it documents as
KUKA's ``$FLANGE`` (so at the home pose A=0, B=90 deg, C=0).  The joint signs are KUKA's (A1, A4
and A6 turn about negative axes), so controller angles go in unchanged.

The inverse is closed-form (the wrist is spherical): up to eight solutions, of which the one
nearest a reference configuration and inside the joint limits is returned.  ``test_rsi_kinematics``
checks the forward model against pinocchio built from the same description.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core_functions.robots import KUKA_KR, JointSpec

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]


@dataclass(frozen=True)
class ArmGeometry:
    """Link lengths (m) of a KR-type arm with the A2/A3 offsets of the KR AGILUS family."""

    base_height: float = 0.400  # base -> A2 (z)
    shoulder_offset: float = 0.025  # A1 axis -> A2 (x)
    upper_arm: float = 0.455  # A2 -> A3 (x)
    forearm_offset: float = 0.035  # A3 -> A4 (z)
    forearm: float = 0.420  # A4 -> wrist centre (x)
    flange: float = 0.080  # wrist centre -> flange (x)


KR6_R900 = ArmGeometry()
#: The same arm as a URDF (root ``base``, flange link ``tool0``), for robot_description and tf.
URDF_PATH = Path(__file__).resolve().parent / "urdf" / "kuka_kr6_r900.urdf"
_FLANGE_FROM_LINK6 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # Ry(+90 deg)


def _rx(a: float) -> Matrix:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> Matrix:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> Matrix:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# ------------------------------------------------------------------------------ KUKA angles
def abc_to_matrix(a: float, b: float, c: float) -> Matrix:
    """KUKA A, B, C (rad): rotations about Z, then the new Y, then the new X: ``Rz(A) Ry(B) Rx(C)``."""
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    return np.array(
        [
            [ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
            [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
            [-sb, cb * sc, cb * cc],
        ]
    )


def matrix_to_abc(r: Matrix) -> tuple[float, float, float]:
    """The A, B, C (rad) of a rotation matrix; at B = +-90 deg, C is taken as 0."""
    sb = -float(r[2, 0])
    cb = math.hypot(float(r[0, 0]), float(r[1, 0]))
    b = math.atan2(sb, cb)
    if cb > 1e-9:
        return math.atan2(float(r[1, 0]), float(r[0, 0])), b, math.atan2(float(r[2, 1]), float(r[2, 2]))
    return math.atan2(-float(r[0, 1]), float(r[1, 1])), b, 0.0


def rotation_angle(r: Matrix) -> float:
    """The angle (rad, 0..pi) of a rotation matrix; atan2 keeps full precision near 0 and pi, where acos does not."""
    sine = math.hypot(float(r[2, 1] - r[1, 2]), float(r[0, 2] - r[2, 0]), float(r[1, 0] - r[0, 1])) / 2.0
    cosine = (float(r[0, 0] + r[1, 1] + r[2, 2]) - 1.0) / 2.0
    return math.atan2(sine, cosine)


def frame(x: float, y: float, z: float, rotation: Matrix) -> Matrix:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = (x, y, z)
    return m


# ---------------------------------------------------------------------------------- model
class KukaArm:
    """Forward and inverse kinematics of one arm; joint values in rad, lengths in m."""

    def __init__(self, geometry: ArmGeometry = KR6_R900, joints: tuple[JointSpec, ...] = KUKA_KR.group("arm").joints) -> None:
        self.g = geometry
        self.joints = joints
        self.lower = np.array([j.lower for j in joints])
        self.upper = np.array([j.upper for j in joints])
        self._delta = math.atan2(geometry.forearm_offset, geometry.forearm)
        self._forearm_length = math.hypot(geometry.forearm_offset, geometry.forearm)

    def fk(self, q: Vector | tuple[float, ...]) -> Matrix:
        """The flange frame (4x4) in the robot base for joint values ``q``."""
        q1, q2, q3, q4, q5, q6 = (float(v) for v in q)
        g = self.g
        r1 = _rz(-q1)
        r3 = r1 @ _ry(q2 + q3)
        elbow = r1 @ _ry(q2) @ np.array([g.upper_arm, 0.0, 0.0])
        wrist = np.array([0.0, 0.0, g.base_height]) + r1 @ np.array([g.shoulder_offset, 0.0, 0.0]) + elbow
        wrist = wrist + r3 @ np.array([g.forearm, 0.0, g.forearm_offset])
        r6 = r3 @ _rx(-q4) @ _ry(q5) @ _rx(-q6)
        flange = wrist + r6 @ np.array([g.flange, 0.0, 0.0])
        return frame(flange[0], flange[1], flange[2], r6 @ _FLANGE_FROM_LINK6)

    def within_limits(self, q: Vector | tuple[float, ...], tolerance: float = 1e-9) -> bool:
        qa = np.asarray(q, dtype=float)
        return bool(np.all(qa >= self.lower - tolerance) and np.all(qa <= self.upper + tolerance))

    def ik_all(self, target: Matrix, reference: Vector | tuple[float, ...] | None = None) -> list[Vector]:
        """Every joint solution reaching ``target`` inside the limits, each angle taken from its
        ``+-2 pi`` twins nearest to ``reference`` (KUKA wrists turn more than a full turn)."""
        ref = np.zeros(6) if reference is None else np.asarray(reference, dtype=float)
        g = self.g
        rot = np.asarray(target[:3, :3], dtype=float)
        r6 = rot @ _FLANGE_FROM_LINK6.T
        wrist = np.asarray(target[:3, 3], dtype=float) - g.flange * r6[:, 0]
        px, py, pz = (float(v) for v in wrist)
        horizontal = math.hypot(px, py)
        solutions: list[Vector] = []
        for front in (True, False):
            q1 = math.atan2(-py, px) if front else math.atan2(py, -px)
            if horizontal < 1e-9:
                q1 = float(ref[0]) if front else float(ref[0]) + math.pi
            reach = px * math.cos(q1) - py * math.sin(q1)
            dx, dz = reach - g.shoulder_offset, pz - g.base_height
            a2, lf = g.upper_arm, self._forearm_length
            cos_gamma = (dx * dx + dz * dz - a2 * a2 - lf * lf) / (2.0 * a2 * lf)
            if abs(cos_gamma) > 1.0 + 1e-9:
                continue  # out of reach for this shoulder side
            cos_gamma = max(-1.0, min(1.0, cos_gamma))
            for elbow in (1.0, -1.0):
                gamma = elbow * math.acos(cos_gamma)
                alpha = math.atan2(dz, dx) - math.atan2(lf * math.sin(gamma), a2 + lf * math.cos(gamma))
                q2 = -alpha
                q3 = self._delta - gamma
                m = (_rz(-q1) @ _ry(q2 + q3)).T @ r6
                for q4, q5, q6 in self._wrist(m, float(ref[3])):
                    q = self._nearest_turns(np.array([q1, q2, q3, q4, q5, q6]), ref)
                    if q is not None:
                        solutions.append(q)
        return [s for s in solutions if self._reaches(s, target)]

    def ik(self, target: Matrix, reference: Vector | tuple[float, ...]) -> Vector | None:
        """The solution reaching ``target`` nearest to ``reference`` (None when unreachable)."""
        ref = np.asarray(reference, dtype=float)
        candidates = self.ik_all(target, ref)
        if not candidates:
            return None
        return min(candidates, key=lambda s: float(np.sum((s - ref) ** 2)))

    # ------------------------------------------------------------------------------ helpers
    @staticmethod
    def _wrist(m: Matrix, q4_reference: float) -> list[tuple[float, float, float]]:
        """(q4, q5, q6) with ``m = Rx(-q4) Ry(q5) Rx(-q6)``; both wrist flips."""
        sin_b = math.hypot(float(m[0, 1]), float(m[0, 2]))
        cos_b = float(m[0, 0])
        if sin_b < 1e-9:  # wrist singular: only q4 + q6 is determined (b = 0); keep q4 where it was
            a = -q4_reference
            if cos_b > 0:
                total = math.atan2(float(m[2, 1]), float(m[1, 1]))  # m = Rx(a + c)
                return [(q4_reference, 0.0, -(total - a))]
            total = math.atan2(-float(m[2, 1]), -float(m[1, 1]))  # b = pi: m = Rx(a) Ry(pi) Rx(c) -> a - c
            return [(q4_reference, math.pi, (total - a))]
        result = []
        for sign in (1.0, -1.0):
            sb = sign * sin_b
            b = math.atan2(sb, cos_b)
            a = math.atan2(float(m[1, 0]) / sb, -float(m[2, 0]) / sb)
            c = math.atan2(float(m[0, 1]) / sb, float(m[0, 2]) / sb)
            result.append((-a, b, -c))
        return result

    def _nearest_turns(self, q: Vector, reference: Vector) -> Vector | None:
        """Each angle moved by whole turns to lie inside its limits, nearest to ``reference``."""
        out = q.copy()
        for i in range(6):
            best = None
            for k in (-2, -1, 0, 1, 2):
                value = q[i] + k * 2 * math.pi
                if self.lower[i] - 1e-7 <= value <= self.upper[i] + 1e-7 and (
                    best is None or abs(value - reference[i]) < abs(best - reference[i])
                ):
                    best = value
            if best is None:
                return None
            out[i] = best
        return out

    def _reaches(self, q: Vector, target: Matrix) -> bool:
        got = self.fk(q)
        return bool(np.allclose(got[:3, 3], target[:3, 3], atol=1e-6) and np.allclose(got[:3, :3], target[:3, :3], atol=1e-6))
