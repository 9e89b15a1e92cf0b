"""FocusApproach: the seed's focus-plane calibration (``ufloop``) and the rotating inspection.

The seed (Semeniuta and Falkman 2019) holds a small part close in front of a fixed camera with a
35 mm lens, so the part must sit in the camera's focus plane.  Its ``ufloop`` finds that plane:
from an approach pose, measure the sharpness of a calibration target on the tool, and while it
keeps rising move the tool along its z axis by ``delta_z``; when a measurement comes out lower
than the one before, the plane has been passed -- step back once.  The inspection then turns the
tool about its axis in increments, one image per increment.

Measurements arrive through the ``Vision`` primitive (task ``measure``/``inspect``): what the
group's back end does with it is the vision side's business.  The V+ back end hands it to its
:class:`robot_bridges.vplus.measurement.MeasurementPort` -- the simulated focus camera, or the
real pipeline once it is plugged in -- so these skills run unchanged on either.
"""
from __future__ import annotations

import math
from collections.abc import Generator
from typing import Any

from core_functions.catalog import ParamSpec, ParamType, skill
from core_functions.functions import CoreFunctions, Skill
from core_functions.geometry import Pose
from core_functions.primitives import MoveRelative, Primitive, SetSpeed, Vision, VisionResult


class FocusNotFound(RuntimeError):
    """The measurement never stopped rising within the allowed number of steps."""


class FocusApproach(CoreFunctions):
    """Skills of the seed's pick-and-inspect cell: find the focus plane, inspect by rotation."""

    def _measure(self, task: str, target: str) -> Generator[Primitive, Any, float]:
        result: VisionResult = yield Vision(task, target=target, nominal=self.cell.pose(target), camera=self.camera())  # type: ignore[arg-type]
        if result.value is None:
            raise LookupError(f"the vision side returned no value for {task} of {target!r}")
        return result.value

    @skill(
        ParamSpec("plane", ParamType.FRAME, "the camera's focus plane; its z axis points the way the tool approaches"),
        ParamSpec("step", ParamType.NUMBER, "tool z increment per iteration (the seed's delta_z)", unit="m", default="0.002", minimum=0.0001, maximum=0.02),
        ParamSpec("speed", ParamType.NUMBER, "speed fraction of the increments (the seed's appr_speed)", unit="fraction", default="0.25", minimum=0.01, maximum=1.0),
        ParamSpec("max_steps", ParamType.INTEGER, "give up after this many increments", default="40", minimum=1, maximum=500),
        states=("Motion", "Vision"),
    )
    def focus_approach(self, plane: str, step: float = 0.002, speed: float = 0.25, max_steps: int = 40) -> Skill:
        """Move the tool along its z axis by increments while the measured sharpness rises; step back once it falls.

        Start from an approach pose in front of the camera.  Records every measurement under
        ``<plane>.sharpness.<i>`` and the best one under ``<plane>.sharpness``.  Leaves the speed at 100 %.
        """
        values: list[float] = []
        yield SetSpeed(speed)
        for increment in range(max_steps + 1):
            values.append((yield from self._measure("measure", plane)))
            if len(values) > 1 and values[-1] < values[-2]:
                break  # the plane is behind us
            if increment == max_steps:
                raise FocusNotFound(
                    f"sharpness still rising after {max_steps} steps of {step * 1000:g} mm towards {plane!r} "
                    f"(last values {', '.join(f'{v:.3g}' for v in values[-3:])})"
                )
            yield MoveRelative(Pose(0.0, 0.0, step), reference="tool")
        yield MoveRelative(Pose(0.0, 0.0, -step), reference="tool")  # back to the sharpest pose
        yield SetSpeed(1.0)
        for i, value in enumerate(values):
            self.ctx.measurements[f"{plane}.sharpness.{i}"] = value
        self.ctx.measurements[f"{plane}.sharpness"] = values[-2]

    @skill(
        ParamSpec("target", ParamType.FRAME, "what the camera inspects (the focus plane the part was brought to)"),
        ParamSpec("turns", ParamType.INTEGER, "number of images", default="4", minimum=1, maximum=72),
        ParamSpec("angle", ParamType.NUMBER, "tool rotation between images", unit="rad", default="1.5707963", minimum=-math.pi, maximum=math.pi),
        states=("Motion", "Vision"),
    )
    def inspect_rotating(self, target: str, turns: int = 4, angle: float = math.pi / 2) -> Skill:
        """Inspect the held part from several sides: an image, then a turn of the tool about its z axis, repeated.

        Records each score under ``<target>.inspect.<i>``; turns back to where it started.
        """
        for i in range(turns):
            self.ctx.measurements[f"{target}.inspect.{i}"] = yield from self._measure("inspect", target)
            if i < turns - 1:
                yield MoveRelative(Pose.from_xyz_rpy(0.0, 0.0, 0.0, yaw=angle), reference="tool")
        if turns > 1:
            yield MoveRelative(Pose.from_xyz_rpy(0.0, 0.0, 0.0, yaw=-angle * (turns - 1)), reference="tool")
