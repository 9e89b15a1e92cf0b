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

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from robot_bridges.camera.render import Scene, render
from robot_bridges.camera.spec import CameraSpec

#: Largest image file read (bytes): a camera image, not whatever a path points at.
MAX_IMAGE_BYTES = 64 * 1024 * 1024


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


def read_image(path: Path) -> NDArray[np.uint8]:
    """An image file as an 8-bit mono array; CaptureError naming the file when that cannot be."""
    try:
        size = path.stat().st_size
    except OSError as error:
        raise CaptureError(f"{path}: {error.strerror or error}") from None
    if not path.is_file():
        raise CaptureError(f"{path}: not a file")
    if size > MAX_IMAGE_BYTES:
        raise CaptureError(f"{path}: {size} bytes, larger than the {MAX_IMAGE_BYTES} bytes an image may have")
    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if image is None:
        raise CaptureError(f"{path}: not an image OpenCV can read (PNG, JPEG, TIFF, BMP, PGM, ...)")
    return image


class FileCamera(CameraSource):
    """Images from files, one per capture in the given order (cycling): offline tests, replayed sessions."""

    def __init__(self, paths: Sequence[Path]) -> None:
        if not paths:
            raise ValueError("a file camera needs at least one image file")
        self.paths = tuple(paths)
        self._next: Iterator[Path] = itertools.cycle(self.paths)

    async def capture(self, spec: CameraSpec, pose: Pose) -> Frame:
        path = next(self._next)
        image = read_image(path)
        intr = spec.intrinsics
        if image.shape != (intr.height, intr.width):
            raise CaptureError(f"{path}: {image.shape[1]}x{image.shape[0]} px, but camera {spec.name} takes {intr.width}x{intr.height}")
        return Frame(image, intr)
