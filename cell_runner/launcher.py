"""``python -m execution_engine launch APP``: the cell as one process per node, supervised.

::

    python -m execution_engine launch apps_xml/rivet_installation.xml --transport dds --speed 2
    python -m execution_engine launch app.xml --nodes nextage_sim_bridge          # this PC: the bridge
    python -m execution_engine launch app.xml --nodes left_arm_machine,right_arm_machine,torso_head_machine,execution_engine
    python -m execution_engine launch kuka_app.xml --robot ros2-control --backend-option arm.controller=/jtc/follow_joint_trajectory

The nodes are those of ``launch/<back end>.launch.py`` with the same names and the same
parameters (``config/<back end>.yaml`` as params file): the bridge of the application robot's back
end (``--robot``, with ``--backend-option KEY=VALUE`` as its parameters; a cell's robots: theirs), one ``group_machine`` per group, and the engine running APP with ``exit_when_done`` -- checked
first, as ``run`` is, by the dry run, here from the joints the bridge publishes, on the model of the bridge's
back end with its options (the engine's ``check_backend`` and ``check_options``, :mod:`cell_runner.engine_check`;
``--no-check``: the engine's ``check:=false``; docs/application_xml.md, "Checking before anything moves").  Each is
the installed executable's code in its own Python process with ``--transport dds`` (no ROS
install) or ``--transport ros`` (rclpy).  ``--nodes`` starts only some of them, so a cell can be
split across machines that share a DDS domain.

Supervision: each line a node prints is prefixed with its name.  The launch ends when the engine
ends (its exit code is the launch's), or at once when any other node dies: the launch names it
and how it died, gives the engine ``--grace`` seconds to end its run on its own (it notices a
lost machine within the DDS liveliness lease, ends the run in error naming the node and stops the
other groups), then stops every node, engine first and bridge last (SIGTERM, SIGKILL after
``--stop-timeout``), and exits with :data:`EXIT_NODE_DIED`.  SIGINT/SIGTERM stop the cell the same
way.  Without the engine among ``--nodes``, the launch serves until a node dies or it is stopped.
"""
from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from app_functions.registry import full_catalog
from cell_runner.engine_check import options_parameter
from cell_runner.settings import LaunchSettings
from core_functions.cell_robots import BACKEND_NAMES, CellRobotModel
from core_functions.geometry import Pose
from core_functions.option_ranges import argument_type
from core_functions.resources import share_path
from execution_engine.app_model import ApplicationError, load_application
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.wire import ENGINE_NODE, bridge_node_name, machine_node_name
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import check_options

EXIT_NODE_DIED = 6  # a node other than the engine ended before the engine did
EXIT_USAGE = 2
EXIT_INVALID = 1
_SPEED_PARAMETER = {"nextage-sim": "speed"}  # back ends whose bridge can run faster than real time (RSI runs on the robot's clock)
_ENTRY = {"engine": ("cell_runner.nodes", "engine_main"), "machine": ("cell_runner.nodes", "group_machine_main")}


@dataclass(frozen=True)
class NodeSpec:
    """One process of the cell: its node name and its command line."""

    name: str
    argv: tuple[str, ...]


@dataclass
class Running:
    spec: NodeSpec
    process: asyncio.subprocess.Process
    pumps: list[asyncio.Task[None]] = field(default_factory=list)


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    launch = sub.add_parser("launch", help="start the cell as one process per node (over DDS without ROS, or rclpy), supervised")
    launch.add_argument("file", metavar="FILE", help="application XML file the engine runs")
    launch.add_argument("--transport", choices=("dds", "ros"), default="dds", help="dds: Cyclone DDS without a ROS install (default); ros: rclpy")
    launch.add_argument("--speed", type=argument_type("speed"), default=1.0, help="simulated seconds per wall second of a simulator back end, in [0.01, 1000] (default 1)")
    launch.add_argument("--nodes", help="comma-separated node names to start (default: every node of the cell)")
    launch.add_argument("--grace", type=argument_type("grace"), default=5.0, help="seconds the engine gets to end its run by itself after another node died, in [0, 600] (default 5)")
    launch.add_argument("--stop-timeout", type=argument_type("stop_timeout"), default=10.0, help="seconds a node gets to stop on SIGTERM before SIGKILL, in [0.1, 600] (default 10)")
    launch.add_argument("--robot", choices=BACKEND_NAMES, help="the back end of the application robot's bridge (default: the robot's usual one), as for run")
    launch.add_argument(
        "--backend-option", action="append", type=backend_option, metavar="KEY=VALUE",
        help="back-end option as for run, given to the bridge as the parameter KEY (repeatable; a cell's robots take theirs from the cell)",
    )
    launch.add_argument(
        "--no-check", action="store_true",
        help="start without the dry run from the robot's measured joints that the engine otherwise does first (its parameter check:=false)",
    )


def backend_option(text: str) -> tuple[str, str]:
    """``--backend-option KEY=VALUE``."""
    key, equals, value = text.partition("=")
    if not equals or not key.strip():
        raise argparse.ArgumentTypeError(f"back-end options are KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


def _no_cameras(backend: str, options: tuple[tuple[str, str], ...], robot: str = "") -> None:
    """A ros2-control robot's cameras are the back end's in ``run`` only: its bridge process takes none (ValueError)."""
    if backend != "ros2-control":
        return
    given = [key for key, _ in options if key in ("camera_source", "camera_timeout") or key.endswith((".topic", ".mount"))]
    if given:
        whose = f"robot {robot!r} (ros2-control)" if robot else "ros2-control"
        raise ValueError(f"{whose}: option {given[0]}: the cameras of a ros2-control robot are taken in run only; launch's bridge process drives it without cameras")


def cell_nodes(
    app_file: Path, transport: str, speed: float, check: bool = True, backend: str | None = None, options: tuple[tuple[str, str], ...] = (),
) -> list[NodeSpec]:
    """The cell of ``app_file``'s robot, bridge first and engine last (the order they start in);
    ``check``: the engine dry-runs the application from the robot's measured joints before it starts;
    ``backend`` and ``options``: the bridge's back end and its options (``--robot``, ``--backend-option``),
    checked here as ``run`` checks them (ValueError naming the option)."""
    app = load_application(app_file, full_catalog())
    robot = app.robot
    checked_on: tuple[str, ...] = ()  # a cell's engine checks on its robots' own back ends and options (the cell's)
    if isinstance(robot, CellRobotModel):  # a mixed cell: one bridge node per robot, each with its cell's options and base
        if backend is not None or options:
            raise ValueError("a cell of several robots names each robot's back end and options in its <robot> elements (backend=, <option name= value=/>), not --robot or --backend-option")
        if speed != 1.0:
            raise ValueError(f"--speed {speed:g}: a cell of several robots runs in real time (each robot's bridge keeps its own clock)")
        for member in robot.members:
            _no_cameras(member.backend, member.options, member.name)
        specs = [_bridge_spec(m.backend, transport, speed, m.name, m.options, m.base, m.names.text(), m.model.name) for m in robot.members]
    else:
        chosen = backend or robot.default_backend
        if backend is not None or options:  # refused here in run's one line, before any process starts
            check_options(chosen, BackendOptions(robot=robot, extra=dict(options)), speed)
            _no_cameras(chosen, options)
            if check:  # the engine dry-runs on the model of the back end the bridge drives, with its options (engine_check)
                checked_on = ("-p", f"check_backend:={chosen}", "-p", options_parameter(options))
        specs = [_bridge_spec(chosen, transport, speed, options=options, model=robot.name)]
    # A simulator at another speed than real time is the cell's clock (it publishes /clock): every
    # other node measures its waits, timeouts and the report in the robot's time, as with use_sim_time:=true.
    followers = () if speed == 1.0 else ("-p", "use_sim_time:=true")
    for group in robot.group_names:
        name = machine_node_name(group)
        member = robot.member_of(group) if isinstance(robot, CellRobotModel) else None
        model, backend = (member.model, member.backend) if member is not None else (robot, robot.default_backend)
        named = ("-p", f"cell_names:={member.names.text()}") if member is not None and not member.names.identity else ()
        specs.append(NodeSpec(name, (
            *_python(*_ENTRY["machine"]), *_common(transport, backend), "-r", f"__node:={name}", "-p", f"group:={group}", "-p", f"robot:={model.name}",
            *named, *followers,
        )))
    common = _common(transport, robot.members[0].backend if isinstance(robot, CellRobotModel) else robot.default_backend)
    specs.append(NodeSpec(ENGINE_NODE, (
        *_python(*_ENTRY["engine"]), *common, "-p", f"application:={app_file.resolve()}", "-p", "exit_when_done:=true",
        *(() if check else ("-p", "check:=false")), *checked_on, *followers,
    )))
    return specs


def _bridge_spec(
    backend: str, transport: str, speed: float, robot: str = "", options: tuple[tuple[str, str], ...] = (), base: Pose | None = None,
    names: str = "", model: str = "",
) -> NodeSpec:
    """The bridge node of ``backend`` with ``options`` as its parameters; for a robot of a mixed cell named
    ``<robot>_bridge``, with its base pose and the cell's names of its groups and joints.  ``model``: the robot
    model, which the ros2-control bridge is told (the others drive one model each)."""
    module = backend.replace("-", "_")
    bridge = list(_common(transport, backend))
    if speed != 1.0:
        parameter = _SPEED_PARAMETER.get(backend)
        if parameter is None:
            raise ValueError(
                f"--speed {speed:g}: the {backend} bridge runs in real time, on the controller's clock; "
                f"only {', '.join(sorted(_SPEED_PARAMETER))} runs at another speed"
            )
        bridge += ["-p", f"{parameter}:={speed!r}"]
    name = bridge_node_name(backend)
    if robot:
        name = f"{robot}_bridge"
        bridge += ["-r", f"__node:={name}"]
        if base is not None:  # at the world's origin too: the bridge then places the robot's URDF and tf in the cell's world
            bridge += ["-p", "base_pose:=" + " ".join(repr(v) for v in (*base.position, *base.rpy()))]
        if names:
            bridge += ["-p", f"cell_names:={names}"]
    if backend == "ros2-control":
        bridge += ["-p", f"robot:={model}"]
    for key, value in options:
        bridge += ["-p", f"{key}:={value}"]
    return NodeSpec(name, (*_python(f"cell_runner.bridge_nodes.{module}", "main"), *bridge))


def _common(transport: str, backend: str) -> tuple[str, ...]:
    """A node's transport and the params file of ``backend``'s cell (config/<back end>.yaml: a section per node)."""
    return ("--transport", transport, "--ros-args", "--params-file", str(share_path("config", f"{backend.replace('-', '_')}.yaml")))


def _python(module: str, function: str) -> tuple[str, ...]:
    """The interpreter running ``module.function(sys.argv)`` as its own process (the console script's code)."""
    return (sys.executable, "-c", f"import sys; from {module} import {function}; sys.exit({function}(sys.argv))")


def select(specs: list[NodeSpec], nodes: str | None) -> list[NodeSpec]:
    if not nodes:
        return specs
    wanted = [n.strip() for n in nodes.split(",") if n.strip()]
    known = {s.name for s in specs}
    unknown = [n for n in wanted if n not in known]
    if unknown or not wanted:
        raise ValueError(f"--nodes: unknown node(s) {', '.join(unknown) or '(none given)'}; this cell has {', '.join(s.name for s in specs)}")
    return [s for s in specs if s.name in wanted]


def describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class Supervisor:
    """Starts the nodes, prefixes their output, ends them in order; one instance per launch."""

    def __init__(self, clock: Clock, out: IO[str], grace: float, stop_timeout: float) -> None:
        self.clock = clock
        self.out = out
        self.grace = grace
        self.stop_timeout = stop_timeout
        self.running: dict[str, Running] = {}

    def say(self, text: str) -> None:
        self.out.write(f"[launch] {text}\n")
        self.out.flush()

    async def start(self, spec: NodeSpec) -> None:
        process = await asyncio.create_subprocess_exec(
            *spec.argv, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT, stdin=asyncio.subprocess.DEVNULL,
        )
        running = Running(spec, process)
        assert process.stdout is not None
        running.pumps.append(asyncio.get_running_loop().create_task(self._pump(spec.name, process.stdout)))
        self.running[spec.name] = running
        self.say(f"{spec.name} started (pid {process.pid})")

    async def _pump(self, name: str, stream: asyncio.StreamReader) -> None:
        while line := await stream.readline():
            self.out.write(f"[{name}] {line.decode('utf-8', 'replace').rstrip()}\n")
            self.out.flush()

    async def run(self, stop: asyncio.Event) -> int:
        """Until the engine ends, a node dies or ``stop`` is set; then every node is stopped."""
        waits = {asyncio.ensure_future(r.process.wait()): name for name, r in self.running.items()}
        stopping = asyncio.ensure_future(stop.wait())
        code: int | None = None
        try:
            while code is None:
                done, _ = await asyncio.wait({*waits, stopping}, return_when=asyncio.FIRST_COMPLETED)
                if stopping in done:
                    self.say("stopping on request")
                    code = 0
                    break
                for task in done:
                    name = waits.pop(task)
                    rc = self.running[name].process.returncode
                    assert rc is not None
                    if name == ENGINE_NODE:
                        self.say(f"{name} ended ({describe_exit(rc)})")
                        code = rc if rc >= 0 else EXIT_NODE_DIED
                    elif code is None:
                        self.say(f"{name} died ({describe_exit(rc)}, pid {self.running[name].process.pid}); stopping the cell")
                        await self._let_engine_end()
                        code = EXIT_NODE_DIED
        finally:
            stopping.cancel()
            await self.stop_all()
        return code

    async def _let_engine_end(self) -> None:
        engine = self.running.get(ENGINE_NODE)
        if engine is None or engine.process.returncode is not None:
            return
        with contextlib.suppress(asyncio.TimeoutError):
            await self.clock.wait_for(engine.process.wait(), self.grace)
        if engine.process.returncode is not None:
            self.say(f"{ENGINE_NODE} ended its run ({describe_exit(engine.process.returncode)})")

    async def stop_all(self) -> None:
        """SIGTERM in reverse start order (engine first, bridge last), SIGKILL after the stop timeout."""
        for name in reversed(list(self.running)):
            process = self.running[name].process
            if process.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    process.terminate()
                try:
                    await self.clock.wait_for(process.wait(), self.stop_timeout)
                except asyncio.TimeoutError:
                    self.say(f"{name} did not stop within {self.stop_timeout:g} s: killed")
                    with contextlib.suppress(ProcessLookupError):
                        process.kill()
                    await process.wait()
                self.say(f"{name} stopped ({describe_exit(process.returncode)})")
        for running in self.running.values():
            await asyncio.gather(*running.pumps, return_exceptions=True)


async def launch(clock: Clock, specs: list[NodeSpec], out: IO[str], grace: float, stop_timeout: float) -> int:
    supervisor = Supervisor(clock, out, grace, stop_timeout)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(sig, stop.set)
            installed.append(sig)
    try:
        try:
            for spec in specs:
                await supervisor.start(spec)
        except OSError as error:
            supervisor.say(f"cannot start a node: {error}")
            await supervisor.stop_all()
            return EXIT_NODE_DIED
        return await supervisor.run(stop)
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)


def launch_settings(args: argparse.Namespace) -> LaunchSettings:
    """``launch``'s options."""
    return LaunchSettings(
        file=args.file, transport=args.transport, speed=args.speed, nodes=args.nodes, grace=args.grace, stop_timeout=args.stop_timeout,
        check=not args.no_check, backend=args.robot, options=tuple(args.backend_option or ()),
    )


def cmd_launch(settings: LaunchSettings, out: IO[str], err: IO[str]) -> int:
    path = Path(settings.file)
    if not path.is_file():
        err.write(f"error: {settings.file}: no such file\n")
        return EXIT_INVALID
    if not settings.speed > 0 or settings.grace < 0 or settings.stop_timeout <= 0:
        err.write("error: --speed and --stop-timeout must be > 0, --grace >= 0\n")
        return EXIT_USAGE
    try:
        specs = select(cell_nodes(path, settings.transport, settings.speed, settings.check, settings.backend, settings.options), settings.nodes)
    except ApplicationError as error:
        err.write(f"error: cannot launch {settings.file}:\n" + "\n".join(str(d) for d in error.diagnostics) + "\n")
        return EXIT_INVALID
    except (ValueError, KeyError, FileNotFoundError) as error:
        err.write(f"error: {error.args[0] if isinstance(error, KeyError) and error.args else error}\n")
        return EXIT_USAGE
    return int(run_with_clock(lambda clock: launch(clock, specs, out, settings.grace, settings.stop_timeout), real_clock()))


def main(argv: Sequence[str] | None = None) -> int:
    """For tests and scripts: the ``launch`` subcommand alone."""
    parser = argparse.ArgumentParser(prog="python -m execution_engine")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return cmd_launch(launch_settings(parser.parse_args(["launch", *(argv or [])])), sys.stdout, sys.stderr)
