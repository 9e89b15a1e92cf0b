"""A renderer of planar scenes as a camera sees them: perspective, soft edges, light, noise, defocus.

Why render at all: a detector proven on images that behave like real ones (holes seen obliquely
as ellipses, their chamfered edges soft, a lighting gradient across the part, sensor noise, a
blur that grows with the distance from the focus plane) is a detector that can be trusted with a
real camera; ground truth plus noise proves nothing about image processing.

Each pixel's ray is intersected with every surface (a rectangle in its own xy plane); the
nearest hit gives the surface's albedo, darkened or brightened inside its discs (holes, rivet
heads) with an edge ramp at least one pixel footprint wide (anti-aliasing).  Defocus is a
Gaussian whose sigma follows the thin-lens circle of confusion, ``aperture * f * |1/z - 1/z_f|``,
per pixel (the image blurred at a few levels and blended by depth).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.vision.camera import Intrinsics

Array = NDArray[np.float64]

#: What a ray that meets no surface sees (the dark cell floor far below), relative brightness.
BACKGROUND = 0.12


@dataclass(frozen=True)
class Disc:
    """A circular feature on a surface: centre in the surface's xy (m), diameter (m), brightness."""

    x: float
    y: float
    diameter: float
    albedo: float
    softness: float = 0.0002  # m: width of the edge ramp (the chamfer of a drilled hole)


@dataclass(frozen=True)
class Surface:
    """A flat rectangle: its pose in the world (4x4, the plane is its xy), half sizes (m), albedo, discs."""

    pose: Array
    half_size: tuple[float, float]
    albedo: float
    discs: tuple[Disc, ...] = ()


@dataclass(frozen=True)
class Optics:
    """The lens and sensor: focus distance (m), aperture (m), noise, exposure."""

    focus_distance: float
    aperture: float = 0.004  # m: entrance pupil diameter
    read_noise: float = 0.008  # relative standard deviation, independent of the signal
    shot_noise: float = 0.015  # relative standard deviation at full brightness (grows with sqrt(signal))
    gain: float = 0.85  # full-scale brightness of an albedo 1 surface

    def blur_sigma(self, intrinsics: Intrinsics, depth: Array | float) -> Array:
        """Defocus blur (px, Gaussian sigma ~ circle of confusion / 2) at ``depth`` (m)."""
        f = 0.5 * (intrinsics.fx + intrinsics.fy)
        z = np.maximum(np.asarray(depth, dtype=float), 1e-6)
        return 0.5 * self.aperture * f * np.abs(1.0 / z - 1.0 / self.focus_distance)


@dataclass(frozen=True)
class Lighting:
    """A linear gradient across the image and a vignette: what makes one threshold fail."""

    gradient: tuple[float, float] = (0.25, -0.15)  # relative change from the left/top edge to the right/bottom one
    vignette: float = 0.2

    def field(self, intrinsics: Intrinsics) -> Array:
        u = (np.arange(intrinsics.width) - intrinsics.cx) / intrinsics.width
        v = (np.arange(intrinsics.height) - intrinsics.cy) / intrinsics.height
        uu, vv = np.meshgrid(u, v)
        return (1.0 + self.gradient[0] * uu + self.gradient[1] * vv) * (1.0 - self.vignette * (uu**2 + vv**2) * 2.0)


@dataclass(frozen=True)
class Scene:
    surfaces: tuple[Surface, ...] = ()
    lighting: Lighting = field(default_factory=Lighting)


def render(
    scene: Scene,
    intrinsics: Intrinsics,
    camera_in_world: Array,
    optics: Optics,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """The 8-bit mono image of ``scene`` from a camera whose optical frame is ``camera_in_world`` (4x4)."""
    radiance, depth = _radiance(scene, intrinsics, camera_in_world)
    image = radiance * scene.lighting.field(intrinsics) * optics.gain
    image = _defocus(image, optics.blur_sigma(intrinsics, depth))
    noise = np.sqrt(optics.read_noise**2 + optics.shot_noise**2 * np.clip(image, 0.0, None))
    image = image + noise * rng.standard_normal(image.shape)
    return np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)


def _radiance(scene: Scene, intrinsics: Intrinsics, camera_in_world: Array) -> tuple[Array, Array]:
    """Brightness before light and lens, and depth along the optical axis (m), per pixel."""
    h, w = intrinsics.height, intrinsics.width
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack(((u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)), axis=-1)
    footprint = 1.0 / intrinsics.fx  # m per px per m of depth
    world_to_camera = np.linalg.inv(camera_in_world)
    depth = np.full((h, w), np.inf)
    radiance = np.full((h, w), BACKGROUND)
    for surface in scene.surfaces:
        plane = world_to_camera @ surface.pose
        rotation, origin = plane[:3, :3], plane[:3, 3]
        normal = rotation[:, 2]
        denom = rays @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(np.abs(denom) > 1e-9, float(origin @ normal) / denom, np.inf)
        hit = rays * t[..., None] - origin
        x, y = hit @ rotation[:, 0], hit @ rotation[:, 1]
        visible = (t > 0) & (t < depth) & (np.abs(x) <= surface.half_size[0]) & (np.abs(y) <= surface.half_size[1])
        if not visible.any():
            continue
        value = np.full((h, w), surface.albedo)
        cosine = np.abs(denom) / np.linalg.norm(rays, axis=-1)
        pixel_m = footprint * t / np.maximum(cosine, 0.05)  # a pixel's size on the surface, across the view
        for disc in surface.discs:
            r = 0.5 * disc.diameter
            near = np.abs(x - disc.x) < r + 0.01
            near &= np.abs(y - disc.y) < r + 0.01
            near &= visible
            if not near.any():
                continue
            d = np.hypot(x[near] - disc.x, y[near] - disc.y) - r
            ramp = np.maximum(disc.softness, pixel_m[near])
            inside = np.clip(0.5 - d / ramp, 0.0, 1.0)
            value[near] = value[near] * (1.0 - inside) + disc.albedo * inside
        radiance[visible] = value[visible]
        depth[visible] = t[visible]
    depth[~np.isfinite(depth)] = 10.0
    return radiance, depth


def _defocus(image: Array, sigma: Array, levels: int = 5) -> Array:
    """Blur each pixel by its own sigma: the image at a few blur levels, blended linearly by sigma."""
    top = float(sigma.max())
    if top < 0.3:
        return image
    steps = np.linspace(float(sigma.min()), top, levels) if top - float(sigma.min()) > 0.3 else np.array([float(np.median(sigma))])
    blurred = [image if s < 0.3 else cv2.GaussianBlur(image, (0, 0), float(s), borderType=cv2.BORDER_REPLICATE) for s in steps]
    if len(steps) == 1:
        return blurred[0]
    position = np.clip((sigma - steps[0]) / (steps[1] - steps[0]), 0.0, len(steps) - 1.0)
    lower = np.floor(position).astype(int)
    lower = np.minimum(lower, len(steps) - 2)
    weight = position - lower
    stack = np.stack(blurred)
    rows, cols = np.indices(image.shape)
    return stack[lower, rows, cols] * (1.0 - weight) + stack[lower + 1, rows, cols] * weight
