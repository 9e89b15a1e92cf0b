"""``python -m execution_engine vision detect``: the hole detector on an image file, for integrators.

The image shows a plane seen head-on at ``--distance`` (m) by a camera with the given pinhole
intrinsics (px); holes of ``--diameter`` (m) are found by :func:`core_functions.vision.holes.find_holes`,
the very function the Vision state uses, and printed in the camera's optical frame (x right,
y down, z along the optical axis; metres).

Exit codes: 0 detection ran (whatever it found, ``{"holes": []}`` included); 1 the image file is
missing, too large or unreadable; 2 a bad command line (a number that is not a positive finite
number, a missing option).  Errors are one line on stderr, naming the file or option.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import IO

from cell_runner.settings import DetectSettings
from core_functions.option_ranges import RangeError, bounds, check
from core_functions.vision.camera import Intrinsics
from core_functions.vision.holes import Hole, detect_head_on
from core_functions.vision.image_file import ImageFileError, read_image

EXIT_OK, EXIT_IMAGE, EXIT_USAGE = 0, 1, 2
#: option -> (its setting in core_functions.option_ranges, what it is)
_NUMBERS = {
    "fx": ("focal_length", "focal length along x (px)"), "fy": ("focal_length", "focal length along y (px)"),
    "cx": ("principal_point", "principal point x (px)"), "cy": ("principal_point", "principal point y (px)"),
    "distance": ("distance", "distance of the plane along the optical axis (m)"), "diameter": ("diameter", "expected hole diameter (m)"),
}


def add_vision_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    vision = sub.add_parser("vision", help="camera tools: detect holes in an image file")
    tools = vision.add_subparsers(dest="vision_command", required=True)
    detect = tools.add_parser("detect", help="find holes of a diameter on a plane seen head-on; print centres (px, m) and diameters")
    detect.add_argument("image", metavar="IMAGE", help="image file (PNG, JPEG, TIFF, BMP, PGM, ...)")
    for name, (setting, text) in _NUMBERS.items():  # parsed here: one-line errors
        detect.add_argument(f"--{name}", required=True, metavar=name.upper(), help=f"{text}, in {bounds(setting).describe()}")
    detect.add_argument("--json", action="store_true", help='print {"holes": [{"center_px": [u, v], "center_m": [x, y, z], "diameter_m": d, "score": s}, ...]}')


def _number(name: str, text: str) -> float:
    """``--NAME``'s value in its range (core_functions.option_ranges); RangeError naming the option and the range."""
    return check(_NUMBERS[name][0], text, label=f"--{name}")


def detect_settings(args: argparse.Namespace) -> DetectSettings:
    """``vision detect``'s options, each number in its range: RangeError naming the option otherwise."""
    values = {name: _number(name, vars(args)[name]) for name in _NUMBERS}
    return DetectSettings(image=args.image, json=args.json, **values)


def run_vision(args: argparse.Namespace, out: IO[str], err: IO[str]) -> int:
    """The ``vision`` subcommand: its settings (a number out of range: one line, exit 2), then the detection."""
    try:
        settings = detect_settings(args)
    except RangeError as error:
        err.write(f"error: {error}\n")
        return EXIT_USAGE
    return cmd_vision(settings, out, err)


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
