"""Simulated cameras: where a feature *really* is, as a camera on the robot would measure it.

Applications look for features (holes, parts) whose nominal poses come from the cell model; the
real ones are somewhere else by a few millimetres, which is why the skill looks.  The engine's
cell snapshot can carry that ground truth (``CellSnapshot.truth``); a locate returns it plus a
small seeded noise, so a skill that corrects its approach with the measurement lands on the true
feature, and one that does not lands beside it.

Cameras are the Nextage's: a stereo pair on the head (``HEAD_JOINT1_Link``; the mount offsets
are hrpsys' CAMERA_HEAD_L/R sensor positions) and one on each hand.  A camera sees a feature
only within its working range; farther away is a VISION fault, as is an unknown feature.
The hand camera mount and all ranges are this simulator's assumptions (docs/nextage_sim.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from core_functions.geometry import Pose
from core_functions.primitives import Vision, VisionResult
from robot_bridges.backend import BridgeError, FaultKind

if TYPE_CHECKING:  # the cell snapshot is only a parameter type here
    from execution_engine.transport.wire import CellSnapshot

#: Capture plus image processing time of one vision primitive (s).
VISION_TIME = 0.25


@dataclass(frozen=True)
class Camera:
    name: str
    link: str  # the link the camera is mounted on
    mount: Pose  # camera origin in that link
    max_range: float  # m: farther features are not found


CAMERAS: dict[str, Camera] = {
    c.name: c
    for c in (
        Camera("head_camera", "HEAD_JOINT1_Link", Pose(0.059959, 0.0, 0.095), 1.5),
        Camera("head_camera_left", "HEAD_JOINT1_Link", Pose(0.059959, 0.069754, 0.095), 1.5),
        Camera("head_camera_right", "HEAD_JOINT1_Link", Pose(0.059959, -0.069754, 0.095), 1.5),
        Camera("left_hand_camera", "LARM_JOINT5_Link", Pose(-0.05, 0.0, 0.0), 0.6),
        Camera("right_hand_camera", "RARM_JOINT5_Link", Pose(-0.05, 0.0, 0.0), 0.6),
    )
}


def camera(name: str) -> Camera:
    try:
        return CAMERAS[name]
    except KeyError:
        raise BridgeError(FaultKind.VISION, f"no camera {name!r} (cameras: {', '.join(CAMERAS)})") from None


class SimulatedVision:
    """Ground truth plus seeded noise; deterministic for a given seed and call sequence."""

    def __init__(self, seed: int = 0, position_noise: float = 1e-4, angle_noise: float = math.radians(0.05)) -> None:
        self._rng = np.random.default_rng(seed)
        self.position_noise = position_noise  # m, standard deviation per axis
        self.angle_noise = angle_noise  # rad, standard deviation per axis
        self._cell: CellSnapshot | None = None

    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell

    def observe(self, primitive: Vision, cam: Camera, camera_pose: Pose) -> VisionResult:
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
        nominal = primitive.nominal or self._frame_pose(target)
        truth = self._cell.truth.get(target) if (self._cell is not None and target) else None
        actual = truth or nominal
        if actual is None:
            where = "the cell model" if self._cell is not None else "any cell model (none received yet)"
            raise BridgeError(FaultKind.VISION, f"feature {target!r} is unknown: not in {where} and no nominal pose given")
        return actual, nominal

    def _frame_pose(self, name: str) -> Pose | None:
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
