"""Where images come from: the simulator's renderer, image files (offline tests), and (ros_camera) ROS topics.

A source is asked for one image of one camera whose optical frame is at ``pose`` (world) now; a
rendering source draws the cell from there, a real one ignores the pose (the robot put the
camera there) and returns its next image.  Failing to deliver is a :class:`CaptureError`, which
the Vision state reports as a VISION fault.
"""
from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from core_functions.vision.image_file import ImageFileError, read_image
from robot_bridges.camera.render import Scene, render
from robot_bridges.camera.spec import CameraSpec

class CaptureError(Exception):
    """No image: the camera did not deliver, the file is missing or unreadable, sizes disagree."""


@dataclass(frozen=True)
class Frame:
    """One image and the intrinsics it was taken with; ``stamp`` in s of the run's clock."""

    image: NDArray[np.uint8]
    intrinsics: Intrinsics
    stamp: float = 0.0


class CameraSource(ABC):
    @abstractmethod
    async def capture(self, spec: CameraSpec, pose: Pose) -> Frame:
        """The image camera ``spec`` takes with its optical frame at ``pose``; CaptureError if none."""


class RenderedCamera(CameraSource):
    """The simulator's camera: renders the current scene (seeded noise: the same seed, the same images)."""

    def __init__(self, scene: Callable[[], Scene], seed: int = 0, now: Callable[[], float] = lambda: 0.0) -> None:
        self._scene = scene
        self._rng = np.random.default_rng(seed)
        self._now = now

    async def capture(self, spec: CameraSpec, pose: Pose) -> Frame:
        image = render(self._scene(), spec.intrinsics, pose.matrix(), spec.optics, self._rng)
        return Frame(image, spec.intrinsics, self._now())


class FileCamera(CameraSource):
    """Images from files, one per capture in the given order (cycling): offline tests, replayed sessions."""

    def __init__(self, paths: Sequence[Path]) -> None:
        if not paths:
            raise ValueError("a file camera needs at least one image file")
        self.paths = tuple(paths)
        self._next: Iterator[Path] = itertools.cycle(self.paths)

    async def capture(self, spec: CameraSpec, pose: Pose) -> Frame:
        path = next(self._next)
        try:
            image = read_image(path)
        except ImageFileError as error:
            raise CaptureError(str(error)) from None
        intr = spec.intrinsics
        if image.shape != (intr.height, intr.width):
            raise CaptureError(f"{path}: {image.shape[1]}x{image.shape[0]} px, but camera {spec.name} takes {intr.width}x{intr.height}")
        return Frame(image, intr)
