"""Camera back ends on the Nextage simulator: the head's stereo pair, rivets in the tray, image files, sharpness."""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import pytest

from app_functions.registry import full_catalog
from core_functions.geometry import Pose
from core_functions.primitives import MoveCartesian, MoveJoints, Vision
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.camera.sources import FileCamera
from robot_bridges.camera.vision import CameraVision
from robot_bridges.nextage_sim import vision
from robot_bridges.nextage_sim.backend import HAND_TOOL, NextageSimBackend
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
APP = load_application(ROOT / "apps_xml" / "rivet_installation.xml", full_catalog())
CELL = APP.cell
assert CELL is not None
SNAPSHOT = CELL.to_snapshot()
HEAD = ("CHEST_JOINT0", "HEAD_JOINT0", "HEAD_JOINT1")


async def backend_over(clock: Clock, group: str, frame: str, height: float = 0.05) -> NextageSimBackend:
    backend = NextageSimBackend(clock, tools={"left_arm": HAND_TOOL, "right_arm": HAND_TOOL})
    backend.set_cell(SNAPSHOT)
    await backend.execute(group, MoveCartesian(CELL.pose(frame).offset_local(dz=-height), "ptp"))
    return backend


def test_the_head_pair_triangulates_holes_within_0_2_mm(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> list[tuple[str, float, str]]:
        backend = NextageSimBackend(clock)
        backend.set_cell(SNAPSHOT)
        await backend.execute("torso_head", MoveJoints((0.0, 0.0, math.radians(60)), HEAD))
        out = []
        for hole in ("drill_1", "drill_2", "drill_3", "drill_4"):
            result = await backend.execute("torso_head", Vision("locate", hole, nominal=CELL.pose(hole), camera="head_camera"))
            assert result.pose is not None and result.report is not None
            out.append((result.report.method, result.pose.distance_to(CELL.true_pose(hole)), result.report.camera))
        return out

    for method, error, camera in run_sim(main):
        assert method == "stereo" and camera == "head_camera_left+head_camera_right"
        assert error < 0.0002


def test_a_rivet_in_its_tray_slot_is_found_as_a_bright_head(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[Pose, float]:
        backend = await backend_over(clock, "right_arm", "rivet_1")
        result = await backend.execute("right_arm", Vision("locate", "rivet_1", nominal=CELL.pose("rivet_1")))
        assert result.pose is not None and result.report is not None
        return result.pose, result.report.diameter

    pose, diameter = run_sim(main)
    assert pose.distance_to(CELL.true_pose("rivet_1")) < 0.05e-3
    assert diameter == pytest.approx(0.0048 * 1.6, rel=0.05)


def test_an_image_file_gives_the_same_locate_as_the_renderer(run_sim, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> tuple[Pose, Pose]:
        backend = await backend_over(clock, "left_arm", "drill_3")
        taken = []
        backend.cameras.on_capture = lambda spec, pose, frame: taken.append(frame.image)
        rendered = await backend.execute("left_arm", Vision("locate", "drill_3", nominal=CELL.pose("drill_3")))
        cv2.imwrite(str(tmp_path / "drill_3.png"), taken[0])
        backend.cameras = CameraVision(FileCamera([tmp_path / "drill_3.png"]))
        backend.cameras.set_cell(SNAPSHOT)
        from_file = await backend.execute("left_arm", Vision("locate", "drill_3", nominal=CELL.pose("drill_3")))
        assert rendered.pose is not None and from_file.pose is not None
        return rendered.pose, from_file.pose

    rendered, from_file = run_sim(main)
    assert rendered == from_file


def test_a_missing_or_unreadable_image_file_is_a_vision_fault(run_sim, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "junk.png").write_bytes(b"not an image")

    async def main(clock: Clock) -> list[str]:
        backend = await backend_over(clock, "left_arm", "drill_3")
        messages = []
        for path in (tmp_path / "missing.png", tmp_path / "junk.png"):
            backend.cameras = CameraVision(FileCamera([path]))
            backend.cameras.set_cell(SNAPSHOT)
            with pytest.raises(BridgeError) as error:
                await backend.execute("left_arm", Vision("locate", "drill_3", nominal=CELL.pose("drill_3")))
            assert error.value.kind is FaultKind.VISION
            messages.append(str(error.value))
        return messages

    missing, junk = run_sim(main)
    assert "left_hand_camera: no image:" in missing and "missing.png" in missing
    assert "junk.png: not an image OpenCV can read" in junk


def test_measure_on_a_feature_is_the_sharpness_of_the_live_image(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> list[float]:
        backend = await backend_over(clock, "left_arm", "drill_2")
        values = []
        for _ in range(3):
            result = await backend.execute("left_arm", Vision("measure", "drill_2", nominal=CELL.pose("drill_2")))
            assert result.value is not None and result.report is not None and result.report.method == "sharpness"
            values.append(result.value)
            await backend.execute("left_arm", MoveCartesian(CELL.pose("drill_2").offset_local(dz=-0.05 - 0.01 * (len(values))), "linear"))
        return values

    values = run_sim(main)
    assert values[0] > values[1] > values[2]  # leaving the focus plane blurs the image


def test_the_hand_eye_mount_is_configurable(run_sim) -> None:  # type: ignore[no-untyped-def]
    default = vision.CAMERAS["left_hand_camera"].mount
    text = " ".join(f"{v:.12g}" for v in (*default.position, *default.rpy()))
    shifted = " ".join(f"{v:.12g}" for v in (*default.compose(Pose(0.005, 0.0, 0.0)).position, *default.rpy()))

    async def located(clock: Clock, mount: str) -> tuple[Pose, tuple[float, float]]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=APP.robot, extra={"left_hand_camera_mount": mount}))
        backend.set_cell(SNAPSHOT)
        await backend.execute("left_arm", MoveCartesian(CELL.pose("drill_2").offset_local(dz=-0.05), "ptp"))
        images: list[object] = []
        backend.cameras.on_capture = lambda spec, pose, frame: images.append(pose)
        result = await backend.execute("left_arm", Vision("locate", "drill_2", nominal=CELL.pose("drill_2")))
        assert result.pose is not None
        camera = images[0]
        assert isinstance(camera, Pose)
        return result.pose, (camera.x, camera.y)

    async def main(clock: Clock) -> tuple[tuple[Pose, tuple[float, float]], tuple[Pose, tuple[float, float]]]:
        return await located(clock, text), await located(clock, shifted)

    (as_default, camera_a), (moved, camera_b) = run_sim(main)
    truth = CELL.true_pose("drill_2")
    assert math.dist(camera_a, camera_b) == pytest.approx(0.005, abs=1e-6)  # the camera sits where its mount says
    assert as_default.distance_to(truth) < 0.05e-3 and moved.distance_to(truth) < 0.05e-3


def test_a_bad_mount_option_is_a_one_line_error(run_sim) -> None:  # type: ignore[no-untyped-def]
    async def main(clock: Clock) -> str:
        with pytest.raises(ValueError) as error:
            await create_backend("nextage-sim", clock, BackendOptions(robot=APP.robot, extra={"right_hand_camera_mount": "1 2 3"}))
        return str(error.value)

    assert run_sim(main) == "nextage-sim: right_hand_camera_mount: six numbers x y z roll pitch yaw (m, rad) expected, got '1 2 3'"
