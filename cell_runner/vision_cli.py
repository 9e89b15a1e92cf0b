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
from typing import IO

from cell_runner.settings import DetectSettings
from core_functions.option_ranges import RangeError, bounds, check

EXIT_USAGE = 2  # EXIT_OK and EXIT_IMAGE: cell_runner.vision_detect
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
    from cell_runner.vision_detect import cmd_vision  # slow to load: the detector loads OpenCV and numpy

    return cmd_vision(settings, out, err)
