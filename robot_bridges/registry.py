"""The back ends the CLI and launch files can choose, by name, imported only when chosen.

Each entry is ``module:function`` of an async factory ``(clock, BackendOptions) -> RobotBackend``;
importing lazily keeps pinocchio, sockets and simulators out of runs that do not use them.
"""
from __future__ import annotations

import importlib
from collections.abc import Awaitable, Callable

from core_functions.cell_robots import BACKEND_NAMES, CELL_BACKEND
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions, RobotBackend

BACKENDS: dict[str, str] = {
    "nextage-sim": "robot_bridges.nextage_sim.backend:create",
    "vplus": "robot_bridges.vplus.backend:create",
    "kuka-rsi": "robot_bridges.kuka_rsi.backend:create",
    "ros2-control": "robot_bridges.ros2_control.factory:create",  # any robot whose driver serves FollowJointTrajectory
    CELL_BACKEND: "robot_bridges.cell_backend:create",  # the robots of a mixed cell, each on its own back end
}
if set(BACKENDS) != {*BACKEND_NAMES, CELL_BACKEND}:  # what a cell's <robot backend=...> may name
    raise ImportError("robot_bridges.registry: BACKENDS and core_functions.cell_robots.BACKEND_NAMES differ")

BackendFactory = Callable[[Clock, BackendOptions], Awaitable[RobotBackend]]


def backend_factory(name: str) -> BackendFactory:
    try:
        target = BACKENDS[name]
    except KeyError:
        raise KeyError(f"unknown robot back end {name!r} (choose from: {', '.join(BACKENDS)})") from None
    module_name, _, function = target.partition(":")
    module = importlib.import_module(module_name)
    factory: BackendFactory = getattr(module, function)
    return factory


async def create_backend(name: str, clock: Clock, options: BackendOptions) -> RobotBackend:
    """The back end ``name`` built from ``options``, at the speed override they start with."""
    backend = await backend_factory(name)(clock, options)
    if options.speed_override != 1.0:
        backend.set_speed_override(options.speed_override)
    return backend


def check_options(name: str, options: BackendOptions, speed: float) -> None:
    """Refuse ``options`` as back end ``name`` would for a run on a clock of ``speed`` (``math.inf``:
    simulated time), building, connecting and starting nothing: each back end's ``parse_options``,
    which its factory builds from, so the two cannot disagree.  ValueError/KeyError naming the option."""
    target = BACKENDS.get(name)
    if target is None:
        backend_factory(name)  # the one-line KeyError naming the back ends
        return
    module = importlib.import_module(target.partition(":")[0])
    module.parse_options(options, speed)
