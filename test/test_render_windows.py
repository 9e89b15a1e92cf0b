"""The renderer computes only what a surface or a disc can reach, and the image is the same to the bit.

The dry run's verdict on a vision-corrected target rests on the detector seeing the image the
simulator's run sees; the renderer's windows are a speed-up only, so each windowed step is compared
with the same step over the whole image on random views: surfaces seen obliquely, partly out of
view, edge-on, behind the camera, and a camera between two of them.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from robot_bridges.camera.render import Disc, Lighting, Optics, Scene, Surface, defocus, radiance, render

#: Small images keep the comparison quick; the windows' arithmetic does not depend on the size.
INTRINSICS = Intrinsics.from_fov(160, 120, math.radians(60.0))
OPTICS = Optics(0.06, aperture=0.004)


def plate(x: float, y: float, z: float, roll: float, pitch: float, half: float, holes: int) -> Surface:
    discs = tuple(Disc(half * (k / max(1, holes) - 0.5), 0.3 * half * (-1) ** k, 0.004 + 0.002 * k, 0.06 if k % 2 else 0.95) for k in range(holes))
    return Surface(Pose.from_xyz_rpy(x, y, z, roll, pitch, 0.0).matrix(), (half, 0.7 * half), 0.75, discs)


surfaces = st.builds(
    plate,
    st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.05, 0.05),
    st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(0.005, 0.08), st.integers(0, 5),
)
#: The camera: somewhere above the plates (or among them), looking roughly down, possibly tilted far.
cameras = st.builds(
    lambda x, y, z, roll, pitch, yaw: Pose.from_xyz_rpy(x, y, z, math.pi + roll, pitch, yaw).matrix(),
    st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.02, 0.15),
    st.floats(-1.2, 1.2), st.floats(-1.2, 1.2), st.floats(-math.pi, math.pi),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(surfaces, min_size=1, max_size=3), cameras)
def test_windowed_radiance_is_the_whole_image_computation(found: list[Surface], camera: np.ndarray) -> None:
    scene = Scene(tuple(found), Lighting())
    fast, fast_depth = radiance(scene, INTRINSICS, camera)
    whole, whole_depth = radiance(scene, INTRINSICS, camera, windows=False)
    assert np.array_equal(fast, whole)
    assert np.array_equal(fast_depth, whole_depth)


@settings(max_examples=60, deadline=None)
@given(st.lists(surfaces, min_size=1, max_size=3), cameras, st.floats(0.03, 0.3), st.floats(0.001, 0.01))
def test_the_banded_defocus_is_the_stacked_blend(found: list[Surface], camera: np.ndarray, focus: float, aperture: float) -> None:
    scene = Scene(tuple(found), Lighting())
    bright, depth = radiance(scene, INTRINSICS, camera, windows=False)
    # A camera almost touching a plate blurs by thousands of pixels: bounded, so that both sides' kernels stay quick.
    sigma = np.minimum(Optics(focus, aperture=aperture).blur_sigma(INTRINSICS, depth), 40.0)
    assert np.array_equal(defocus(bright, sigma), stacked_defocus(bright, sigma))


def stacked_defocus(image: np.ndarray, sigma: np.ndarray, levels: int = 5) -> np.ndarray:
    """The blend written the plain way: every level blurred whole, stacked, two of them taken per pixel."""
    top, bottom = float(sigma.max()), float(sigma.min())
    if top < 0.3:
        return image
    steps = np.linspace(bottom, top, levels) if top - bottom > 0.3 else np.array([float(np.median(sigma))])
    blurred = [image if s < 0.3 else cv2.GaussianBlur(image, (0, 0), float(s), borderType=cv2.BORDER_REPLICATE) for s in steps]
    if len(steps) == 1:
        return blurred[0]
    position = np.clip((sigma - steps[0]) / (steps[1] - steps[0]), 0.0, len(steps) - 1.0)
    lower = np.minimum(np.floor(position).astype(int), len(steps) - 2)
    weight = position - lower
    stack = np.stack(blurred)
    rows, cols = np.indices(image.shape)
    return stack[lower, rows, cols] * (1.0 - weight) + stack[lower + 1, rows, cols] * weight


def test_a_plate_filling_part_of_the_view_renders_its_holes() -> None:
    """Not an empty image: the windows find the plate and its holes (dark inside, the plate's brightness around)."""
    camera = Pose.from_xyz_rpy(0.0, 0.0, 0.06, math.pi, 0.0, 0.0).matrix()
    hole = Disc(0.0, 0.0, 0.006, 0.06)
    scene = Scene((Surface(np.eye(4), (0.01, 0.01), 0.75, (hole,)),), Lighting())
    bright, depth = radiance(scene, INTRINSICS, camera)
    cy, cx = int(round(INTRINSICS.cy)), int(round(INTRINSICS.cx))
    assert bright[cy, cx] == 0.06 and math.isclose(depth[cy, cx], 0.06)
    assert bright[cy, cx + 12] == 0.75  # on the plate, beside the hole (2 mm from its edge at 0.06 m: about 12 px)
    assert bright[0, 0] < 0.2 and depth[0, 0] == 10.0  # beyond the plate: the floor far below
    image = render(scene, INTRINSICS, camera, OPTICS, np.random.default_rng(1))
    assert image[cy, cx] < image[cy, cx + 12]


def test_the_same_seed_gives_the_same_image() -> None:
    """What the dry run and the simulator's run both rely on: one scene, one pose, one noise seed, one image."""
    camera = Pose.from_xyz_rpy(0.004, -0.002, 0.07, math.pi, 0.2, 0.3).matrix()
    scene = Scene((plate(0.0, 0.0, 0.0, 0.1, -0.2, 0.03, 4),), Lighting())
    first = render(scene, INTRINSICS, camera, OPTICS, np.random.default_rng(7))
    again = render(scene, INTRINSICS, camera, OPTICS, np.random.default_rng(7))
    assert np.array_equal(first, again)
