"""The ``vplus`` back end's options, parsed and checked before anything connects, starts or runs.

``run`` checks them before its dry run (``robot_bridges.registry.check_options``), and the back
end's factory builds from what this returns, so a value the run would refuse is refused first, in
the same words, and never after seconds of checking.  Numbers take their ranges from
:mod:`core_functions.option_ranges` (``timeout`` and ``tolerance_mm`` with the ranges of V+).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from core_functions import option_ranges
from core_functions.robots import ADEPT_VIPER_S850
from robot_bridges.backend import BackendOptions
from robot_bridges.vplus.trust import PoseTolerance

BACKEND = "vplus"
EXTRAS = ("timeout", "retries", "linear", "camera", "controller_speed", "tolerance_mm", "tolerance_deg", "sim_frozen_pose")


@dataclass(frozen=True)
class VPlusSettings:
    """What the back end is built from."""

    timeout: float
    retries: int
    tolerance: PoseTolerance
    frozen_pose: bool
    linear: str
    camera: str


def parse_options(options: BackendOptions, speed: float = 1.0) -> VPlusSettings:
    """The options checked against each other and against the run's clock (``speed``; ``math.inf``
    for simulated time); ValueError naming the option."""
    options.check(BACKEND, ADEPT_VIPER_S850, EXTRAS)
    if options.host is not None:
        # A real controller moves in real time: a scaled clock would divide every ack timeout by the
        # speed factor (real motions "time out"), a simulated one would jump every network wait.
        # Only a controller that is itself a simulator at that speed may be driven faster, and the
        # user must say so (controller_speed), never the run's --speed alone.
        controller_speed = option_ranges.check("speed", options.extra.get("controller_speed", "1"), label="vplus: controller_speed")
        if math.isinf(speed) or not math.isclose(speed, controller_speed):
            raise ValueError(
                f"vplus: the controller at {options.host} runs at x{controller_speed:g} (a real one in real time): run with "
                f"--speed {controller_speed:g}" + ("" if controller_speed != 1 else " (the default), or tell a simulated controller's speed with --backend-option controller_speed=F")
            )
    if options.rsi_listen is not None:
        raise ValueError("the vplus back end takes no rsi_listen (that is for KUKA RSI)")
    if options.faults:
        raise ValueError("the vplus back end takes no --fault: inject V+ faults through robot_bridges.vplus.simulator.Faults")
    timeout = option_ranges.check("timeout", options.extra.get("timeout", "5"), label="vplus: timeout", scope=BACKEND)
    retries = option_ranges.check_int("retries", options.extra.get("retries", "3"), label="vplus: retries")
    tolerance = PoseTolerance.from_options(options.extra, BACKEND)
    frozen = options.extra.get("sim_frozen_pose", "0")
    if frozen not in ("0", "1"):
        raise ValueError(f"vplus: sim_frozen_pose is 0 or 1, got {frozen!r}")
    if frozen == "1" and options.host is not None:
        raise ValueError("vplus: sim_frozen_pose shapes the simulated controller; a real one (--host) takes none")
    linear = options.extra.get("linear", "joint")
    if linear not in ("joint", "reject"):
        raise ValueError(f"vplus: linear must be 'joint' or 'reject', got {linear!r}")
    if options.port is not None:
        option_ranges.check_int("port", options.port, label="vplus: port")
        if options.port == 0 and options.host is not None:
            raise ValueError(f"vplus: port 0 names no AdeptServer: give the port the controller at {options.host} listens on")
    camera = options.extra.get("camera", "none" if options.host is not None else "simulated")
    if camera not in ("simulated", "rendered", "none"):
        raise ValueError(f"vplus: camera must be 'simulated', 'rendered' or 'none', got {camera!r}")
    return VPlusSettings(timeout, retries, tolerance, frozen == "1", linear, camera)
