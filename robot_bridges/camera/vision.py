"""The Vision state on cameras: capture, detect, transform into the world, report.

Joins a back end's cameras (:mod:`robot_bridges.camera.sources`) to the detector
(:mod:`core_functions.vision.locate`).  The back end says which cameras take part and where each
optical frame is at capture time (its forward kinematics composed with the hand-eye mount); this
module asks the sources for the images, finds the feature the cell model describes and answers
with its measured world pose, which the skill's ``locate_frame`` puts into the cell index exactly
as before.  A feature the cameras have no image model of (a fixture, a tray) goes to the back
end's ``fallback`` if it has one; every result carries a :class:`VisionReport` for the trace.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from core_functions.cell_index import CellFrame
from core_functions.geometry import Pose
from core_functions.primitives import Vision, VisionReport, VisionResult
from core_functions.vision.features import FeatureModel, feature_model
from core_functions.vision.locate import View, VisionFault, feature_roi, locate
from core_functions.vision.sharpness import sharpness
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.camera.render import Scene
from robot_bridges.camera.scene import build_scene
from robot_bridges.camera.sources import CameraSource, CaptureError, Frame
from robot_bridges.camera.spec import CameraSpec

if TYPE_CHECKING:
    from node_transport.wire import CellSnapshot

#: (camera, its optical frame in the world at capture) for each camera taking part.
Placed = Sequence[tuple[CameraSpec, Pose]]
Fallback = Callable[[Vision, Placed], VisionResult]
#: Called with every image taken (to publish or record it); nothing is copied unless one is set.
CaptureHook = Callable[[CameraSpec, Pose, Frame], None]


class CameraVision:
    """Answers Vision primitives from camera images."""

    def __init__(
        self, source: CameraSource | Callable[[str], CameraSource], fallback: Fallback | None = None, specs: Mapping[str, CameraSpec] | None = None
    ) -> None:
        self._source = source
        self._fallback = fallback
        #: The real cameras (not the names standing for a pair), for wiring topics to them.
        self.specs: Mapping[str, CameraSpec] = dict(specs or {})
        self._cell: CellSnapshot | None = None
        self._frames: dict[str, CellFrame] = {}
        self._scene: Scene | None = None
        self.on_capture: CaptureHook | None = None

    def use_source(self, source: CameraSource | Callable[[str], CameraSource]) -> None:
        """Take images from ``source`` from now on (a ROS camera instead of the renderer)."""
        self._source = source

    # ------------------------------------------------------------------------ the cell
    def set_cell(self, cell: CellSnapshot) -> None:
        self._cell = cell
        self._frames = {f.name: f for f in cell.frames}
        self._scene = None

    def scene(self) -> Scene:
        """The cell as rendered (built once per cell model)."""
        if self._scene is None:
            cell = self._cell
            self._scene = Scene() if cell is None else build_scene(cell.frames, cell.elements, cell.truth)
        return self._scene

    def model_of(self, target: str) -> FeatureModel | None:
        frame = self._frames.get(target)
        if frame is None or self._cell is None:
            return None
        try:
            return feature_model(frame, self._cell.elements)
        except ValueError as error:
            raise BridgeError(FaultKind.VISION, str(error)) from None

    # ---------------------------------------------------------------------- capturing
    async def capture(self, placed: Placed) -> list[View]:
        views = []
        for spec, pose in placed:
            source = self._source if isinstance(self._source, CameraSource) else self._source(spec.name)
            try:
                frame = await source.capture(spec, pose)
            except CaptureError as error:
                raise BridgeError(FaultKind.VISION, f"{spec.name}: no image: {error}") from None
            if self.on_capture is not None:
                self.on_capture(spec, pose, frame)
            views.append(View(spec.name, frame.image, frame.intrinsics, pose))
        return views

    # ------------------------------------------------------------------------ the state
    async def observe(self, primitive: Vision, placed: Placed) -> VisionResult:
        """Answer ``primitive`` from images of the ``placed`` cameras; BridgeError(VISION) when it cannot."""
        target = primitive.target
        model = self.model_of(target)
        nominal = primitive.nominal or (self._frames[target].pose if target in self._frames else None)
        camera = "+".join(spec.name for spec, _ in placed)
        if primitive.task == "measure" and (model is not None or self._frames.get(target, _NO_FRAME).attributes.get("measure") == "sharpness"):
            views = await self.capture(placed[:1])
            # Around the feature when it is in view: its edges, not the noise of a plain surface, then rule the measure.
            roi = feature_roi(views[0], nominal, model.diameter) if (model is not None and nominal is not None) else None
            value = sharpness(views[0].image, roi)
            size = (views[0].intrinsics.width, views[0].intrinsics.height)
            return VisionResult(value=value, report=VisionReport(camera, "sharpness", size, nominal, sharpness=value))
        if model is None or nominal is None or primitive.task == "measure":
            if self._fallback is None:
                raise BridgeError(FaultKind.VISION, f"{target or 'the feature'}: the cameras have no image model of it (no diameter in the cell model)")
            return self._fallback(primitive, placed)
        views = await self.capture(placed)
        try:
            found = locate(views, target, nominal, model)
        except VisionFault as error:
            raise BridgeError(FaultKind.VISION, str(error)) from None
        correction = tuple(m - n for m, n in zip(found.pose.position, nominal.position))
        report = VisionReport(
            camera=camera,
            method=found.method,
            image_size=(views[0].intrinsics.width, views[0].intrinsics.height),
            nominal=nominal,
            measured=found.pose,
            correction=(correction[0], correction[1], correction[2]),
            residual=found.residual,
            diameter=found.diameter,
            sharpness=found.sharpness,
        )
        value = found.pose.distance_to(nominal) if primitive.task == "inspect" else None
        return VisionResult(pose=found.pose, value=value, score=found.score, report=report)


_NO_FRAME = CellFrame("", Pose())
