"""The pinhole camera model and the geometry of pixels: rays, planes, stereo triangulation.

Frames follow REP 103's optical convention: x right, y down, z along the optical axis, metres.
A camera's pose is the pose of its optical frame; images are undistorted (a real camera's
driver publishes rectified images, and the simulator renders without distortion).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Rotation from a body frame (x forward, y left, z up) to its optical frame (x right, y down, z forward).
OPTICAL_IN_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class Intrinsics:
    """Image size (px) and pinhole parameters (px): what a ``sensor_msgs/CameraInfo`` K holds."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if not (self.width > 0 and self.height > 0):
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if not (self.fx > 0 and self.fy > 0):
            raise ValueError(f"focal lengths must be positive, got fx={self.fx} fy={self.fy}")

    @staticmethod
    def from_fov(width: int, height: int, horizontal_fov: float) -> Intrinsics:
        """Square pixels, principal point at the image centre, ``horizontal_fov`` in rad."""
        f = 0.5 * width / math.tan(0.5 * horizontal_fov)
        return Intrinsics(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    def matrix(self) -> Array:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points: Array) -> Array:
        """N x 3 points in the optical frame (z > 0) -> N x 2 pixel coordinates."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        z = p[:, 2]
        return np.column_stack((self.fx * p[:, 0] / z + self.cx, self.fy * p[:, 1] / z + self.cy))

    def rays(self, pixels: Array) -> Array:
        """N x 2 pixels -> N x 3 ray directions in the optical frame (z = 1, not normalised)."""
        uv = np.atleast_2d(np.asarray(pixels, dtype=float))
        return np.column_stack(((uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy, np.ones(len(uv))))

    def contains(self, pixel: Array, margin: float = 0.0) -> bool:
        u, v = float(pixel[0]), float(pixel[1])
        return -0.5 + margin <= u <= self.width - 0.5 - margin and -0.5 + margin <= v <= self.height - 0.5 - margin

    def pixel_size_at(self, depth: float) -> float:
        """Metres per pixel on a fronto-parallel plane at ``depth`` (mean of both axes)."""
        return depth * 0.5 * (1.0 / self.fx + 1.0 / self.fy)


def plane_points(intrinsics: Intrinsics, plane_in_camera: Array, pixels: Array) -> Array:
    """Where the rays of ``pixels`` meet the xy plane of ``plane_in_camera`` (4x4): N x 2 plane coordinates (m).

    Rays parallel to the plane or meeting it behind the camera give NaN rows.
    """
    rays = intrinsics.rays(pixels)
    rotation, origin = plane_in_camera[:3, :3], plane_in_camera[:3, 3]
    normal = rotation[:, 2]
    denom = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (origin @ normal) / denom
    t = np.where((np.abs(denom) > 1e-12) & (t > 0), t, np.nan)
    hits = rays * t[:, None]
    local = (hits - origin) @ rotation  # into plane coordinates
    return local[:, :2]


def ray_plane(intrinsics: Intrinsics, plane_in_camera: Array, pixel: Array) -> Array | None:
    """The 3D point (optical frame) where the ray of one pixel meets the plane, or None."""
    xy = plane_points(intrinsics, plane_in_camera, np.asarray([pixel], dtype=float))[0]
    if not np.all(np.isfinite(xy)):
        return None
    return plane_in_camera[:3, :3] @ np.array([xy[0], xy[1], 0.0]) + plane_in_camera[:3, 3]


def from_plane(plane_in_camera: Array, xy: Array) -> Array:
    """Plane coordinates (N x 2) -> points in the optical frame (N x 3)."""
    p = np.atleast_2d(np.asarray(xy, dtype=float))
    local = np.column_stack((p, np.zeros(len(p))))
    return local @ plane_in_camera[:3, :3].T + plane_in_camera[:3, 3]


def projection_matrix(intrinsics: Intrinsics, camera_in_world: Array) -> Array:
    """3x4 P = K [R | t] mapping world points to pixels for a camera whose optical frame is ``camera_in_world``."""
    world_to_camera = np.linalg.inv(camera_in_world)
    return intrinsics.matrix() @ world_to_camera[:3, :]


def triangulate(
    left: tuple[Intrinsics, Array, Array], right: tuple[Intrinsics, Array, Array]
) -> tuple[Array, float]:
    """World point seen at pixel ``uv`` by two cameras, each ``(intrinsics, camera_in_world, uv)``.

    Linear triangulation (OpenCV's DLT); returns the point and its mean reprojection error (px).
    """
    p1 = projection_matrix(left[0], left[1])
    p2 = projection_matrix(right[0], right[1])
    uv1 = np.asarray(left[2], dtype=float).reshape(2, 1)
    uv2 = np.asarray(right[2], dtype=float).reshape(2, 1)
    h = cv2.triangulatePoints(p1, p2, uv1, uv2)[:, 0]
    point = h[:3] / h[3]
    errors = []
    for p, uv in ((p1, uv1), (p2, uv2)):
        x = p @ np.append(point, 1.0)
        errors.append(float(np.hypot(x[0] / x[2] - uv[0, 0], x[1] / x[2] - uv[1, 0])))
    return point, float(np.mean(errors))
