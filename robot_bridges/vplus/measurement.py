"""The measurement port of the V+ back end, and a simulated focus camera behind it.

An Adept controller has no camera: in the seed's cell, images come from a separate acquisition
service and a processing node (over ZeroMQ), and the master control node asks them for a
measurement -- the sharpness of a calibration target held by the tool -- between robot moves.
So the V+ back end does not measure anything itself; it hands every :class:`Vision` primitive
to a :class:`MeasurementPort`.  Plug the real vision pipeline in by implementing the port; the
simulated one here stands in for it when the cell runs on the V+ simulator.
"""
from __future__ import annotations

import math
import random
from abc import ABC, abstractmethod

from core_functions.geometry import Pose
from core_functions.primitives import Vision, VisionResult


class MeasurementError(Exception):
    """The vision side could not measure (no target, no image); becomes a VISION fault."""


class MeasurementPort(ABC):
    """Whatever answers the robot's vision requests."""

    @abstractmethod
    async def measure(self, request: Vision, tcp: Pose) -> VisionResult:
        """Answer ``request`` with the tool at ``tcp`` (world frame); raise :class:`MeasurementError`."""


class SimulatedFocusCamera(MeasurementPort):
    """A fixed camera focused on a plane: sharpness of the target on the tool, by its distance.

    ``measure`` requests return the sharpness of the calibration target carried by the tool, a
    Gaussian of the TCP's signed distance to the focus plane along the plane's z axis -- the
    shape of the seed's Figure 9 -- with a little seeded noise.  The focus plane is the request's
    ``nominal`` pose (the cell frame the skill names).  ``locate`` returns the nominal pose (a
    perfect camera); ``inspect`` scores 1 when the target is in focus.
    """

    def __init__(self, depth_of_field: float = 0.003, peak: float = 100.0, noise: float = 0.001, seed: int = 0) -> None:
        if not (depth_of_field > 0 and peak > 0 and noise >= 0):
            raise ValueError("depth_of_field and peak must be > 0, noise >= 0")
        self.depth_of_field = depth_of_field
        self.peak = peak
        self.noise = noise
        self._random = random.Random(seed)
        self.requests = 0

    def distance(self, plane: Pose, tcp: Pose) -> float:
        """Signed distance (m) of the TCP from the focus plane, along the plane's z axis."""
        return plane.inverse().compose(tcp).z

    def sharpness(self, distance: float) -> float:
        return self.peak * math.exp(-0.5 * (distance / self.depth_of_field) ** 2)

    async def measure(self, request: Vision, tcp: Pose) -> VisionResult:
        self.requests += 1
        if request.nominal is None:
            raise MeasurementError(f"no pose for {request.target or 'the target'}: the simulated camera needs the focus plane's frame")
        if request.task == "locate":
            return VisionResult(pose=request.nominal, score=1.0)
        value = self.sharpness(self.distance(request.nominal, tcp))
        value *= 1.0 + self._random.gauss(0.0, self.noise)
        if request.task == "inspect":
            return VisionResult(value=value, score=min(1.0, value / self.peak))
        return VisionResult(value=value, score=1.0)
