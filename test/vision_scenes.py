"""Rendered test scenes for the vision tests and the accuracy bench: a plate with holes seen by a camera."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from robot_bridges.camera.render import Disc, Lighting, Optics, Scene, Surface, render

INTRINSICS = Intrinsics.from_fov(640, 480, math.radians(60.0))
DIAMETER = 0.0048


@dataclass(frozen=True)
class Shot:
    image: np.ndarray
    camera: Pose  # optical frame in the world (the plate is the world's xy plane)
    holes: tuple[tuple[float, float], ...]  # true centres on the plate (m)

    def plane(self) -> np.ndarray:
        return np.linalg.inv(self.camera.matrix())


def looking_down(distance: float, tilt: float = 0.0, yaw: float = 0.0, at: tuple[float, float] = (0.0, 0.0)) -> Pose:
    """A camera ``distance`` from the point ``at`` of the plate, its axis ``tilt`` rad from the normal."""
    return (
        Pose(at[0], at[1], 0.0)
        .compose(Pose.from_xyz_rpy(0, 0, 0, 0, 0, yaw))
        .compose(Pose.from_xyz_rpy(0, 0, 0, tilt, 0, 0))
        .compose(Pose.from_xyz_rpy(0, 0, 0, math.pi, 0, 0))
        .compose(Pose(0, 0, -distance))
    )


def shoot(
    holes: tuple[tuple[float, float], ...],
    camera: Pose,
    *,
    focus: float | None = None,
    aperture: float = 0.002,
    noise: float = 0.008,
    gradient: tuple[float, float] = (0.25, -0.15),
    extra: tuple[Surface, ...] = (),
    seed: int = 0,
    diameter: float = DIAMETER,
    albedo: float = 0.06,
) -> Shot:
    plate = Surface(np.eye(4), (0.2, 0.2), 0.75, tuple(Disc(x, y, diameter, albedo) for x, y in holes))
    scene = Scene((plate, *extra), Lighting(gradient))
    optics = Optics(focus if focus is not None else float(np.linalg.norm(camera.position)), aperture=aperture, read_noise=noise)
    image = render(scene, INTRINSICS, camera.matrix(), optics, np.random.default_rng(seed))
    return Shot(image, camera, holes)
