"""``python -m execution_engine vision detect``: JSON in the documented shape, the Vision state's detector, one-line errors."""
from __future__ import annotations

import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from vision_scenes import DIAMETER, INTRINSICS, looking_down, shoot

from cell_runner.cli import main
from core_functions.vision.holes import find_holes, head_on

DISTANCE = 0.08
HOLES = ((0.003, -0.002), (-0.012, 0.006))


def args(image: Path, *extra: str) -> list[str]:
    i = INTRINSICS
    return ["vision", "detect", str(image), "--fx", str(i.fx), "--fy", str(i.fy), "--cx", str(i.cx), "--cy", str(i.cy), "--distance", str(DISTANCE), "--diameter", str(DIAMETER), *extra]


def cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(argv, out, err)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    shot = shoot(HOLES, looking_down(DISTANCE), seed=3)
    path = tmp_path_factory.mktemp("img") / "plate.png"
    cv2.imwrite(str(path), shot.image)
    return path, shot.plane()


def test_json_gives_each_hole_in_pixels_and_in_the_optical_frame(image: tuple[Path, np.ndarray]) -> None:
    path, plane = image
    code, out, err = cli(args(path, "--json"))
    assert code == 0 and err == ""
    document = json.loads(out)
    assert list(document) == ["holes"] and len(document["holes"]) == 2
    for hole in document["holes"]:
        assert list(hole) == ["center_px", "center_m", "diameter_m", "score"]
        assert len(hole["center_px"]) == 2 and len(hole["center_m"]) == 3
        assert hole["center_m"][2] == pytest.approx(DISTANCE, abs=1e-9)
        assert hole["diameter_m"] == pytest.approx(DIAMETER, rel=0.05) and 0 < hole["score"] <= 1
    expected = [(plane @ np.array([x, y, 0.0, 1.0]))[:3] for x, y in HOLES]
    for truth in expected:  # the camera looks straight down: its frame's x right, y down, z into the plate
        found = min(document["holes"], key=lambda h: float(np.linalg.norm(np.array(h["center_m"]) - truth)))
        assert np.linalg.norm(np.array(found["center_m"][:2]) - truth[:2]) < 0.03e-3
        u, v = INTRINSICS.project(truth)[0]
        assert abs(found["center_px"][0] - u) < 0.3 and abs(found["center_px"][1] - v) < 0.3


def test_it_is_the_detector_of_the_vision_state(image: tuple[Path, np.ndarray]) -> None:
    path, _ = image
    _, out, _ = cli(args(path, "--json"))
    direct = find_holes(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), INTRINSICS, head_on(DISTANCE), DIAMETER)
    assert json.loads(out) == {"holes": [h.as_json() for h in direct]}


def test_without_json_one_line_per_hole(image: tuple[Path, np.ndarray]) -> None:
    path, _ = image
    code, out, _ = cli(args(path))
    lines = out.splitlines()
    assert code == 0 and lines[0] == f"{path}: 2 hole(s) of 4.8 mm at 0.08 m" and len(lines) == 3
    assert all(" px  (" in line and " mm  diameter " in line and " score " in line for line in lines[1:])


@pytest.mark.parametrize(
    ("change", "code", "message"),
    [
        ({"--fx": "abc"}, 2, "error: --fx must be a number in [0.1, 1e+06] px, got 'abc'"),
        ({"--distance": "-1"}, 2, "error: --distance must be a number in [0.001, 100] m, got '-1'"),
        ({"--diameter": "nan"}, 2, "error: --diameter must be a number in [1e-05, 1] m, got 'nan'"),
        ({"--cx": "inf"}, 2, "error: --cx must be a number in [-1e+06, 1e+06] px, got 'inf'"),
        ({"--fy": "1e308"}, 2, "error: --fy must be a number in [0.1, 1e+06] px, got '1e308'"),  # finite, and no camera's
        ({"--diameter": "5"}, 2, "error: --diameter must be a number in [1e-05, 1] m, got '5'"),
    ],
)
def test_bad_numbers_are_one_line_errors_with_exit_2(image: tuple[Path, np.ndarray], change: dict[str, str], code: int, message: str) -> None:
    argv = args(image[0])
    for option, value in change.items():
        argv[argv.index(option) + 1] = value
    got, out, err = cli(argv)
    assert (got, out, err) == (code, "", message + "\n")


def test_a_missing_or_unreadable_image_is_a_one_line_error_with_exit_1(tmp_path: Path) -> None:
    code, out, err = cli(args(tmp_path / "nope.png"))
    assert code == 1 and out == "" and err.startswith("error: ") and "nope.png: No such file or directory" in err and err.count("\n") == 1
    (tmp_path / "text.png").write_text("hello")
    code, _, err = cli(args(tmp_path / "text.png"))
    assert code == 1 and err == f"error: {tmp_path / 'text.png'}: not an image OpenCV can read (PNG, JPEG, TIFF, BMP, PGM, ...)\n"
    code, _, err = cli(args(tmp_path))
    assert code == 1 and err == f"error: {tmp_path}: not a file\n"


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=2000), cut=st.integers(0, 4000))
def test_random_or_truncated_files_never_raise(tmp_path: Path, image: tuple[Path, np.ndarray], data: bytes, cut: int) -> None:
    real = image[0].read_bytes()
    for name, content in (("random.png", data), ("cut.png", real[:cut])):
        path = tmp_path / name
        path.write_bytes(content)
        code, out, err = cli(args(path, "--json"))
        assert (code == 0 and json.loads(out)["holes"] is not None) or (code == 1 and err.count("\n") == 1)
