"""``run``: the checks before a run, the run on the deployment, its summary and outputs.

The command line (:mod:`cell_runner.cli`) imports this module only when ``run`` is given: it loads
the back ends, the simulators and the dry run (numpy, pinocchio, coal), which ``validate``,
``functions`` and ``report`` do not need.
"""
from __future__ import annotations

import asyncio
import signal
import sys
import time
from typing import IO

from cell_runner.console_edit import console_editor
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.check import check as dry_run_check, options_refusal
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.start import StartRefused, start_checked
from cell_runner.exits import EXIT_INTERNAL, EXIT_INVALID, EXIT_OK, EXIT_OUTPUT, EXIT_PEER, EXIT_STOPPED, EXIT_USAGE, explain
from cell_runner.operator_console import OperatorConsole
from cell_runner.output_files import WriteFailure
from cell_runner.record_hook import prepare_flight, start_recording, stop_recording
from cell_runner.run_checks import Refused, app_inputs, preflight
from cell_runner.settings import RunSettings
from core_functions.catalog import Catalog
from execution_engine.app_model import Application, ApplicationError, load_application
from execution_engine.checkpoint.store import CheckpointError
from execution_engine.engine.report import RunReport
from execution_engine.observers import LivePrinter, QuestionPrinter, RunObserver, TraceWriter
from node_transport.clock import Clock, run_with_clock
from robot_bridges.backend import BridgeError
from robot_bridges.registry import create_backend

#: What an operator can do about a controller that would not take the run (exit 5).
PEER_ADVICE = (
    "check that the controller is on, reachable from this machine and serving on that address and port "
    "(--host/--port, --rsi-listen) and that no other client holds it, then run again"
)
#: The same for a robot reached through the ROS graph (the ros2-control back end).
GRAPH_ADVICE = (
    "check that the robot's driver runs in this ROS_DOMAIN_ID (ros2 control list_controllers, ros2 action list -t) "
    "and that the back-end options name its controllers, then run again"
)


async def _run(
    app: Application, settings: RunSettings, clock: Clock, out: IO[str], writer: TraceWriter | None, lost: list[WriteFailure] | None = None,
    checked: DryRunReport | None = None,
) -> RunReport:
    """The run; ``lost`` gets the outputs (recording, checkpoint) that could not be written whole;
    ``checked``: the dry run's verdict from the simulator's start (checked again if the robot is elsewhere)."""
    name, options = settings.backend.backend_for(app), settings.backend.backend_options(app)
    backend = await create_backend(name, clock, options)
    trajectory_db = settings.outputs.trajectory_db
    machine_parameters = {"trajectory_db": trajectory_db} if trajectory_db else {}
    # An alarm waits only when someone can answer it: in this process, an operator at a terminal
    # (--interactive); nobody else reaches the in-process engine.  While that person is waited
    # for, simulated time stands still instead of racing on.
    operators = settings.interactive and sys.stdin.isatty()
    if settings.interactive and not operators:
        out.write("warning: --interactive: standard input is not a terminal, so there are no operator keys; an alarm ends the run at once\n")
    deployment = await deploy_local(
        clock, app.robot, backend, machine_parameters=machine_parameters, operators=operators, hold_for_operators=operators and clock.simulated,
        engine_parameters={"speed_override": settings.backend.speed_override},  # --speed-override: the engine's, changeable while it runs
    )
    observer = RunObserver(deployment.transport.create_node("run_observer"), app.robot.group_names)
    if writer is not None:  # before the console: whatever the console shows is in the trace already
        observer.sinks.append(writer.on_status)
        observer.engine_sinks.append(writer.on_engine)
        observer.event_sinks.append(writer.on_event)
        observer.plan_sinks.append(writer.on_plan)  # the plan the start check proved (none with --no-check)
    if not settings.quiet:
        printer = LivePrinter(out, (*app.robot.group_names, "engine"))
        observer.sinks.append(printer.on_status)
        observer.engine_sinks.append(printer.on_engine)
        observer.event_sinks.append(printer.on_event)
    elif operators:  # quiet hides progress, never a question the run waits on
        observer.engine_sinks.append(QuestionPrinter(out).on_engine)
    recorder = await start_recording(settings, app, deployment.transport, name, observer)  # checkpoints after the trace
    if recorder.writer is not None:  # an edit of the paused run: the checkpoint goes on with the new application
        deployment.engine.remainder.hooks.append(recorder.writer.swapped)
    if writer is not None:  # and the trace names the new operations' iterations
        deployment.engine.remainder.hooks.append(writer.swapped)
    if recorder.recorder is not None:  # and the recording holds the edited file
        deployment.engine.remainder.hooks.append(recorder.recorder.swapped)
    console = OperatorConsole(deployment.transport.create_node("operator_console"), out, deployment.engine.operator_command, deployment.engine.breakpoint_command,
                              deployment.engine.speed)
    loop = asyncio.get_running_loop()
    interactive = console.attach_stdin(loop) if operators else False
    setup = setup_for(name, options) if settings.check else None  # checked where the robot is
    console.editor = console_editor(deployment.engine, app, backend, clock, setup, trajectory_db)  # key e: edit the paused run
    run_task = loop.create_task(start_checked(deployment.engine, app, backend, clock, setup, trajectory_db, checked, recorder.resume, out))
    interrupts = 0

    def on_interrupt() -> None:
        nonlocal interrupts
        interrupts += 1
        if interrupts == 1:
            out.write("\ninterrupt: stopping the application (Ctrl-C again to abandon)\n")
            console.spawn(console.command("stop", "Ctrl-C"), loop)
        else:
            run_task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, on_interrupt)
        except (NotImplementedError, RuntimeError):
            pass
    try:
        return await run_task
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.remove_signal_handler(sig)
            except (NotImplementedError, RuntimeError):
                pass
        if interactive:
            console.detach_stdin(loop)  # the terminal as it was, also after Ctrl-C or an exception
        failures = await stop_recording(recorder, out)
        if lost is not None:
            lost.extend(failures)
        await deployment.close()


def cmd_run(file: str, settings: RunSettings, catalog: Catalog, out: IO[str], err: IO[str]) -> int:
    """Run the application ``file`` as ``settings`` say, each check first."""
    read_at = time.time()  # the dry run's verdict is kept only for files unchanged since
    try:
        app = load_application(file, catalog)
    except ApplicationError as error:
        for diagnostic in error.diagnostics:
            err.write(f"{diagnostic}\n")
        err.write(f"{file}: not run: {len(error.diagnostics)} problem(s)\n")
        return EXIT_INVALID
    try:
        settings = preflight(app, settings)  # files and peers, before anything runs and without writing a byte
    except Refused as refusal:
        err.write(f"error: {refusal}\n")
        return EXIT_USAGE
    try:
        settings = prepare_flight(app, settings)  # --resume, then every file read or written (output_files), before any is written
    except (CheckpointError, Refused) as refusal:
        err.write(f"error: {refusal}\n")
        return EXIT_USAGE
    name, options = settings.backend.backend_for(app), settings.backend.backend_options(app)
    refusal = options_refusal(file, name, options, settings.speed, dry_run_first=settings.check)
    if refusal is not None:  # every back-end option, before the dry run's seconds
        err.write(refusal + "\n")
        return EXIT_USAGE
    checked: DryRunReport | None = None  # the verdict from the simulator's start; _run checks again if the robot is elsewhere
    if settings.check:
        outputs = settings.outputs
        avoid = [path for _, path in app_inputs(app)] + [p for p in (outputs.trace, outputs.record, outputs.checkpoint, outputs.trajectory_db) if p]
        avoid += [v for k, v in settings.backend.extra.items() if k in ("config", "feedback")]  # a back end's files read or written
        code, checked = dry_run_check(
            app, file, name, options, outputs.trajectory_db, out, err, summary=not settings.quiet, read_at=read_at, avoid=avoid,
        )
        if code != EXIT_OK:
            found = f"{len(checked.findings)} problem(s) found by the dry run" if checked is not None else "the dry run did not pass"
            err.write(f"{file}: not run: {found}; use --no-check to run anyway\n")
            return code
    trace_path = settings.outputs.trace
    try:
        trace = open(trace_path, "w", encoding="utf-8") if trace_path else None
    except OSError as error:
        err.write(f"error: --trace {trace_path}: cannot be written ({error.strerror or error}); give a writable file\n")
        return EXIT_USAGE
    writer = TraceWriter(trace, app.iterations()) if trace is not None else None
    try:
        return _run_recorded(app, file, settings, out, err, writer, checked)
    finally:
        if trace is not None:
            try:
                trace.close()
            except OSError:  # already counted by the writer: its records were lost, not the run
                pass


def _run_recorded(
    app: Application, file: str, settings: RunSettings, out: IO[str], err: IO[str], writer: TraceWriter | None, checked: DryRunReport | None,
) -> int:
    """Run, print the summary, close the trace with its run_end record; the exit code."""
    report: RunReport | None = None
    outcome = "error"
    lost: list[WriteFailure] = []  # outputs that could not be written whole: exit 4 after a good run
    try:
        report = run_with_clock(lambda c: _run(app, settings, c, out, writer, lost, checked), settings.clock())
    except BridgeError as error:  # the controller refused or never answered, before the first primitive
        code = EXIT_PEER
        advice = GRAPH_ADVICE if settings.backend.backend_for(app) == "ros2-control" else PEER_ADVICE
        err.write(f"error: cannot run {file}: {error}; {advice}\n")
        explain(error, settings.verbose, err)
    except StartRefused as refusal:  # the dry run from where the robot is found problems: nothing moved
        code, outcome = EXIT_INVALID, "refused"
        err.write("".join(f"{line}\n" for line in refusal.lines) + f"{file}: not run: {refusal.reason}; use --no-check to run anyway\n")
    except (KeyError, ValueError, OSError, ConnectionError) as error:
        code = EXIT_USAGE
        err.write(f"error: cannot run {file}: {error}\n")
        explain(error, settings.verbose, err)
    except asyncio.CancelledError:
        code, outcome = EXIT_STOPPED, "abandoned"
        err.write("run abandoned\n")
    except Exception as error:  # noqa: BLE001 - a defect: one line, the trace still closed, the traceback with -v
        code = EXIT_INTERNAL
        err.write(f"error: the run of {file} failed: {type(error).__name__}: {error} (a defect of this program: please report it; -v shows the traceback)\n")
        explain(error, settings.verbose, err)
    if report is not None:
        out.write("\n" + "\n".join(report.summary_lines(app.iterations())) + "\n")
        outcome = report.outcome
        code = EXIT_OK if report.ok else EXIT_STOPPED if report.outcome == "stopped" else EXIT_INVALID
    code = EXIT_OUTPUT if lost and code == EXIT_OK else code
    if writer is not None:
        t = report.t_end if report is not None else writer.last_t
        done, total = (report.operations_done, report.operations_total) if report is not None else (0, len(app.operations))
        writer.finish(t, outcome, code, done, total)
        if writer.error is not None:
            lost.insert(0, WriteFailure("--trace", str(settings.outputs.trace), writer.error.strerror or str(writer.error),
                                        f"{writer.lost} record(s) lost, the trace is incomplete"))
    for failure in lost:
        err.write(failure.line(outcome) + "\n")
    return EXIT_OUTPUT if lost and code == EXIT_OK else code
