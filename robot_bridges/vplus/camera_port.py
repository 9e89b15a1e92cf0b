"""A measurement port on camera images: the focus loop's sharpness from a real (or rendered) image.

The seed's cell has a fixed camera with a close-range lens looking at the part the tool holds;
the master node asks for the sharpness of a calibration target on the tool between robot moves.
:class:`CameraMeasurement` answers ``measure``/``inspect`` with the variance of the Laplacian
(:func:`core_functions.vision.sharpness.sharpness`) of an image from any
:class:`~robot_bridges.camera.sources.CameraSource`: a ROS camera on a real cell, or, on the V+
simulator, :func:`rendered_focus_camera`, which renders the calibration target (a grid of dark
dots) where the tool holds it, as the fixed camera sees it with its shallow depth of field.
"""
from __future__ import annotations

import math

from core_functions.geometry import Pose
from core_functions.primitives import Vision, VisionReport, VisionResult
from core_functions.vision.camera import Intrinsics
from core_functions.vision.sharpness import sharpness
from robot_bridges.camera.render import Disc, Lighting, Optics, Scene, Surface
from robot_bridges.camera.sources import CameraSource, CaptureError, RenderedCamera
from robot_bridges.camera.spec import CameraSpec
from robot_bridges.vplus.measurement import MeasurementError, MeasurementPort

#: The seed's inspection camera: 35 mm lens, 150 mm from its focus plane, a few mm of depth of field.
FOCUS_CAMERA = CameraSpec(
    "inspection_camera", "world", Pose(), Intrinsics.from_fov(640, 480, math.radians(15.0)), Optics(0.15, aperture=0.006), 1.0
)
#: Calibration target on the tool: dots of 1.5 mm on a 4 mm grid, 5 x 5.
TARGET_DOTS = tuple(Disc(0.004 * i, 0.004 * j, 0.0015, 0.08) for i in range(-2, 3) for j in range(-2, 3))


def facing(plane: Pose, distance: float) -> Pose:
    """The camera ``distance`` along the focus plane's z axis, looking back at the plane."""
    return plane.compose(Pose(0.0, 0.0, distance)).compose(Pose.from_xyz_rpy(0.0, 0.0, 0.0, math.pi, 0.0, 0.0))


class CameraMeasurement(MeasurementPort):
    """``measure``/``inspect``: sharpness of the camera's image; ``locate``: not a job for a fixed focus camera."""

    def __init__(self, source: CameraSource, spec: CameraSpec = FOCUS_CAMERA, peak: float | None = None) -> None:
        self.source = source
        self.spec = spec
        self.peak = peak  # inspect scores value / peak when given
        self.tcp = Pose()
        self.requests = 0

    async def measure(self, request: Vision, tcp: Pose) -> VisionResult:
        self.requests += 1
        if request.task == "locate":
            raise MeasurementError("the inspection camera measures sharpness; it does not locate features")
        if request.nominal is None:
            raise MeasurementError(f"no pose for {request.target or 'the target'}: the camera needs the focus plane's frame")
        self.tcp = tcp
        try:
            frame = await self.source.capture(self.spec, facing(request.nominal, self.spec.optics.focus_distance))
        except CaptureError as error:
            raise MeasurementError(f"{self.spec.name}: no image: {error}") from None
        value = sharpness(frame.image)
        size = (frame.intrinsics.width, frame.intrinsics.height)
        report = VisionReport(self.spec.name, "sharpness", size, request.nominal, sharpness=value)
        score = min(1.0, value / self.peak) if (request.task == "inspect" and self.peak) else 1.0
        return VisionResult(value=value, score=score, report=report)


def rendered_focus_camera(seed: int = 0) -> CameraMeasurement:
    """The simulator's inspection camera: renders the calibration target at the tool's current pose."""
    port: CameraMeasurement

    def scene() -> Scene:
        return Scene((Surface(port.tcp.matrix(), (0.012, 0.012), 0.8, TARGET_DOTS),), Lighting((0.1, 0.05), 0.1))

    port = CameraMeasurement(RenderedCamera(scene, seed))
    return port
