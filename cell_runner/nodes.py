"""``ros2 run`` entry points of the engine and of a group machine (see setup.py console_scripts).

::

    ros2 run dual_arm_executive execution_engine --ros-args -p application:=/path/app.xml
    ros2 run dual_arm_executive group_machine --ros-args -r __node:=left_arm_machine -p group:=left_arm

Both are thin: the objects are the same :class:`ExecutionEngine` and :class:`GroupMachine` the
embedded deployment builds, on a :class:`~node_transport.ros.RosTransport` node
instead of a local one; process start-up and shutdown are :mod:`cell_runner.ros_main`'s.
"""
from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from cell_runner.dry_run.cell_start import CellStarts
from cell_runner.dry_run.start import StartRefused
from cell_runner.engine_check import options_from_text
from cell_runner.libraries import APPLICATION_FUNCTIONS
from cell_runner.output_files import Refused
from cell_runner.record_hook import record_node, stop_recording
from cell_runner.ros_main import (
    ExitCode,
    Outcome,
    StartupError,
    run_node,
    serve_forever,
    startup_errors,
    warn_undeclared,
)
from execution_engine.app_model import Application, ApplicationError, load_application
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.report import RunReport
from execution_engine.engine.run_action import RunApplicationServer
from execution_engine.machine.group_machine import GroupMachine, default_trajectory_db
from node_transport.port import Node, TransportError
from node_transport.wire import ENGINE_NODE, machine_node_name


@dataclass(frozen=True)
class EngineSettings:
    """What the engine process needs besides the engine's own parameters."""

    application: str
    exit_when_done: bool
    record: str = ""
    wait_for_goals: bool = False
    check: bool = True
    trajectory_db: str = ""
    check_backend: str = ""  # the back end the check dry-runs on ('' = the robot model's default)
    check_options: str = ""  # its options, KEY=VALUE;KEY=VALUE (cell_runner.engine_check)


def declare_engine_parameters(node: Node) -> EngineSettings:
    """The engine process's own parameters (the engine object declares the rest)."""
    application = str(node.declare_parameter("application", "", "application XML file to run (required)"))
    exit_when_done = bool(
        node.declare_parameter("exit_when_done", False, "exit after the run (code 0 if it finished cleanly) instead of serving on")
    )
    record = str(node.declare_parameter(
        "record", "", "MCAP file to record every topic of the graph to while the application runs, as ros2 bag record -s mcap stores it (empty: no recording)"
    ))
    wait_for_goals = bool(
        node.declare_parameter("wait_for_goals", False, "with no application: serve RunApplication goals on execution_engine/run_application")
    )
    check = bool(node.declare_parameter(
        "check", True,
        "dry-run every run (the application, each RunApplication goal) from the robot's joints on joint_states first, and refuse "
        "it with the findings when it would collide or fail; a robot away from the start is brought back first (false: run unchecked)",
    ))
    trajectory_db = str(node.declare_parameter(
        "trajectory_db", "", "the machines' trajectory database, which the dry run reads (never writes); empty: the machines' default"
    ))
    check_backend = str(node.declare_parameter(
        "check_backend", "",
        "the back end whose model that dry run uses, as run --robot names it (launch sets the bridge's); '' = the robot model's default back end",
    ))
    check_options = str(node.declare_parameter(
        "check_options", "",
        "that back end's options for the dry run, KEY=VALUE;KEY=VALUE as run's --backend-option (launch sets the bridge's); '' = none",
    ))
    return EngineSettings(application, exit_when_done, record, wait_for_goals, check, trajectory_db, check_backend, check_options)


def engine_starts(node: Node, engine: ExecutionEngine, settings: EngineSettings) -> CellStarts | None:
    """The engine's start check on the back end and options it is given (None: ``check`` is off); ValueError
    naming ``check_options`` when it is not KEY=VALUE;KEY=VALUE."""
    if not settings.check:
        return None
    options = options_from_text(settings.check_options)
    return CellStarts(node, engine, settings.trajectory_db or default_trajectory_db(), engine.startup_timeout, settings.check_backend, options)


def load_or_explain(path: str) -> Application:
    """The validated application; StartupError listing every diagnostic when it has errors."""
    if not path:
        raise StartupError("parameter 'application' is required: --ros-args -p application:=/path/app.xml")
    try:
        return load_application(Path(path), APPLICATION_FUNCTIONS.catalog(None))
    except ApplicationError as error:
        errors = sum(1 for d in error.diagnostics if d.is_error)
        lines = [f"cannot run {path}: {errors} error(s)", *(str(d) for d in error.diagnostics)]
        raise StartupError("\n".join(lines), ExitCode.FAILED) from None


def serve_goals(node: Node, engine: ExecutionEngine, starts: CellStarts | None = None) -> RunApplicationServer | None:
    """The RunApplication action server, or None where the transport cannot carry its types (rclpy
    without the built dual_arm_executive_interfaces package): the engine runs on without it.
    ``starts``: each goal is checked from the robot's measured joints first (None: unchecked)."""
    try:
        return RunApplicationServer(node, engine, starts.run_goal if starts is not None else None)
    except TransportError as error:
        node.logger.info(
            "%s: the RunApplication action is not served (under rclpy it needs the built interface package: "
            "colcon build --base-paths <repo> <repo>/interfaces; the operator services start/pause/resume/stop run the application): %s",
            node.fully_qualified_name, error,
        )
        return None


async def run_engine(node: Node, outcome: Outcome) -> None:
    """Load the application, run it, print the report, then keep the operator services and the
    RunApplication action up (or, with ``wait_for_goals`` and no application, only serve goals)."""
    with startup_errors():
        settings = declare_engine_parameters(node)
        engine = ExecutionEngine(node, APPLICATION_FUNCTIONS.catalog(None))
        starts = engine_starts(node, engine, settings)
    goals = serve_goals(node, engine, starts)
    warn_undeclared(node)
    if not settings.application and settings.wait_for_goals:
        if goals is None:
            raise StartupError("wait_for_goals: the RunApplication action is not available on this transport")
        node.logger.info("%s: waiting for RunApplication goals on %s", node.fully_qualified_name, goals.server.name)
        await serve_forever()
    app = load_or_explain(settings.application)
    node.logger.info("%s: running %s (%d operations)", node.fully_qualified_name, app.name, len(app.operations))
    outcome.code = ExitCode.FAILED  # until the report says otherwise
    try:  # the recording is never the application or its cell (output_files)
        recorder = record_node(node, settings.record, app, option="parameter record")
    except Refused as refusal:
        raise StartupError(str(refusal)) from None
    groups = app.robot.group_names
    if recorder is not None and not await recorder.ready(groups, engine.startup_timeout):
        node.logger.warning("%s: the recording may miss the run's first messages: not every machine's topics were matched within %g s",
                            node.fully_qualified_name, engine.startup_timeout)
    try:
        report = await _run_checked(engine, app, starts)
    except StartRefused as refusal:
        print("\n".join([*refusal.lines, f"{app.path}: not run: {refusal.reason}; to run it anyway: -p check:=false (launch --no-check)"]),
              file=sys.stderr, flush=True)
        report = None
    finally:
        if recorder is not None:
            await recorder.settle(groups, engine.service_timeout)
        lost = await stop_recording(recorder, sys.stdout)
    if report is not None:
        print("\n".join(report.summary_lines()), flush=True)
        outcome.code = ExitCode.OK if report.ok and not lost else ExitCode.FAILED  # a recording that failed is no success
    if not settings.exit_when_done:
        await serve_forever()


async def _run_checked(engine: ExecutionEngine, app: Application, starts: CellStarts | None) -> RunReport:
    """The application's run, checked from where the robot is unless ``check`` is off."""
    if starts is None:
        return await engine.run(app)
    return await starts.run(app, lambda line: print(line, flush=True))


async def run_group_machine(node: Node, outcome: Outcome) -> None:
    """One group's state machine, serving until stopped."""
    with startup_errors():
        machine = GroupMachine(node, APPLICATION_FUNCTIONS)
    warn_undeclared(node)
    if node.name != machine_node_name(machine.group):
        node.logger.warning(
            "%s drives %s; name it %s (-r __node:=%s) as the launch files do",
            node.fully_qualified_name, machine.group, machine_node_name(machine.group), machine_node_name(machine.group),
        )
    try:
        await machine.run()
    finally:
        machine.close()


def engine_main(argv: Sequence[str] | None = None) -> int:
    """``execution_engine`` executable."""
    return run_node(ENGINE_NODE, run_engine, sys.argv if argv is None else argv)


def group_machine_main(argv: Sequence[str] | None = None) -> int:
    """``group_machine`` executable; launch files rename it ``<group>_machine``."""
    return run_node("group_machine", run_group_machine, sys.argv if argv is None else argv)
