"""Locate one feature of the cell in one or two camera views: the Vision state's measurement.

Each view is an image with its camera's intrinsics and the pose of its optical frame in the world
at the instant of capture (hand-eye mount composed with the robot's forward kinematics).  The
feature's nominal pose gives the plane to measure on and where to look; the detector's circles
within the search radius are the candidates.  Exactly one must fit: none (not in view, out of
focus, not there) or several (two holes where one is expected) is a :class:`VisionFault`, since
guessing would put a rivet beside a hole.  With two views (the head's stereo pair) the hole's
image points are triangulated; with one, the ray meets the part plane.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics, triangulate
from core_functions.vision.features import FeatureModel
from core_functions.vision.holes import Hole, find_holes
from core_functions.vision.sharpness import sharpness

#: A hole whose edge is softer than this share of its radius (in the image) is out of focus.
MAX_BLUR = 0.6


class VisionFault(Exception):
    """Nothing, or more than one thing, fits: the caller turns it into a VISION fault."""


@dataclass(frozen=True)
class View:
    """One image and where its camera was when it was taken."""

    camera: str
    image: NDArray[np.uint8]
    intrinsics: Intrinsics
    pose: Pose  # optical frame (x right, y down, z forward) in the world at capture time


@dataclass(frozen=True)
class Located:
    """Where the feature is (world), how sure, and what each view saw."""

    pose: Pose
    score: float
    residual: float  # m: plane fit RMS (one view) or stereo disagreement (two views)
    diameter: float
    method: str  # "plane" or "stereo"
    holes: tuple[Hole, ...]
    sharpness: float


def _in_view(view: View, target: str, nominal: Pose, model: FeatureModel) -> NDArray[np.float64]:
    """The nominal plane in the camera; VisionFault when the feature cannot be in the image."""
    plane = np.linalg.inv(view.pose.matrix()) @ nominal.matrix()
    centre = plane[:3, 3]
    intr = view.intrinsics
    where = f"{target} is outside the view of {view.camera}"
    if centre[2] <= 1e-6:
        raise VisionFault(f"{where}: it is behind the camera ({centre[2] * 1000:.1f} mm along its axis)")
    pixel = intr.project(centre)[0]
    radius_px = 0.5 * model.diameter * intr.fx / centre[2]
    if not intr.contains(pixel, margin=radius_px):
        raise VisionFault(f"{where}: its nominal position projects to ({pixel[0]:.0f}, {pixel[1]:.0f}) px, the image is {intr.width}x{intr.height}")
    return plane


def feature_roi(view: View, nominal: Pose, diameter: float, size: float = 3.0) -> tuple[int, int, int, int] | None:
    """The image box (x, y, w, h) of ``size`` diameters around the feature's nominal position, None if not in view."""
    centre = (np.linalg.inv(view.pose.matrix()) @ np.append(nominal.position, 1.0))[:3]
    if centre[2] <= 1e-6:
        return None
    u, v = view.intrinsics.project(centre)[0]
    half = 0.5 * size * diameter * view.intrinsics.fx / centre[2]
    if not view.intrinsics.contains(np.array([u, v])):
        return None
    return int(u - half), int(v - half), int(2 * half) + 1, int(2 * half) + 1


def _one_view(view: View, target: str, nominal: Pose, model: FeatureModel) -> Hole:
    plane = _in_view(view, target, nominal, model)
    holes = find_holes(view.image, view.intrinsics, plane, model.diameter, model.polarity)
    near = [h for h in holes if math.hypot(*h.plane_xy) <= model.search_radius]
    radius_px = [0.25 * (h.blob.axes[0] + h.blob.axes[1]) for h in near]
    sharp = [h for h, r in zip(near, radius_px) if h.edge_width_px <= MAX_BLUR * r + 2.0]
    what = f"{'hole' if model.polarity == 'dark' else 'disc'} of {model.diameter * 1000:.2f} mm"
    image = f"{view.camera}'s {view.intrinsics.width}x{view.intrinsics.height} image"
    if not sharp:
        if near:
            blur = max(h.edge_width_px for h in near)
            raise VisionFault(f"{target}: {image} is out of focus (edge {blur:.1f} px wide; sharpness {sharpness(view.image):.2f})")
        elsewhere = f"; {len(holes)} elsewhere in the image" if holes else ""
        raise VisionFault(
            f"{target}: no {what} within {model.search_radius * 1000:.1f} mm of its nominal position in {image}"
            f"{elsewhere} (sharpness {sharpness(view.image):.2f})"
        )
    if len(sharp) > 1:
        listed = ", ".join(f"{math.hypot(*h.plane_xy) * 1000:.2f} mm off (score {h.score:.2f})" for h in sharp)
        raise VisionFault(f"{target}: {len(sharp)} candidates fit in {image}, ambiguous: {listed}")
    return sharp[0]


def locate(views: Sequence[View], target: str, nominal: Pose, model: FeatureModel) -> Located:
    """The measured world pose of ``target`` (nominal orientation, measured position); VisionFault if not exactly one fits."""
    if not views:
        raise VisionFault(f"{target}: no image to look at")
    holes = tuple(_one_view(view, target, nominal, model) for view in views)
    points = [view.pose.matrix() @ np.append(h.center_m, 1.0) for view, h in zip(views, holes)]
    if len(views) >= 2:
        left, right = views[0], views[1]
        point, _ = triangulate(
            (left.intrinsics, left.pose.matrix(), np.array(holes[0].center_px)),
            (right.intrinsics, right.pose.matrix(), np.array(holes[1].center_px)),
        )
        residual = float(np.mean([np.linalg.norm(p[:3] - point) for p in points]))
        method = "stereo"
    else:
        point, residual, method = points[0][:3], holes[0].residual_m, "plane"
    measured = Pose(float(point[0]), float(point[1]), float(point[2]), *nominal.quaternion)
    return Located(
        pose=measured,
        score=float(min(h.score for h in holes)),
        residual=float(residual),
        diameter=float(np.mean([h.diameter_m for h in holes])),
        method=method,
        holes=holes,
        sharpness=sharpness(views[0].image),
    )
