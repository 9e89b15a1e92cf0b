"""Which simulator a dry run uses for a back end, with which options, on which clock.

A dry run never talks to a controller: for a real robot (``--host``, ``--rsi-listen``) it runs on
the simulator of that robot, with the options that change what the robot can do (the RSI
configuration and its tool outputs, V+'s ``linear`` and camera, the Nextage tool) kept, and the
ones that only concern a connection or a demonstration (addresses, injected faults) dropped.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from core_functions.cell_robots import CELL_BACKEND, CellRobot, CellRobotModel
from robot_bridges.backend import BackendOptions, RobotBackend
from robot_bridges.cell_backend import member_options

#: Nextage simulator control period in the dry run (0.01 s in a run).  A planned motion stays within
#: the joint limits between its checked samples (the limits are a box, the samples are interpolated
#: linearly), so ticking along it every 10 ms only costs time, and each motion ends at its exact
#: duration whatever the period.  The period bounds how long a stop takes to land, though: the
#: engine stops the groups beside a failed function, and the bridge waits 5 s for that.
NEXTAGE_DRY_RUN_PERIOD = 0.5
#: Options about the link to a controller or about logging, not about what the robot does: left
#: out of the dry run.  Every other option is kept (and an unknown one refused, as the run would).
_LINK_ONLY: dict[str, tuple[str, ...]] = {
    "vplus": ("controller_speed",),
    "kuka-rsi": ("runner", "simulator", "silence", "feedback"),
}


@dataclass(frozen=True)
class DryRunSetup:
    """How to build the dry run's robot: registry name, options, clock, and its own time if it keeps one."""

    backend: str
    options: BackendOptions
    simulated_clock: bool = True  # False: a simulator keeping its own time, run beside the real clock
    robot_seconds: Callable[[RobotBackend], Callable[[], float]] | None = None
    unkept: str = ""  # why no verdict of it may be kept (the robot's model comes from outside the files the key reads)


def _kuka_seconds(backend: RobotBackend) -> Callable[[], float]:
    """RSI's own time: cycles (IPOC steps) the simulated controller has run."""
    from robot_bridges.kuka_rsi.backend import KukaRsiBackend  # slow to load (0.05 s, numpy): only a KUKA dry run needs it

    if not isinstance(backend, KukaRsiBackend):
        raise TypeError(f"RSI cycles asked of {backend.name}")
    kuka, cycle = backend, backend.link.cycle_ms / 1000.0

    def seconds() -> float:
        return 0.0 if kuka.iface is None else kuka.iface.state(0).cycles * cycle

    return seconds


def setup_for(backend: str, options: BackendOptions) -> DryRunSetup:
    """The dry run's simulator for ``backend`` configured by ``options`` (the ones of the real run)."""
    if backend == CELL_BACKEND and isinstance(options.robot, CellRobotModel):
        return _cell_setup(options.robot, options)
    extra = {k: v for k, v in options.extra.items() if k not in _LINK_ONLY.get(backend, ())}
    offline = replace(options, host=None, port=None, rsi_listen=None, faults=(), extra=extra)
    if backend == "nextage-sim":
        return DryRunSetup(backend, replace(offline, extra={**extra, "control_period": str(NEXTAGE_DRY_RUN_PERIOD)}))
    if backend == "vplus":
        camera = extra.get("camera", "none" if options.host is not None else "simulated")  # what the real run would have
        return DryRunSetup(backend, replace(offline, extra={**extra, "camera": camera}))
    if backend == "kuka-rsi":
        accelerated = {**extra, "simulator": "accelerated", "runner": "thread"}
        return DryRunSetup(backend, replace(offline, extra=accelerated), simulated_clock=False, robot_seconds=_kuka_seconds)
    if backend == "ros2-control" and extra.get("transport", "dds") in ("dds", "ros"):  # the URDF model is the robot; its URDF read where the run reads it
        modelled = {**extra, "transport": "model", "description": extra.get("transport", "dds")}
        unkept = "" if extra.get("urdf") else "the robot's URDF is read from /robot_description on the ROS graph"
        return DryRunSetup(backend, replace(offline, extra=modelled), unkept=unkept)
    return DryRunSetup(backend, offline)


def _cell_setup(robot: CellRobotModel, options: BackendOptions) -> DryRunSetup:
    """A mixed cell's dry run: each robot on the simulator its own back end's dry run uses, all at once on one
    clock -- the real one as soon as one of them keeps its own time (a KUKA's RSI controller, then in real
    time rather than accelerated, so that every robot's motions stand on the same time line)."""
    members: list[CellRobot] = []
    setups: list[DryRunSetup] = []
    for member in robot.members:
        setup = setup_for(member.backend, member_options(options, member))
        extra = setup.options.extra
        if setup.robot_seconds is not None:  # its own accelerated time would not line up with the others' motions:
            extra = {**extra, "simulator": "process", "runner": "process"}  # as a run; the collision sweep needs one time line, the wall clock's
        setups.append(setup)
        members.append(replace(member, options=tuple(extra.items())))
    simulated = replace(robot, members=tuple(members))
    unkept = "; ".join(s.unkept for s in setups if s.unkept)
    offline = replace(options, robot=simulated, host=None, port=None, rsi_listen=None, faults=(), extra={})
    return DryRunSetup(CELL_BACKEND, offline, simulated_clock=all(s.simulated_clock for s in setups), unkept=unkept)
