"""``python -m execution_engine``: validate applications, list the function catalog, run applications.

Exit codes (docs/faults.md lists every refusal with its message and code):

* 0 success (``run``: every group reached Finish cleanly);
* 1 invalid application, problems found by the dry run (``validate --simulate``, and ``run`` before
  it starts unless ``--no-check``) or a failed run (an alarm nobody can answer included);
* 2 bad command line or an option refused before anything runs (files, names, back-end setup);
* 3 run stopped by the operator (or abandoned with a second Ctrl-C);
* 4 the run (or report) finished but an output could not be written whole: the trace, the recording,
  the checkpoint, the timeline (a full disk, a file system gone read-only; the summary is still
  printed, and one line per output says what was lost);
* 5 the controller could not be reached or refused the run (connection refused, no answer, all
  client slots taken, an RSI peer that never spoke);
* 70 a defect of this program (one line; ``-v`` shows the traceback).

Every failure ends in one line naming the file, option or peer and what to do; a traceback only with
``-v``.
"""
from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, NoReturn

from app_functions.registry import full_catalog
from cell_runner import launcher
from cell_runner.catalog_document import PARAM_TYPE_HELP, XML_USAGE, catalog_document
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.check import check as dry_run_check, options_refusal
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.start import StartRefused, start_checked
from cell_runner.operator_console import OperatorConsole
from cell_runner.output_files import WriteFailure
from cell_runner.record_hook import add_run_options, prepare_flight, start_recording, stop_recording
from cell_runner.run_checks import Refused, check_trajectory_db, preflight
from cell_runner.run_report import add_report_parser, cmd_report, report_settings
from cell_runner.settings import BackendSettings, Outputs, RunSettings, ValidateSettings
from cell_runner.vision_cli import add_vision_parser, run_vision
from core_functions.catalog import Catalog
from core_functions.option_ranges import RangeError, argument_type, bounds
from core_functions.robots import ROBOTS
from execution_engine.app_model import Application, ApplicationError, load_application, read_application
from execution_engine.checkpoint.store import CheckpointError
from execution_engine.engine.report import RunReport
from execution_engine.observers import LivePrinter, QuestionPrinter, RunObserver, TraceWriter
from node_transport.clock import Clock, run_with_clock
from node_transport.console_log import ConsoleLog
from robot_bridges.backend import BridgeError
from robot_bridges.registry import create_backend

EXIT_OK, EXIT_INVALID, EXIT_USAGE, EXIT_STOPPED, EXIT_OUTPUT, EXIT_PEER, EXIT_INTERNAL = 0, 1, 2, 3, 4, 5, 70


@dataclass(frozen=True)
class ExtraCommand:
    """A subcommand a package above this one adds to the program (the operator station's ``studio``).

    The command line cannot import what sits above it; the program's entry
    (``execution_engine/__main__.py``) hands such commands in instead.  ``add_parser`` adds the
    subcommand to argparse's subparsers; ``run`` takes its parsed arguments, the catalog and the
    output streams and returns the exit code."""

    name: str
    add_parser: Callable[[Any], None]
    run: Callable[[argparse.Namespace, Catalog, IO[str], IO[str]], int]

# ------------------------------------------------------------------------------ validate
def cmd_validate(settings: ValidateSettings, catalog: Catalog, out: IO[str], err: IO[str]) -> int:
    """Check each file; with ``--simulate`` also dry-run each valid one."""
    if settings.simulate and settings.trajectory_db:
        try:  # the database the run will use: refused here as run refuses it
            check_trajectory_db(settings.trajectory_db, [Path(f) for f in settings.files])
        except Refused as refusal:
            err.write(f"error: {refusal}\n")
            return EXIT_USAGE
    status = EXIT_OK
    for file in settings.files:
        app, diagnostics = read_application(file, catalog)
        errors = [d for d in diagnostics if getattr(d, "severity", "error") == "error"]
        for diagnostic in diagnostics:
            err.write(f"{diagnostic}\n")
        if errors:
            status = EXIT_INVALID
            err.write(f"{file}: {len(errors)} error(s)\n")
            continue
        out.write(f"{file}: valid\n")
        if settings.simulate and app is not None:
            backend = settings.backend
            code, report = dry_run_check(app, file, backend.backend_for(app), backend.backend_options(app), settings.trajectory_db, out, err)
            if report is not None and report.findings:
                err.write(f"{file}: {len(report.findings)} problem(s) found by the dry run\n")
            status = max(status, code)
    return status


# ----------------------------------------------------------------------------- functions
def cmd_functions(catalog: Catalog, as_json: bool, out: IO[str]) -> int:
    if as_json:
        json.dump(catalog_document(catalog), out, indent=2)
        out.write("\n")
        return EXIT_OK
    out.write(XML_USAGE + "\n\nRobots (joint limits and poses in degrees):\n")
    for robot in ROBOTS:
        out.write(f"  {robot.name} (also: {', '.join(robot.aliases)}): {robot.description}\n")
        out.write(f"    {robot.workspace}\n")
        for g in robot.groups:
            limits = ", ".join(f"{j.name} [{math.degrees(j.lower):g}, {math.degrees(j.upper):g}]" for j in g.joints)
            out.write(f"    {g.name} ({g.kind}; camera {g.camera}): {limits}\n")
        for name, pose in sorted(robot.poses.items()):
            out.write(f"    pose {name}: {' '.join(f'{math.degrees(pose[j]):g}' for j in robot.joint_names)}  ({', '.join(robot.joint_names)})\n")
        out.write(f"    cameras: {', '.join(robot.cameras)}\n")
    out.write("\nFunctions:\n")
    for spec in (catalog.functions[n] for n in catalog.names()):
        out.write(f"\n  {spec.signature()}    [{spec.library}; groups: {', '.join(spec.group_kinds)}]\n")
        for line in spec.doc.splitlines():
            out.write(f"      {line}\n")
        for p in spec.params:
            extras = [p.type.value]
            if p.unit:
                extras.append(f"unit {p.unit}")
            if p.choices:
                extras.append("one of " + "|".join(p.choices))
            if p.kinds:
                extras.append("whole-robot pose" if p.kinds == ("robot",) else "kind " + "|".join(p.kinds))
            if p.minimum is not None or p.maximum is not None:
                extras.append(f"range [{'' if p.minimum is None else f'{p.minimum:g}'}, {'' if p.maximum is None else f'{p.maximum:g}'}]")
            extras.append("required" if p.required else f"default {p.default}")
            out.write(f"      - {p.name}: {p.doc} ({'; '.join(extras)})\n")
        if spec.sync:
            out.write(f"      synchronised ({spec.sync}): give it to the partner groups in the same operation\n")
        if spec.requires is not None:
            out.write(f"      the hand must hold: {spec.requires.value}\n")
        if spec.leaves is not None:
            out.write(f"      afterwards the hand holds: {spec.leaves.value}\n")
    out.write("\nParameter types:\n")
    for t, text in PARAM_TYPE_HELP.items():
        out.write(f"  {t.value:<11} {text}\n")
    return EXIT_OK


# ----------------------------------------------------------------------------------- run
def parse_speed(text: str) -> float:
    """A speed factor in its range (core_functions.option_ranges), or ``max`` for simulated time (as fast as the computer goes)."""
    if text.lower() in ("max", "inf", "fastest"):
        return math.inf
    speed = bounds("speed")
    try:
        return speed.check("speed", text)
    except RangeError:
        raise argparse.ArgumentTypeError(f"speed must be a number in {speed.describe()} or 'max', got {text!r}") from None


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
    )
    observer = RunObserver(deployment.transport.create_node("run_observer"), app.robot.group_names)
    if writer is not None:  # before the console: whatever the console shows is in the trace already
        observer.sinks.append(writer.on_status)
        observer.engine_sinks.append(writer.on_engine)
        observer.event_sinks.append(writer.on_event)
    if not settings.quiet:
        printer = LivePrinter(out, (*app.robot.group_names, "engine"))
        observer.sinks.append(printer.on_status)
        observer.engine_sinks.append(printer.on_engine)
        observer.event_sinks.append(printer.on_event)
    elif operators:  # quiet hides progress, never a question the run waits on
        observer.engine_sinks.append(QuestionPrinter(out).on_engine)
    recorder = await start_recording(settings, app, deployment.transport, name, observer)  # checkpoints after the trace
    console = OperatorConsole(deployment.transport.create_node("operator_console"), out, deployment.engine.operator_command)
    loop = asyncio.get_running_loop()
    interactive = console.attach_stdin(loop) if operators else False
    setup = setup_for(name, options) if settings.check else None  # checked where the robot is
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
        code, checked = dry_run_check(app, file, name, options, settings.outputs.trajectory_db, out, err, summary=not settings.quiet)
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
    writer = TraceWriter(trace) if trace is not None else None
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
        err.write(f"error: cannot run {file}: {error}; {PEER_ADVICE}\n")
        _explain(error, settings.verbose, err)
    except StartRefused as refusal:  # the dry run from where the robot is found problems: nothing moved
        code, outcome = EXIT_INVALID, "refused"
        err.write("".join(f"{line}\n" for line in refusal.lines) + f"{file}: not run: {refusal.reason}; use --no-check to run anyway\n")
    except (KeyError, ValueError, OSError, ConnectionError) as error:
        code = EXIT_USAGE
        err.write(f"error: cannot run {file}: {error}\n")
        _explain(error, settings.verbose, err)
    except asyncio.CancelledError:
        code, outcome = EXIT_STOPPED, "abandoned"
        err.write("run abandoned\n")
    except Exception as error:  # noqa: BLE001 - a defect: one line, the trace still closed, the traceback with -v
        code = EXIT_INTERNAL
        err.write(f"error: the run of {file} failed: {type(error).__name__}: {error} (a defect of this program: please report it; -v shows the traceback)\n")
        _explain(error, settings.verbose, err)
    if report is not None:
        out.write("\n" + "\n".join(report.summary_lines()) + "\n")
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


#: What an operator can do about a controller that would not take the run (exit 5).
PEER_ADVICE = (
    "check that the controller is on, reachable from this machine and serving on that address and port "
    "(--host/--port, --rsi-listen) and that no other client holds it, then run again"
)


def _explain(error: BaseException, verbose: bool, err: IO[str]) -> None:
    """The traceback, for a developer, only with ``-v``."""
    if verbose:
        traceback.print_exception(error, file=err)


def parse_option(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"back-end options are KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


# ---------------------------------------------------------------------------------- main
class OneLineParser(argparse.ArgumentParser):
    """A bad command line is one line (exit 2): what is wrong, and where the usage is."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(extra: Sequence[ExtraCommand] = ()) -> argparse.ArgumentParser:
    parser = OneLineParser(prog="python -m execution_engine", description="Skill-based robot applications in XML.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True)
    validate = sub.add_parser("validate", help="check application files; FILE:LINE:COL messages on problems")
    validate.add_argument("files", nargs="+", metavar="FILE")
    validate.add_argument("--simulate", action="store_true", help="also dry-run each valid file on the robot's simulator: every unreachable target, joint limit, missing trajectory and unsupported action at its line, and the predicted cycle time")
    validate.add_argument("--robot", choices=("nextage-sim", "vplus", "kuka-rsi"), help="with --simulate: the back end whose simulator to use (default: the application robot's)")
    validate.add_argument("--backend-option", action="append", type=parse_option, metavar="KEY=VALUE", help="with --simulate: back-end option as for run, e.g. config=my_rsi.xml (repeatable)")
    validate.add_argument("--seed", type=argument_type("seed"), default=0, help="with --simulate: simulator random seed (vision noise) in [0, 4294967295], as for run")
    validate.add_argument("--trajectory-db", metavar="PATH", help="with --simulate: the trajectory database the run will use (read, never written)")
    functions = sub.add_parser("functions", help="list the function catalog")
    functions.add_argument("--json", action="store_true", help="machine-readable catalog")
    add_report_parser(sub)
    add_vision_parser(sub)
    run = sub.add_parser("run", help="run an application (default: on the Nextage kinematic simulator)")
    run.add_argument("file", metavar="FILE")
    run.add_argument("--speed", type=parse_speed, default=1.0, help="robot seconds per wall second, in [0.01, 1000]: 1 (the default) is real time, any other factor simulated time that counts only the computer's idle waits; or 'max': simulated time as fast as the computer goes")
    run.add_argument("--trace", metavar="PATH", help="write every event as a JSON line to PATH")
    run.add_argument("--robot", choices=("nextage-sim", "vplus", "kuka-rsi"), help="back end (default: the application robot's)")
    run.add_argument("--host", help="controller address (V+); none starts the simulator")
    run.add_argument("--port", type=argument_type("port"), help="controller port (V+ default 1234), in [0, 65535]")
    run.add_argument("--rsi-listen", metavar="HOST:PORT", help="KUKA RSI: serve a real controller on this address")
    run.add_argument("--fault", action="append", metavar="GROUP:KIND@FRACTION", help="simulator fault injection, e.g. right_arm:joint_limit@0.5 (repeatable)")
    run.add_argument("--seed", type=argument_type("seed"), default=0, help="simulator random seed (vision noise) in [0, 4294967295]")
    run.add_argument("--backend-option", action="append", type=parse_option, metavar="KEY=VALUE", help="back-end specific option, e.g. timeout=20 (repeatable; each back end lists and checks its own)")
    run.add_argument("--trajectory-db", metavar="PATH", help="SQLite file for recorded trajectories")
    run.add_argument("--interactive", action="store_true", help="operator keys at the terminal, each acting when pressed (no Enter): p pause, r resume, s stop, t step, x reset, k skip, h help")
    run.add_argument("-q", "--quiet", action="store_true", help="print only the summary")
    run.add_argument("--no-check", action="store_true", help="start without the dry run on the simulator (validate --simulate) that otherwise comes first")
    add_run_options(run)
    for command in extra:
        command.add_parser(sub)
    launcher.add_parser(sub)  # one process per node, over DDS or rclpy
    return parser


def main(
    argv: Sequence[str] | None = None, out: IO[str] = sys.stdout, err: IO[str] = sys.stderr, extra: Sequence[ExtraCommand] = (),
) -> int:
    parser = build_parser(extra)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):  # --help, usage and errors to the caller's streams
            args = parser.parse_args(argv)
    except SystemExit as exit_:
        return EXIT_USAGE if exit_.code else EXIT_OK
    with ConsoleLog(err, args.verbose):  # every command's log: a warning that repeats is one counted line a second
        try:
            return dispatch(args, out, err, extra)
        except KeyboardInterrupt:
            err.write("interrupted\n")
            return EXIT_STOPPED
        except Exception as error:  # noqa: BLE001 - a defect: one line for the operator, the traceback with -v
            err.write(f"error: {args.command} failed: {type(error).__name__}: {error} (a defect of this program: please report it; -v shows the traceback)\n")
            _explain(error, args.verbose, err)
            return EXIT_INTERNAL


# ------------------------------------------------------------------------------ settings
def backend_settings(args: argparse.Namespace, host: str | None, port: int | None) -> BackendSettings:
    """The back end of ``run``'s options (``studio`` takes them over; its controller's address is
    ``--controller-host``/``--controller-port``, given here as ``host`` and ``port``)."""
    return BackendSettings(
        name=args.robot, host=host, port=port, rsi_listen=args.rsi_listen, faults=tuple(args.fault or ()), seed=args.seed,
        options=tuple(args.backend_option or ()),
    )


def run_settings(args: argparse.Namespace) -> RunSettings:
    """``run``'s options as the run takes them."""
    return RunSettings(
        backend=backend_settings(args, args.host, args.port),
        speed=args.speed,
        outputs=Outputs(trace=args.trace, record=args.record, checkpoint=args.checkpoint, trajectory_db=args.trajectory_db),
        check=not args.no_check,
        resume=args.resume,
        on_interrupted=args.on_interrupted,
        interactive=args.interactive,
        quiet=args.quiet,
        verbose=args.verbose,
    )


def validate_settings(args: argparse.Namespace) -> ValidateSettings:
    """``validate``'s options: the files; with ``--simulate``, the back end whose simulator dry-runs them."""
    backend = BackendSettings(name=args.robot, seed=args.seed, options=tuple(args.backend_option or ()))
    return ValidateSettings(files=tuple(args.files), simulate=args.simulate, backend=backend, trajectory_db=args.trajectory_db)


def dispatch(args: argparse.Namespace, out: IO[str], err: IO[str], extra: Sequence[ExtraCommand] = ()) -> int:
    """Run the chosen subcommand on the settings its arguments make."""
    catalog = full_catalog()
    if args.command == "validate":
        return cmd_validate(validate_settings(args), catalog, out, err)
    if args.command == "functions":
        return cmd_functions(catalog, args.json, out)
    if args.command == "launch":
        return launcher.cmd_launch(launcher.launch_settings(args), out, err)
    for command in extra:
        if args.command == command.name:
            return command.run(args, catalog, out, err)
    if args.command == "report":
        return cmd_report(report_settings(args), out, err)
    if args.command == "vision":
        return run_vision(args, out, err)
    if Path(args.file).is_dir():
        err.write(f"error: {args.file}: is a directory, not an application file\n")
        return EXIT_INVALID
    if not Path(args.file).is_file():
        err.write(f"error: {args.file}: no such file\n")
        return EXIT_INVALID
    return cmd_run(args.file, run_settings(args), catalog, out, err)
