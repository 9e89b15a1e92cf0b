"""The hole detector on rendered images: sub-pixel accuracy whatever the pose, noise, blur and light; filters; sharpness."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from vision_scenes import DIAMETER, INTRINSICS, looking_down, shoot

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics, plane_points, ray_plane, triangulate
from core_functions.vision.detect import find_blobs
from core_functions.vision.holes import detect_head_on, find_holes
from core_functions.vision.sharpness import sharpness
from robot_bridges.camera.render import Surface

TOLERANCE = 0.05e-3  # m: the accuracy aim for p95; every single case here must meet it


def error_of(found: tuple[float, float], true: tuple[float, float]) -> float:
    return math.hypot(found[0] - true[0], found[1] - true[1])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@example(x=0.0, y=0.0, distance=0.0625, tilt=0.3125, yaw=0.0, noise=0.0, defocus=1.0, gradient=(0.375, 0.21875), seed=19301)  # a dark corner once fitted a second 'hole'
@given(
    x=st.floats(-0.004, 0.004),
    y=st.floats(-0.004, 0.004),
    distance=st.floats(0.05, 0.09),
    tilt=st.floats(0.0, 0.6),
    yaw=st.floats(-math.pi, math.pi),
    noise=st.floats(0.0, 0.03),
    defocus=st.floats(0.85, 1.2),
    gradient=st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4)),
    seed=st.integers(0, 2**16),
)
def test_a_hole_at_any_pose_noise_blur_and_light_is_found_within_0_05_mm(
    x: float, y: float, distance: float, tilt: float, yaw: float, noise: float, defocus: float, gradient: tuple[float, float], seed: int
) -> None:
    camera = looking_down(distance, tilt, yaw)
    shot = shoot(((x, y),), camera, focus=distance * defocus, noise=noise, gradient=gradient, seed=seed)
    holes = find_holes(shot.image, INTRINSICS, shot.plane(), DIAMETER)
    assert len(holes) == 1
    assert error_of(holes[0].plane_xy, (x, y)) < TOLERANCE
    assert abs(holes[0].diameter_m - DIAMETER) < 0.05 * DIAMETER
    # the circle's centre projected back is where the hole's centre is in the image (not the ellipse's centre)
    true_px = INTRINSICS.project((shot.plane() @ np.array([x, y, 0.0, 1.0]))[:3])[0]
    assert math.hypot(*(np.array(holes[0].center_px) - true_px)) < 0.3


def test_an_oblique_view_measures_the_circle_not_the_ellipse_centre() -> None:
    """At 35 degrees the ellipse's centre is visibly off the hole's centre; the plane fit is not."""
    camera = looking_down(0.06, 0.6, 0.3)
    shot = shoot(((0.001, -0.002),), camera, noise=0.0)
    hole = find_holes(shot.image, INTRINSICS, shot.plane(), DIAMETER)[0]
    ellipse_centre_on_plane = plane_points(INTRINSICS, shot.plane(), np.array([hole.blob.center]))[0]
    assert error_of(hole.plane_xy, (0.001, -0.002)) < 0.01e-3
    assert error_of(tuple(ellipse_centre_on_plane), (0.001, -0.002)) > 0.02e-3


def test_partial_occlusion_and_a_touching_neighbour_do_not_pull_the_centre() -> None:
    camera = looking_down(0.06, 0.2, 0.0)
    cover = np.eye(4)
    cover[:3, 3] = (0.0 + 0.01 + 0.0015, 0.0, 0.002)  # a bright clamp 2 mm above the plate over a quarter of the hole
    clamp = Surface(cover, (0.01, 0.01), 0.9)
    shot = shoot(((0.0, 0.0), (0.0, 0.0062)), camera, extra=(clamp,))
    holes = find_holes(shot.image, INTRINSICS, shot.plane(), DIAMETER)
    centre = min(holes, key=lambda h: error_of(h.plane_xy, (0.0, 0.0)))
    assert error_of(centre.plane_xy, (0.0, 0.0)) < 0.1e-3
    neighbour = min(holes, key=lambda h: error_of(h.plane_xy, (0.0, 0.0062)))
    assert error_of(neighbour.plane_xy, (0.0, 0.0062)) < TOLERANCE


def test_the_expected_diameter_filters_candidates() -> None:
    camera = looking_down(0.07)
    shot = shoot(((-0.01, 0.0),), camera)
    big = shoot(((0.01, 0.0),), camera, diameter=2 * DIAMETER)
    assert len(find_holes(shot.image, INTRINSICS, shot.plane(), DIAMETER)) == 1
    assert find_holes(big.image, INTRINSICS, big.plane(), DIAMETER) == []
    assert len(find_holes(big.image, INTRINSICS, big.plane(), 2 * DIAMETER)) == 1


def test_a_plain_surface_has_no_holes_and_bright_discs_are_found_by_polarity() -> None:
    camera = looking_down(0.07)
    assert find_holes(shoot((), camera, noise=0.03).image, INTRINSICS, np.linalg.inv(camera.matrix()), DIAMETER) == []
    rivet = shoot(((0.002, 0.001),), camera, albedo=1.3)  # a rivet head, brighter than the tray
    plane = rivet.plane()
    assert find_holes(rivet.image, INTRINSICS, plane, DIAMETER) == []
    heads = find_holes(rivet.image, INTRINSICS, plane, DIAMETER, polarity="bright")
    assert len(heads) == 1 and error_of(heads[0].plane_xy, (0.002, 0.001)) < TOLERANCE


def test_head_on_detection_reports_the_camera_frame() -> None:
    camera = looking_down(0.08)
    shot = shoot(((0.003, -0.002),), camera, noise=0.0)
    (hole,) = detect_head_on(shot.image, INTRINSICS, 0.08, DIAMETER)
    # optical frame of a camera looking down with the world's x to its right... per looking_down: x right = world x
    expected = (shot.plane() @ np.array([0.003, -0.002, 0.0, 1.0]))[:3]
    assert np.allclose(hole.center_m, expected, atol=0.02e-3)


def test_sharpness_peaks_at_the_focus_distance() -> None:
    camera = looking_down(0.07)
    values = [sharpness(shoot(((0.0, 0.0), (0.01, 0.01)), camera, focus=f, aperture=0.004).image) for f in (0.05, 0.06, 0.07, 0.08, 0.1)]
    assert values.index(max(values)) == 2
    assert values[0] < values[1] < values[2] > values[3] > values[4]


def test_ray_plane_and_triangulation_agree_with_projection() -> None:
    intr = Intrinsics(800, 600, 900.0, 905.0, 401.3, 297.8)
    point = np.array([0.02, -0.01, 0.5])
    left = np.eye(4)
    right = np.eye(4)
    right[0, 3] = 0.14
    uv_left = intr.project(point)[0]
    uv_right = intr.project(point - right[:3, 3])[0]
    found, error = triangulate((intr, left, uv_left), (intr, right, uv_right))
    assert np.allclose(found, point, atol=1e-9) and error < 1e-6
    plane = np.eye(4)
    plane[2, 3] = 0.5
    hit = ray_plane(intr, plane, uv_left)
    assert hit is not None and np.allclose(hit, point, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.binary(min_size=0, max_size=400), st.integers(1, 20), st.integers(1, 20))
def test_arbitrary_bytes_as_an_image_never_crash_the_detector(data: bytes, rows: int, cols: int) -> None:
    pixels = np.frombuffer((data * (rows * cols // max(1, len(data)) + 1))[: rows * cols] or bytes(rows * cols), dtype=np.uint8)
    image = pixels.reshape(rows, cols)
    for blob in find_blobs(image, "dark", 3.0, 10.0):
        assert np.isfinite(blob.center).all()


def test_an_image_of_the_wrong_size_for_the_camera_is_refused() -> None:
    with pytest.raises(ValueError, match="camera model says 640x480"):
        find_holes(np.zeros((10, 10), np.uint8), INTRINSICS, np.eye(4) @ Pose(0, 0, 0.1).matrix(), DIAMETER)
