"""The Nextage's cameras, and ground truth plus noise for features they have no image model of.

Cameras: a stereo pair on the head (``HEAD_JOINT1_Link``; the mount offsets are hrpsys'
CAMERA_HEAD_L/R sensor positions, looking along the link's x axis), ``head_camera`` standing for
the pair (a locate with it triangulates from both), and one on each hand: 35 mm off the wrist
axis, converging on the point 50 mm out along the tool axis (where the skills' clearance puts a
hole), focused there.  Their images are rendered from the cell (:mod:`robot_bridges.camera`);
the hand camera mounts, lenses and ranges are this simulator's assumptions (docs/vision.md).

Features without an image model (a fixture, a tray: no ``diameter``) are still located the old
way, their true pose plus a small seeded noise, and say so in the trace (method ``simulated``).
A camera sees a feature only within its working range; farther away is a VISION fault, as is an
unknown feature.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import Vision, VisionReport, VisionResult
from core_functions.vision.camera import Intrinsics
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.camera.render import Optics
from robot_bridges.camera.spec import CameraSpec, body_mount, look_at_mount

if TYPE_CHECKING:  # the cell snapshot is only a parameter type here
    from node_transport.wire import CellSnapshot

#: Capture plus image processing time of one vision primitive (s).
VISION_TIME = 0.25
#: The hand camera's frame of reference: the default TCP (z out of the hand) on the wrist flange.
_TOOL = Pose.from_xyz_rpy(0.0, 0.0, 0.0, 0.0, -math.pi / 2, 0.0)
#: Hand camera: 35 mm off the tool axis, aimed at the point 50 mm out along it.
HAND_MOUNT = look_at_mount((0.035, 0.0, 0.0), (0.0, 0.0, 0.05), (0.0, 1.0, 0.0), _TOOL)
HAND_FOCUS = math.hypot(0.035, 0.05)
HEAD_INTRINSICS = Intrinsics.from_fov(1024, 768, math.radians(50.0))
HAND_INTRINSICS = Intrinsics.from_fov(640, 480, math.radians(60.0))

Camera = CameraSpec

CAMERAS: dict[str, CameraSpec] = {
    c.name: c
    for c in (
        CameraSpec("head_camera", "HEAD_JOINT1_Link", body_mount(0.059959, 0.0, 0.095), HEAD_INTRINSICS, Optics(0.5, aperture=0.002), 1.5),
        CameraSpec("head_camera_left", "HEAD_JOINT1_Link", body_mount(0.059959, 0.069754, 0.095), HEAD_INTRINSICS, Optics(0.5, aperture=0.002), 1.5),
        CameraSpec("head_camera_right", "HEAD_JOINT1_Link", body_mount(0.059959, -0.069754, 0.095), HEAD_INTRINSICS, Optics(0.5, aperture=0.002), 1.5),
        CameraSpec("left_hand_camera", "LARM_JOINT5_Link", HAND_MOUNT, HAND_INTRINSICS, Optics(HAND_FOCUS, aperture=0.002), 0.6),
        CameraSpec("right_hand_camera", "RARM_JOINT5_Link", HAND_MOUNT, HAND_INTRINSICS, Optics(HAND_FOCUS, aperture=0.002), 0.6),
    )
}
#: Cameras that stand for a stereo pair: a locate with them triangulates from both.
STEREO: dict[str, tuple[str, str]] = {"head_camera": ("head_camera_left", "head_camera_right")}
#: The cameras that take images (the pair's stand-in takes none of its own).
REAL_CAMERAS: dict[str, CameraSpec] = {n: c for n, c in CAMERAS.items() if n not in STEREO}


def camera(name: str, cameras: Mapping[str, CameraSpec] = CAMERAS) -> CameraSpec:
    try:
        return cameras[name]
    except KeyError:
        raise BridgeError(FaultKind.VISION, f"no camera {name!r} (cameras: {', '.join(cameras)})") from None


def taking_part(name: str, cameras: Mapping[str, CameraSpec] = CAMERAS) -> tuple[CameraSpec, ...]:
    """The cameras that take an image for a request naming ``name`` (both of a stereo pair)."""
    pair = STEREO.get(name)
    return tuple(camera(n, cameras) for n in pair) if pair else (camera(name, cameras),)


def cameras_with(mounts: Mapping[str, Pose]) -> dict[str, CameraSpec]:
    """The cameras, with these hand-eye mounts (optical frame in the link) instead of the defaults."""
    unknown = sorted(set(mounts) - set(REAL_CAMERAS))
    if unknown:
        raise ValueError(f"no camera {', '.join(unknown)} to mount (cameras: {', '.join(REAL_CAMERAS)})")
    return {n: (dataclasses.replace(c, mount=mounts[n]) if n in mounts else c) for n, c in CAMERAS.items()}


class SimulatedVision:
    """Ground truth plus seeded noise; deterministic for a given seed and call sequence."""

    def __init__(self, seed: int = 0, position_noise: float = 1e-4, angle_noise: float = math.radians(0.05)) -> None:
        self._rng = np.random.default_rng(seed)
        self.position_noise = position_noise  # m, standard deviation per axis
        self.angle_noise = angle_noise  # rad, standard deviation per axis
        self._cell: CellSnapshot | None = None

    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell

    def fallback(self, primitive: Vision, placed: Sequence[tuple[CameraSpec, Pose]]) -> VisionResult:
        """For a feature without an image model: the true pose plus noise, reported as ``simulated``."""
        cam, camera_pose = placed[0]
        result = self.observe(primitive, cam, camera_pose)
        report = VisionReport(cam.name, "simulated", nominal=primitive.nominal, measured=result.pose)
        return VisionResult(pose=result.pose, value=result.value, score=result.score, report=report)

    def observe(self, primitive: Vision, cam: CameraSpec, camera_pose: Pose) -> VisionResult:
        """What ``cam`` at ``camera_pose`` reports for ``primitive``; BridgeError(VISION) if nothing."""
        target = primitive.target
        actual, nominal = self._where(primitive)
        distance = camera_pose.distance_to(actual)
        if distance > cam.max_range:
            raise BridgeError(
                FaultKind.VISION,
                f"{target or 'the feature'} is {distance:.3f} m from {cam.name}, beyond its "
                f"{cam.max_range:.2f} m working range",
            )
        measured = self._noisy(actual)
        if primitive.task == "locate":
            return VisionResult(pose=measured)
        deviation = actual.distance_to(nominal) if nominal is not None else 0.0
        if primitive.task == "inspect":
            return VisionResult(pose=measured, value=float(deviation + self._rng.normal(0.0, self.position_noise)))
        value = self._attribute_value(target)
        if value is None:
            value = distance  # a range measurement when the cell names no quantity
        return VisionResult(value=float(value + self._rng.normal(0.0, self.position_noise)))

    # ------------------------------------------------------------------------------ helpers
    def _where(self, primitive: Vision) -> tuple[Pose, Pose | None]:
        """(true pose, nominal pose) of the target; VISION error when neither is known."""
        target = primitive.target
        nominal = primitive.nominal or self.frame_pose(target)
        truth = self._cell.truth.get(target) if (self._cell is not None and target) else None
        actual = truth or nominal
        if actual is None:
            where = "the cell model" if self._cell is not None else "any cell model (none received yet)"
            raise BridgeError(FaultKind.VISION, f"feature {target!r} is unknown: not in {where} and no nominal pose given")
        return actual, nominal

    def frame_pose(self, name: str) -> Pose | None:
        if self._cell is None or not name:
            return None
        for frame in self._cell.frames:
            if frame.name == name:
                return frame.pose
        return None

    def _attribute_value(self, name: str) -> float | None:
        if self._cell is None or not name:
            return None
        texts = [f.attributes.get("value") for f in self._cell.frames if f.name == name]
        texts.append(self._cell.elements.get(name, {}).get("value"))
        for text in texts:
            if text is not None:
                try:
                    return float(text)
                except ValueError:
                    raise BridgeError(FaultKind.VISION, f"feature {name!r}: value {text!r} is not a number") from None
        return None

    def _noisy(self, pose: Pose) -> Pose:
        dp = self._rng.normal(0.0, self.position_noise, 3)
        droll, dpitch, dyaw = self._rng.normal(0.0, self.angle_noise, 3)
        turned = pose.compose(Pose.from_xyz_rpy(0.0, 0.0, 0.0, droll, dpitch, dyaw))
        return turned.translated(float(dp[0]), float(dp[1]), float(dp[2]))
