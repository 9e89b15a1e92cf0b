"""Poses the way every part of the project exchanges them: metres and unit quaternions (REP 103).

A :class:`Pose` is immutable, JSON-friendly (plain floats) and converts to and from 4x4
homogeneous matrices and roll/pitch/yaw (fixed-axis X-Y-Z, as URDF ``rpy``), so cell models,
primitives, simulators and bridges agree on one convention.  Bridges that speak other units
(V+: mm and degrees, yaw-pitch-roll) convert at their edge.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    Matrix = NDArray[np.float64]


@dataclass(frozen=True)
class Pose:
    """Position (m) and orientation (unit quaternion x, y, z, w) of a frame in its parent."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    qx: float = 0.0
    qy: float = 0.0
    qz: float = 0.0
    qw: float = 1.0

    def __post_init__(self) -> None:
        values = (self.x, self.y, self.z, self.qx, self.qy, self.qz, self.qw)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"pose has a non-finite component: {values}")
        norm = math.sqrt(self.qx**2 + self.qy**2 + self.qz**2 + self.qw**2)
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"pose quaternion must have unit length, has {norm:.6f}")

    # ---------------------------------------------------------------------- constructors
    @staticmethod
    def from_xyz_rpy(x: float, y: float, z: float, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> Pose:
        qx, qy, qz, qw = rpy_to_quaternion(roll, pitch, yaw)
        return Pose(x, y, z, qx, qy, qz, qw)

    @staticmethod
    def from_matrix(m: Matrix) -> Pose:
        import numpy as np  # slow to load (0.1 s): only matrices need it, validate and functions never do

        qx, qy, qz, qw = matrix_to_quaternion(np.asarray(m, dtype=float)[:3, :3])
        return Pose(float(m[0, 3]), float(m[1, 3]), float(m[2, 3]), qx, qy, qz, qw)

    # ------------------------------------------------------------------------ accessors
    @property
    def position(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.z)

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        return (self.qx, self.qy, self.qz, self.qw)

    def rpy(self) -> tuple[float, float, float]:
        return quaternion_to_rpy(self.qx, self.qy, self.qz, self.qw)

    def matrix(self) -> Matrix:
        import numpy as np  # slow to load (0.1 s): only matrices need it, validate and functions never do

        m = np.eye(4)
        m[:3, :3] = quaternion_to_matrix(self.qx, self.qy, self.qz, self.qw)
        m[:3, 3] = (self.x, self.y, self.z)
        return m

    # ------------------------------------------------------------------------ algebra
    def compose(self, other: Pose) -> Pose:
        """``self * other``: ``other`` expressed in this frame, returned in this frame's parent.

        Quaternion algebra in plain floats: no numpy, so reading a cell (validate) does not load it, and
        a few times faster than 4x4 matrices for one pose."""
        ax, ay, az, aw = self.qx, self.qy, self.qz, self.qw
        bx, by, bz, bw = other.qx, other.qy, other.qz, other.qw
        px, py, pz = rotate(self.quaternion, other.position)
        q = (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        )
        return Pose(self.x + px, self.y + py, self.z + pz, *_canonical(*q))

    def inverse(self) -> Pose:
        conjugate = (-self.qx, -self.qy, -self.qz, self.qw)
        px, py, pz = rotate(conjugate, self.position)
        return Pose(-px, -py, -pz, *_canonical(*conjugate))

    def translated(self, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> Pose:
        """Shift along the *parent's* axes, keeping the orientation."""
        return Pose(self.x + dx, self.y + dy, self.z + dz, self.qx, self.qy, self.qz, self.qw)

    def offset_local(self, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> Pose:
        """Shift along this frame's *own* axes (an approach along the tool z, say)."""
        return self.compose(Pose(dx, dy, dz))

    def distance_to(self, other: Pose) -> float:
        return math.dist(self.position, other.position)

    def angle_to(self, other: Pose) -> float:
        """Rotation angle (rad) between the two orientations."""
        dot = abs(self.qx * other.qx + self.qy * other.qy + self.qz * other.qz + self.qw * other.qw)
        return 2.0 * math.acos(min(1.0, dot))

    def __str__(self) -> str:
        r, p, y = self.rpy()
        return (
            f"({self.x:.4f}, {self.y:.4f}, {self.z:.4f}) m, rpy ({math.degrees(r):.2f}, "
            f"{math.degrees(p):.2f}, {math.degrees(y):.2f}) deg"
        )


def rpy_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Fixed-axis X (roll), then Y (pitch), then Z (yaw), as in URDF: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    qw = cr * cp * cy + sr * sp * sy
    qx = sr * cp * cy - cr * sp * sy
    qy = cr * sp * cy + sr * cp * sy
    qz = cr * cp * sy - sr * sp * cy
    return _normalized(qx, qy, qz, qw)


def quaternion_to_rpy(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    sinp = 2.0 * (qw * qy - qz * qx)
    pitch = math.copysign(math.pi / 2, sinp) if abs(sinp) >= 1.0 else math.asin(sinp)
    roll = math.atan2(2.0 * (qw * qx + qy * qz), 1.0 - 2.0 * (qx * qx + qy * qy))
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return roll, pitch, yaw


def rotate(q: tuple[float, float, float, float], v: tuple[float, float, float]) -> tuple[float, float, float]:
    """The vector ``v`` rotated by the unit quaternion ``q`` (x, y, z, w): v + 2w (u x v) + 2 u x (u x v)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (qy * vz - qz * vy), 2.0 * (qz * vx - qx * vz), 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + qy * tz - qz * ty, vy + qw * ty + qz * tx - qx * tz, vz + qw * tz + qx * ty - qy * tx)


def quaternion_to_matrix(qx: float, qy: float, qz: float, qw: float) -> Matrix:
    import numpy as np  # slow to load (0.1 s): only matrices need it, validate and functions never do

    return np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )


def matrix_to_quaternion(r: Matrix) -> tuple[float, float, float, float]:
    """Shepperd's method: numerically stable for every rotation."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        qw, qx, qy, qz = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        qw, qx, qy, qz = (r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        qw, qx, qy, qz = (r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        qw, qx, qy, qz = (r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s
    return _canonical(float(qx), float(qy), float(qz), float(qw))


def _canonical(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float, float]:
    """One sign (w >= 0; at w = 0 the largest component positive, as Shepperd's method gives it) and unit length,
    so equal rotations give equal quaternions."""
    if qw < 0 or (qw == 0 and max((qx, qy, qz), key=abs) < 0):
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    return _normalized(qx, qy, qz, qw)


def _normalized(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float, float]:
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    return qx / n, qy / n, qz / n, qw / n
