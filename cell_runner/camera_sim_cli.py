"""``camera-sim``'s command line: its options checked before anything heavy loads (:mod:`cell_runner.camera_sim` serves)."""
from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, field

from core_functions import option_ranges


@dataclass(frozen=True)
class CameraSimSettings:
    file: str
    transport: str = "dds"  # dds (Cyclone DDS, no ROS install) or ros (rclpy)
    rate: float = 5.0  # Hz: images per second of each camera
    urdf: str | None = None  # None: /robot_description
    cameras: tuple[str, ...] = ()  # (): every camera of the robot
    topics: Mapping[str, str] = field(default_factory=dict)  # camera -> topic prefix (default: its name)
    seed: int = 0
    start_timeout: float = 10.0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    sim = sub.add_parser("camera-sim", help="publish the application robot's camera images, rendered from the cell at the robot's joint states (a mock robot's cameras)")
    sim.add_argument("file", metavar="APP.xml", help="the application: its robot's cameras and its cell")
    sim.add_argument("--transport", choices=("dds", "ros"), default="dds", help="dds: Cyclone DDS without a ROS install (default); ros: rclpy")
    sim.add_argument("--rate", default="5", help=f"images per second of each camera, in {option_ranges.bounds('camera_rate').describe()} (default 5)")
    sim.add_argument("--urdf", metavar="FILE", help="the robot's URDF (default: /robot_description from the graph)")
    sim.add_argument("--camera", action="append", metavar="NAME[=PREFIX]", help="publish only this camera (repeatable), its topics under PREFIX (default: NAME)")
    sim.add_argument("--seed", type=int, default=0, help="image noise seed")


def settings_of(args: argparse.Namespace) -> CameraSimSettings:
    """The command line's settings; ValueError in one line naming the option."""
    rate = option_ranges.check("camera_rate", args.rate, label="--rate")
    chosen, topics = [], {}
    for text in args.camera or ():
        name, _, prefix = text.partition("=")
        if not name or any(c.isspace() for c in text) or prefix.endswith("/"):
            raise ValueError(f"--camera {text!r}: NAME or NAME=PREFIX (a topic prefix without spaces)")
        chosen.append(name)
        if prefix:
            topics[name] = prefix
    return CameraSimSettings(args.file, args.transport, rate, args.urdf, tuple(chosen), topics, args.seed)
