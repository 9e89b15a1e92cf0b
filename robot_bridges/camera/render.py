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

Cost: every step is worked out pixel by pixel, so only the pixels a surface or a disc can reach
are computed, and each defocus level only on the rows whose pixels take something of it (their bounding boxes in the image, widened against rounding), and
what depends only on the camera (each pixel's ray, the lighting field) is computed once per
camera.  The image is the same to the bit as computing every surface and disc over the whole
image (``windows=False``, which the tests compare against), and as the renderer before these
windows; a dry run sees the image the simulator's run sees.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.vision.camera import Intrinsics

Array = NDArray[np.float64]

#: What a ray that meets no surface sees (the dark cell floor far below), relative brightness.
BACKGROUND = 0.12
#: Pixels added around a computed window against rounding at its edges (a speed-up only: see _window).
WINDOW_MARGIN = 2
#: px: the largest defocus blur drawn.  A surface almost touching the lens (a hand camera swept past a part while
#: the arm moves, as camera-sim draws it) would ask for a blur of millions of pixels -- a Gaussian kernel of gigabytes
#: and minutes; past a few dozen pixels the image is a uniform grey either way.
MAX_BLUR = 50.0


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
        return np.minimum(0.5 * self.aperture * f * np.abs(1.0 / z - 1.0 / self.focus_distance), MAX_BLUR)


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
    bright, depth = radiance(scene, intrinsics, camera_in_world)
    bright *= _light(scene.lighting, intrinsics)
    bright *= optics.gain
    image = defocus(bright, optics.blur_sigma(intrinsics, depth))
    noise = np.clip(image, 0.0, None)  # the same operations as written out plainly, in place (no temporaries)
    noise *= optics.shot_noise**2
    noise += optics.read_noise**2
    np.sqrt(noise, out=noise)
    shot = rng.standard_normal(image.shape)
    shot *= noise
    shot += image
    shot *= 255.0
    np.rint(shot, out=shot)
    np.clip(shot, 0, 255, out=shot)
    return shot.astype(np.uint8)


@dataclass(frozen=True)
class _Pixels:
    """What depends only on the camera's intrinsics: each pixel's ray (x/z, y/z; z is 1) and its length."""

    rx: Array
    ry: Array
    length: Array


@lru_cache(maxsize=16)
def _pixels(intrinsics: Intrinsics) -> _Pixels:
    u, v = np.meshgrid(np.arange(intrinsics.width, dtype=float), np.arange(intrinsics.height, dtype=float))
    rx, ry = (u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy
    length = np.sqrt(rx * rx + ry * ry + 1.0)
    for array in (rx, ry, length):
        array.flags.writeable = False  # shared by every image of this camera
    return _Pixels(rx, ry, length)


@lru_cache(maxsize=16)
def _light(lighting: Lighting, intrinsics: Intrinsics) -> Array:
    """:meth:`Lighting.field`, computed once per camera and lighting (read only)."""
    light = lighting.field(intrinsics)
    light.flags.writeable = False
    return light


def _window(plane: Array, half_size: tuple[float, float], intrinsics: Intrinsics) -> tuple[slice, slice] | None:
    """The pixels (rows, columns) the rectangle ``plane`` (4x4 in the camera) can cover; None: none.

    A rectangle wholly in front of the camera projects to the convex hull of its projected
    corners, so every pixel whose ray meets it lies in their bounding box (widened by
    :data:`WINDOW_MARGIN` pixels against rounding).  One with a corner at or behind the camera's
    plane may reach any pixel: the whole image.  Only a speed-up: a pixel outside the window is
    one the rectangle does not cover, which the per-pixel test would also find.
    """
    h, w = intrinsics.height, intrinsics.width
    ex, ey = plane[:3, 0] * half_size[0], plane[:3, 1] * half_size[1]
    corners = np.array([plane[:3, 3] + sx * ex + sy * ey for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)])
    z = corners[:, 2]
    if not np.all(z > 1e-6):
        return (slice(0, h), slice(0, w)) if np.any(z > 0.0) else None
    u = intrinsics.fx * corners[:, 0] / z + intrinsics.cx
    v = intrinsics.fy * corners[:, 1] / z + intrinsics.cy
    c0, c1 = max(0, math.floor(u.min()) - WINDOW_MARGIN), min(w, math.ceil(u.max()) + WINDOW_MARGIN + 1)
    r0, r1 = max(0, math.floor(v.min()) - WINDOW_MARGIN), min(h, math.ceil(v.max()) + WINDOW_MARGIN + 1)
    if c0 >= c1 or r0 >= r1:
        return None
    return slice(r0, r1), slice(c0, c1)


def _moved(plane: Array, x: float, y: float) -> Array:
    """``plane`` with its origin moved to (x, y) of its own xy plane."""
    moved = plane.copy()
    moved[:3, 3] = plane[:3, 3] + x * plane[:3, 0] + y * plane[:3, 1]
    return moved


def _within(inner: tuple[slice, slice] | None, outer: tuple[slice, slice]) -> tuple[slice, slice] | None:
    """``inner`` (image rows, columns) clipped to ``outer`` and counted from ``outer``'s corner; None: no overlap."""
    if inner is None:
        return None
    r0, r1 = max(inner[0].start, outer[0].start), min(inner[0].stop, outer[0].stop)
    c0, c1 = max(inner[1].start, outer[1].start), min(inner[1].stop, outer[1].stop)
    if r0 >= r1 or c0 >= c1:
        return None
    return slice(r0 - outer[0].start, r1 - outer[0].start), slice(c0 - outer[1].start, c1 - outer[1].start)


def radiance(scene: Scene, intrinsics: Intrinsics, camera_in_world: Array, windows: bool = True) -> tuple[Array, Array]:
    """Brightness before light and lens, and depth along the optical axis (m), per pixel.

    Every quantity is worked out pixel by pixel (no sum across pixels), so a pixel's value does not
    depend on which other pixels are computed with it: each surface is computed only over the pixels
    it can cover (:func:`_window`; ``windows=False``: over the whole image, the reference the tests
    compare against), and the image is the same to the bit.
    """
    h, w = intrinsics.height, intrinsics.width
    pixels = _pixels(intrinsics)
    footprint = 1.0 / intrinsics.fx  # m per px per m of depth
    world_to_camera = np.linalg.inv(camera_in_world)
    depth = np.full((h, w), np.inf)
    bright = np.full((h, w), BACKGROUND)
    for surface in scene.surfaces:
        plane = world_to_camera @ surface.pose
        window = _window(plane, surface.half_size, intrinsics) if windows else (slice(0, h), slice(0, w))
        if window is None:
            continue
        rx, ry = pixels.rx[window], pixels.ry[window]
        (a0, a1, a2), (b0, b1, b2), (n0, n1, n2) = (tuple(map(float, plane[:3, k])) for k in range(3))
        o0, o1, o2 = map(float, plane[:3, 3])
        denom = rx * n0 + ry * n1 + n2
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(np.abs(denom) > 1e-9, (o0 * n0 + o1 * n1 + o2 * n2) / denom, np.inf)
        hx, hy, hz = rx * t - o0, ry * t - o1, t - o2
        x, y = hx * a0 + hy * a1 + hz * a2, hx * b0 + hy * b1 + hz * b2
        seen = depth[window]
        visible = (t > 0) & (t < seen) & (np.abs(x) <= surface.half_size[0]) & (np.abs(y) <= surface.half_size[1])
        if not visible.any():
            continue
        value = np.full(t.shape, surface.albedo)
        length = pixels.length[window]
        for disc in surface.discs:
            r = 0.5 * disc.diameter
            around = _within(_window(_moved(plane, disc.x, disc.y), (r + 0.01, r + 0.01), intrinsics) if windows else window, window)
            if around is None:
                continue
            dx, dy, dvisible = x[around], y[around], visible[around]
            near = np.abs(dx - disc.x) < r + 0.01
            near &= np.abs(dy - disc.y) < r + 0.01
            near &= dvisible
            if not near.any():
                continue
            cosine = np.abs(denom[around]) / length[around]
            pixel_m = footprint * t[around] / np.maximum(cosine, 0.05)  # a pixel's size on the surface, across the view
            d = np.hypot(dx[near] - disc.x, dy[near] - disc.y) - r
            ramp = np.maximum(disc.softness, pixel_m[near])
            inside = np.clip(0.5 - d / ramp, 0.0, 1.0)
            part = value[around]
            part[near] = part[near] * (1.0 - inside) + disc.albedo * inside
        np.copyto(bright[window], value, where=visible)
        np.copyto(seen, t, where=visible)
    np.copyto(depth, 10.0, where=np.isinf(depth))
    return bright, depth


def defocus(image: Array, sigma: Array, levels: int = 5) -> Array:
    """Blur each pixel by its own sigma: the image at a few blur levels, blended linearly by sigma.

    Each band of pixels between two levels is blended from those two levels only, and a level is
    blurred only over the rows of the bands that take something of it (:func:`_blurred`): a band
    whose pixels all sit on one of its levels (weight 0 or 1, such as the floor far below, all at
    one depth) takes nothing of the other, whose product with its weight would be 0 anyway.  The
    image is the same to the bit as blurring every level whole and blending per pixel.
    """
    top = float(sigma.max())
    if top < 0.3:
        return image
    steps = np.linspace(float(sigma.min()), top, levels) if top - float(sigma.min()) > 0.3 else np.array([float(np.median(sigma))])
    if len(steps) == 1:
        return _blurred(image, float(steps[0]), None)
    position = np.clip((sigma - steps[0]) / (steps[1] - steps[0]), 0.0, len(steps) - 1.0)
    lower = np.floor(position).astype(int)
    lower = np.minimum(lower, len(steps) - 2)
    weight = position - lower
    bands = []
    rows_of: dict[int, Array] = {}  # level -> the rows where some pixel takes something of it
    for k in range(len(steps) - 1):
        mask = lower == k
        if not mask.any():
            continue
        w = weight[mask]
        rows = mask.any(axis=1)
        for level, used in ((k, bool((w < 1.0).any())), (k + 1, bool((w > 0.0).any()))):
            if used:
                rows_of[level] = rows_of[level] | rows if level in rows_of else rows
        bands.append((k, mask, w))
    blurred = {level: _blurred(image, float(steps[level]), rows) for level, rows in rows_of.items()}
    out = np.empty_like(image)
    for k, mask, w in bands:
        low = blurred[k][mask] if k in blurred else np.zeros(len(w))  # weight 1 everywhere: times 0
        high = blurred[k + 1][mask] if k + 1 in blurred else np.zeros(len(w))  # weight 0 everywhere
        out[mask] = low * (1.0 - w) + high * w
    return out


def _blurred(image: Array, sigma: float, rows: Array | None) -> Array:
    """``image`` blurred with ``sigma`` on the ``rows`` asked for (None: all), 0 on the others.

    OpenCV's Gaussian of sigma s on doubles has a kernel reaching ``round(8 s + 1) // 2`` pixels;
    the rows asked for, widened by that reach (clamped to the image, whose replicated border is its
    own), are blurred whole-width.  A pixel's value then comes from the same pixels by the same
    arithmetic as in the whole image's blur: the row filter treats each row alike, the column
    filter each column, and a row's reach never meets the cut.  (A window cut in columns too is
    not: OpenCV's row filter takes another code path near a row's end, changing the last bit.)
    """
    if sigma < 0.3:
        return image
    h = image.shape[0]
    where = np.flatnonzero(rows) if rows is not None else np.arange(0)
    reach = (int(round(8.0 * sigma + 1.0)) | 1) // 2 + WINDOW_MARGIN
    r0, r1 = (max(0, int(where[0]) - reach), min(h, int(where[-1]) + reach + 1)) if len(where) else (0, h)
    if rows is None or (r0, r1) == (0, h):
        return cv2.GaussianBlur(image, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    out = np.zeros_like(image)
    out[r0:r1] = cv2.GaussianBlur(np.ascontiguousarray(image[r0:r1]), (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    return out
