"""``vision detect``'s detection: the image read, the holes found and printed (see :mod:`cell_runner.vision_cli`).

A module of its own because it loads OpenCV and numpy, which the command line imports only when
``vision`` runs.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import IO

from cell_runner.settings import DetectSettings
from core_functions.vision.camera import Intrinsics
from core_functions.vision.holes import Hole, detect_head_on
from core_functions.vision.image_file import ImageFileError, read_image

EXIT_OK, EXIT_IMAGE = 0, 1


def cmd_vision(settings: DetectSettings, out: IO[str], err: IO[str]) -> int:
    try:
        image = read_image(Path(settings.image))
    except ImageFileError as error:
        err.write(f"error: {error}\n")
        return EXIT_IMAGE
    height, width = image.shape
    intrinsics = Intrinsics(width, height, settings.fx, settings.fy, settings.cx, settings.cy)
    holes = detect_head_on(image, intrinsics, settings.distance, settings.diameter)
    if settings.json:
        out.write(json.dumps({"holes": [h.as_json() for h in holes]}) + "\n")
    else:
        out.write(f"{settings.image}: {len(holes)} hole(s) of {settings.diameter * 1000:g} mm at {settings.distance:g} m\n")
        for i, hole in enumerate(holes, start=1):
            out.write(_line(i, hole))
    return EXIT_OK


def _line(i: int, hole: Hole) -> str:
    x, y, z = (v * 1000 for v in hole.center_m)
    return (
        f"  {i}: ({hole.center_px[0]:.2f}, {hole.center_px[1]:.2f}) px  ({x:.3f}, {y:.3f}, {z:.3f}) mm  "
        f"diameter {hole.diameter_m * 1000:.3f} mm  score {hole.score:.2f}\n"
    )
