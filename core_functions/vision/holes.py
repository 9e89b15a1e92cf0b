"""Holes on a known plane: blobs of the image mapped onto the part's surface and measured there.

A circle seen obliquely is an ellipse whose centre is *not* the image of the circle's centre
(perspective).  Mapping the fitted edge points through their rays onto the plane known from the
cell model and fitting there gives the circle itself: its centre and diameter in metres, exact
for any view angle.  The expected diameter then filters candidates, and the circle's centre
projected back is the hole's true image point (``center_px``), which is what stereo triangulation
needs.  :func:`find_holes` is the one detector: the Vision state calls it with the plane from the
cell model, the ``vision detect`` command with a plane seen head-on at a given distance.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.vision.camera import Intrinsics, from_plane, plane_points
from core_functions.vision.detect import Blob, Polarity, find_blobs

Array = NDArray[np.float64]

#: Accepted relative difference between a measured and the expected diameter.
DIAMETER_TOLERANCE = 0.25
#: A circle on the plane is round: major/minor axis ratio above this is not a hole.
MAX_ROUNDNESS = 1.25
#: Share of its rim a hole must show: less (a dark image corner under uneven light, a hole cut by the image border)
#: fits any circle, and its centre is no measurement.
MIN_COVERAGE = 0.5


@dataclass(frozen=True)
class Hole:
    """A circular feature found on the plane (optical frame: x right, y down, z forward; metres)."""

    center_px: tuple[float, float]
    center_m: tuple[float, float, float]
    diameter_m: float
    score: float
    plane_xy: tuple[float, float]  # the centre in the plane's own coordinates (m)
    residual_m: float  # RMS distance of the edge points from the fitted circle, on the plane
    edge_width_px: float
    blob: Blob

    def as_json(self) -> dict[str, object]:
        return {
            "center_px": [round(self.center_px[0], 4), round(self.center_px[1], 4)],
            "center_m": [round(v, 7) for v in self.center_m],
            "diameter_m": round(self.diameter_m, 7),
            "score": round(self.score, 4),
        }


def head_on(distance: float) -> Array:
    """The plane z = ``distance`` of the optical frame, seen head-on (its axes those of the camera)."""
    if not (math.isfinite(distance) and distance > 0):
        raise ValueError(f"the plane's distance must be a positive number of metres, got {distance!r}")
    plane = np.eye(4)
    plane[2, 3] = distance
    return plane


def size_range(intrinsics: Intrinsics, plane_in_camera: Array, diameter: float) -> tuple[float, float] | None:
    """Smallest and largest image size (px) a circle of ``diameter`` on the plane can have in this image."""
    w, h = intrinsics.width, intrinsics.height
    probes = np.array([[u, v] for u in np.linspace(0, w - 1, 5) for v in np.linspace(0, h - 1, 5)])
    xy = plane_points(intrinsics, plane_in_camera, probes)
    ok = np.all(np.isfinite(xy), axis=1)
    if not ok.any():
        return None
    depths = from_plane(plane_in_camera, xy[ok])[:, 2]
    f = max(intrinsics.fx, intrinsics.fy)
    normal_z = abs(float(plane_in_camera[2, 2]))  # cosine of the view angle on the optical axis
    largest = f * diameter / float(depths.min())
    smallest = min(intrinsics.fx, intrinsics.fy) * diameter / float(depths.max()) * max(0.2, normal_z * 0.7)
    return max(3.0, smallest * 0.7), largest * 1.4 + 4.0


def find_holes(
    image: NDArray[np.generic],
    intrinsics: Intrinsics,
    plane_in_camera: Array,
    diameter: float,
    polarity: Polarity = "dark",
    tolerance: float = DIAMETER_TOLERANCE,
) -> list[Hole]:
    """Every circle of about ``diameter`` (m) on the plane ``plane_in_camera`` (4x4, optical frame), best first."""
    if not (math.isfinite(diameter) and diameter > 0):
        raise ValueError(f"the hole diameter must be a positive number of metres, got {diameter!r}")
    shape = np.asarray(image).shape
    if shape[0] != intrinsics.height or shape[1] != intrinsics.width:
        raise ValueError(f"the image is {shape[1]}x{shape[0]} px but the camera model says {intrinsics.width}x{intrinsics.height}")
    sizes = size_range(intrinsics, plane_in_camera, diameter)
    if sizes is None:
        return []
    holes = []
    for blob in find_blobs(image, polarity, *sizes):
        hole = _on_plane(blob, intrinsics, plane_in_camera, diameter, tolerance)
        if hole is not None:
            holes.append(hole)
    return sorted(holes, key=lambda h: -h.score)


def _on_plane(blob: Blob, intrinsics: Intrinsics, plane: Array, diameter: float, tolerance: float) -> Hole | None:
    if blob.coverage < MIN_COVERAGE:
        return None
    xy = plane_points(intrinsics, plane, blob.edge)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) < 8:
        return None
    scale = 1.0 / diameter  # fit in units of the expected diameter: well-conditioned at any size
    (cx, cy), (d1, d2), _ = cv2.fitEllipse((xy * scale).astype(np.float32))
    if not (d1 > 0 and d2 > 0):
        return None
    major, minor = max(d1, d2) / scale, min(d1, d2) / scale
    measured = 0.5 * (major + minor)
    if major / minor > MAX_ROUNDNESS or abs(measured - diameter) > tolerance * diameter:
        return None
    centre = np.array([cx, cy]) / scale
    radial = np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) - 0.5 * measured
    residual = float(np.sqrt(np.mean(radial**2)))
    point = from_plane(plane, centre)[0]
    if point[2] <= 0:
        return None
    pixel = intrinsics.project(point)[0]
    score = blob.coverage * math.exp(-residual / (0.02 * diameter)) * math.exp(-abs(measured - diameter) / (0.1 * diameter))
    return Hole(
        (float(pixel[0]), float(pixel[1])),
        (float(point[0]), float(point[1]), float(point[2])),
        float(measured),
        float(min(1.0, max(0.0, score))),
        (float(centre[0]), float(centre[1])),
        residual,
        blob.edge_width,
        blob,
    )


def detect_head_on(image: NDArray[np.generic], intrinsics: Intrinsics, distance: float, diameter: float) -> list[Hole]:
    """Holes of ``diameter`` on a plane seen head-on at ``distance`` (the ``vision detect`` command)."""
    return find_holes(image, intrinsics, head_on(distance), diameter)
