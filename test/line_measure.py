"""How far executed TCP poses are from a commanded straight line, measured by brute force.

Independent of :mod:`core_functions.linear_path` on purpose: the tests judge the sampler with a
different computation (orientation along the line as ``q0 * exp(s * log(q0^-1 q1))`` from
pinocchio's ``log3`` instead of a slerp in R^4, the nearest line pose found on nested grids
instead of a golden-section search), so a shared mistake cannot pass unnoticed.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from core_functions.geometry import Pose

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Worst:
    """The executed pose farthest from the line, in tolerance units, and its two errors."""

    ratio: float  # max(position / tolerance, angle / tolerance) at the nearest pose of the line
    position: float  # m, at that pose of the line
    angle: float  # rad, at that pose of the line
    off_segment: float  # m, the largest distance of any executed position from the segment


def _qmul(a: Array, b: Array) -> Array:
    """Hamilton products of quaternions (x, y, z, w), broadcast over rows."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


class LineMeasure:
    """Distances of poses from the line ``start`` -> ``end`` (position lerp, orientation geodesic)."""

    def __init__(self, start: Pose, end: Pose, position_tolerance: float, angle_tolerance: float) -> None:
        self.p0 = np.array(start.position)
        self.dp = np.array(end.position) - self.p0
        self.q0 = np.array(start.quaternion)
        self.omega = pin.log3(start.matrix()[:3, :3].T @ end.matrix()[:3, :3])  # rotation vector, start frame
        self.tp, self.ta = position_tolerance, angle_tolerance

    def _errors(self, pose: Pose, s: Array) -> tuple[Array, Array]:
        positions = self.p0 + s[:, None] * self.dp
        dp = np.linalg.norm(np.array(pose.position) - positions, axis=1)
        theta = float(np.linalg.norm(self.omega))
        axis = self.omega / theta if theta > 1e-12 else np.zeros(3)
        half = s * theta / 2.0
        steps = np.column_stack([np.sin(half)[:, None] * axis, np.cos(half)])
        along = _qmul(np.broadcast_to(self.q0, steps.shape), steps)  # q0 * exp(s * omega / 2)
        conj = along * np.array([-1.0, -1.0, -1.0, 1.0])
        rel = _qmul(conj, np.broadcast_to(np.array(pose.quaternion), along.shape))
        da = 2.0 * np.arctan2(np.linalg.norm(rel[:, :3], axis=1), np.abs(rel[:, 3]))
        return dp, da

    def nearest(self, pose: Pose) -> tuple[float, float, float]:
        """(ratio, position error, angle error) at the pose of the line nearest ``pose``."""
        lo, hi = 0.0, 1.0
        best = 0
        for _ in range(3):  # a coarse grid, then finer ones around its best: 2.5e-8 of the line at last
            s = np.linspace(lo, hi, 401)
            dp, da = self._errors(pose, s)
            ratio = np.maximum(dp / self.tp, da / self.ta)
            best = int(np.argmin(ratio))
            step = (hi - lo) / 400
            lo, hi = max(0.0, s[best] - step), min(1.0, s[best] + step)
        return float(ratio[best]), float(dp[best]), float(da[best])

    def off_segment(self, pose: Pose) -> float:
        offset = np.array(pose.position) - self.p0
        length2 = float(self.dp @ self.dp)
        s = 0.0 if length2 == 0.0 else min(1.0, max(0.0, float(offset @ self.dp) / length2))
        return float(np.linalg.norm(offset - s * self.dp))

    def worst(self, poses: Iterable[Pose]) -> Worst:
        found = Worst(0.0, 0.0, 0.0, 0.0)
        farthest = 0.0
        for pose in poses:
            farthest = max(farthest, self.off_segment(pose))
            ratio, dp, da = self.nearest(pose)
            if ratio > found.ratio:
                found = Worst(ratio, dp, da, 0.0)
        return Worst(found.ratio, found.position, found.angle, farthest)

    def describe(self, worst: Worst) -> str:
        return (
            f"{worst.off_segment * 1000:.4f} mm off the segment; nearest line pose {worst.position * 1000:.4f} mm / "
            f"{math.degrees(worst.angle):.4f} deg away ({worst.ratio:.2f} x the tolerance)"
        )
