"""The settings of each command, as the command line gives them: frozen, typed, checked when made.

The command line is the only code that reads argparse: each subcommand's module turns its
arguments into one of these, in one function next to the options it defines (``cli.py`` for
``run`` and ``validate``, ``launcher``, ``run_report`` and ``vision_cli`` for theirs), and hands
that down.  Nothing below it reads an attribute that may or may not be there, and nothing
changes a setting on the way: a step that works a setting out -- a controller's name resolved to
its address, the checkpoint named next to the trace, a resumed run's new trace -- returns new
settings (``dataclasses.replace``).  The studio builds the same :class:`RunSettings` for every run
it starts from the page.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from core_functions.option_ranges import START_HELD, bounds
from execution_engine.app_model import Application
from execution_engine.checkpoint.store import ANSWERS
from node_transport.clock import Clock, scaled_clock, simulated_clock
from robot_bridges.backend import BackendOptions


@dataclass(frozen=True)
class BackendSettings:
    """Which back end a run drives and how it reaches, or simulates, the robot."""

    name: str | None = None  # --robot; None: the application robot's usual back end
    host: str | None = None  # a controller's address (V+); None starts the simulator
    port: int | None = None
    rsi_listen: str | None = None  # KUKA RSI: HOST:PORT to serve a real controller on
    faults: tuple[str, ...] = ()  # simulator fault injections, GROUP:KIND@FRACTION
    seed: int = 0  # simulator random seed (vision noise)
    options: tuple[tuple[str, str], ...] = ()  # --backend-option KEY=VALUE, in the order given (a later one wins)
    speed_override: float = 100.0  # --speed-override: percent of the application's speed the run starts at (engine/speed.py)

    def __post_init__(self) -> None:
        bounds("seed").check_int("--seed", self.seed)
        if bounds("speed_override").check("--speed-override", self.speed_override) == 0.0:
            raise ValueError(f"--speed-override: {START_HELD}")
        if self.port is not None:
            bounds("port").check_int("--port", self.port)

    def backend_for(self, app: Application) -> str:
        """``--robot``, else the application robot's usual back end: the run and its dry run use the same."""
        return str(self.name or app.robot.default_backend)

    @property
    def extra(self) -> dict[str, str]:
        """The back-end options by name."""
        return dict(self.options)

    def backend_options(self, app: Application) -> BackendOptions:
        """What the back end of ``app``'s robot is built from."""
        return BackendOptions(robot=app.robot, host=self.host, port=self.port, rsi_listen=self.rsi_listen, faults=self.faults, seed=self.seed, extra=self.extra,
                              speed_override=self.speed_override / 100.0)


@dataclass(frozen=True)
class Outputs:
    """The files a run writes (and the trajectory database it also reads); None: not written."""

    trace: str | None = None
    record: str | None = None
    checkpoint: str | None = None
    trajectory_db: str | None = None


@dataclass(frozen=True)
class RunSettings:
    """How a run goes: ``run``'s options, and the studio's for every run it starts."""

    backend: BackendSettings = field(default_factory=BackendSettings)
    speed: float = 1.0  # robot seconds per wall second; math.inf: simulated time, as fast as the computer goes
    outputs: Outputs = field(default_factory=Outputs)
    check: bool = True  # the dry run on the simulator first, and again from where the robot is
    resume: str | None = None  # the checkpoint of the run this one goes on with
    on_interrupted: str = "ask"  # with resume: what to do with the function the crash interrupted
    interactive: bool = False  # operator keys at the terminal
    quiet: bool = False  # the summary only
    verbose: bool = False  # INFO log, tracebacks of defects

    def __post_init__(self) -> None:
        if not math.isinf(self.speed):
            bounds("speed").check("--speed", self.speed)
        if self.on_interrupted not in ANSWERS:
            raise ValueError(f"--on-interrupted {self.on_interrupted!r}: one of {', '.join(ANSWERS)}")

    def clock(self) -> Clock:
        """The run's clock: simulated time for ``max``, else robot time at ``speed``."""
        return simulated_clock() if math.isinf(self.speed) else scaled_clock(self.speed)


@dataclass(frozen=True)
class ValidateSettings:
    """``validate``: the files, and with ``simulate`` the back end whose simulator dry-runs them."""

    files: tuple[str, ...]
    simulate: bool = False
    backend: BackendSettings = field(default_factory=BackendSettings)
    trajectory_db: str | None = None  # read by the dry run, never written


@dataclass(frozen=True)
class LaunchSettings:
    """``launch``: the application, and how its cell's processes are started and supervised."""

    file: str
    transport: str = "dds"  # dds (Cyclone DDS, no ROS install) or ros (rclpy)
    speed: float = 1.0  # simulated seconds per wall second of a simulator back end
    nodes: str | None = None  # --nodes: comma-separated node names to start (launcher.select reads them); None: every node
    grace: float = 5.0  # s the engine gets to end its run by itself after another node died
    stop_timeout: float = 10.0  # s a node gets to stop on SIGTERM before SIGKILL
    check: bool = True  # the engine's dry run from the robot's measured joints (its parameter check)
    backend: str | None = None  # --robot: the back end of the application robot's bridge (None: the robot's usual one)
    options: tuple[tuple[str, str], ...] = ()  # --backend-option KEY=VALUE: the bridge's parameters of those names


@dataclass(frozen=True)
class ReportSettings:
    """``report``: the record to read, and where its timeline goes (None with ``draw``: next to the record)."""

    file: str
    timeline: str | None = None
    draw: bool = True


@dataclass(frozen=True)
class DetectSettings:
    """``vision detect``: the image, the camera's pinhole intrinsics (px), the plane and the hole (m)."""

    image: str
    fx: float
    fy: float
    cx: float
    cy: float
    distance: float
    diameter: float
    json: bool = False
