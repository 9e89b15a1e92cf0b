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
``-v``.  The codes are :mod:`cell_runner.exits`'.

Each subcommand imports what it uses when it runs: ``run`` (:mod:`cell_runner.run_command`) and
``validate --simulate`` load the back ends, the simulators and the dry run (numpy, pinocchio, coal);
``validate``, ``functions`` and ``report`` start without them (test/test_fast_start.py).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, NoReturn

from app_functions.registry import full_catalog
from cell_runner import camera_sim_cli, launcher
from cell_runner.catalog_document import PARAM_TYPE_HELP, XML_USAGE, catalog_document
from cell_runner.exits import EXIT_INTERNAL, EXIT_INVALID, EXIT_OK, EXIT_STOPPED, EXIT_USAGE, explain
from cell_runner.run_checks import Refused, check_trajectory_db
from cell_runner.settings import BackendSettings, Outputs, ReportSettings, RunSettings, ValidateSettings
from cell_runner.vision_cli import add_vision_parser, run_vision
from core_functions.catalog import Catalog
from core_functions.option_ranges import START_HELD, RangeError, argument_type, bounds
from core_functions.robots import ROBOTS
from execution_engine.checkpoint.store import ANSWERS
from execution_engine.app_model import read_application
from node_transport.console_log import ConsoleLog



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
        read_at = time.time()  # a dry run's verdict is kept only for files unchanged since
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
            # slow to load: the dry run loads the simulators and the collision scene (numpy, pinocchio, coal)
            from cell_runner.dry_run.check import check as dry_run_check

            backend = settings.backend
            avoid = [*settings.files, *([settings.trajectory_db] if settings.trajectory_db else [])]
            code, report = dry_run_check(
                app, file, backend.backend_for(app), backend.backend_options(app), settings.trajectory_db, out, err, read_at=read_at, avoid=avoid,
            )
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
        for outcome in spec.outcomes:  # what an <if outcome=...> may test
            out.write(f"      outcome {outcome.name}: {outcome.doc}\n")
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


def parse_override(text: str) -> float:
    """A speed override a run may start at: in [0, 100] %, and above 0 (nothing would move)."""
    percent = argument_type("speed_override", label="speed override")(text)
    if percent == 0.0:
        raise argparse.ArgumentTypeError(f"speed override: {START_HELD}")
    return percent


def parse_option(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"back-end options are KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


# --------------------------------------------------------------------- report, recorder
def add_report_parser(sub: Any) -> None:
    """The ``report`` subcommand on the CLI's subparsers."""
    report = sub.add_parser("report", help="summarise a run from its recording (.mcap) or trace (.jsonl) and draw its timeline")
    report.add_argument("file", metavar="RUN.mcap|TRACE.jsonl")
    report.add_argument("--timeline", metavar="OUT.svg|OUT.png", help="where to write the timeline (default: next to FILE, .timeline.svg)")
    report.add_argument("--no-timeline", action="store_true", help="print the summary only")


def report_settings(args: argparse.Namespace) -> ReportSettings:
    """``report``'s options."""
    return ReportSettings(file=args.file, timeline=args.timeline, draw=not args.no_timeline)


def add_run_options(run: argparse.ArgumentParser) -> None:
    """``run``'s options of the flight recorder (cell_runner/record_hook.py): recording, checkpoint, resuming."""
    run.add_argument(
        "--record", metavar="RUN.mcap",
        help="record every topic of the run to an MCAP file that Foxglove, PlotJuggler and ros2 bag open "
             "(read it back with: python -m execution_engine report RUN.mcap)",
    )
    run.add_argument(
        "--checkpoint", metavar="PATH",
        help="SQLite file of the run's progress after every function result (default: next to --trace or --record, "
             "NAME.checkpoint.sqlite; none without them)",
    )
    run.add_argument("--resume", metavar="CHECKPOINT", help="go on with a run that crashed or was killed, from its checkpoint")
    run.add_argument(
        "--on-interrupted", choices=ANSWERS, default="ask",
        help="with --resume: what to do with a function the crash interrupted: ask the operator (default), redo it, or skip it",
    )


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
    validate.add_argument("--robot", choices=("nextage-sim", "vplus", "kuka-rsi", "ros2-control"), help="with --simulate: the back end whose simulator to use (default: the application robot's)")
    validate.add_argument("--backend-option", action="append", type=parse_option, metavar="KEY=VALUE", help="with --simulate: back-end option as for run, e.g. config=my_rsi.xml (repeatable)")
    validate.add_argument("--seed", type=argument_type("seed"), default=0, help="with --simulate: simulator random seed (vision noise) in [0, 4294967295], as for run")
    validate.add_argument("--trajectory-db", metavar="PATH", help="with --simulate: the trajectory database the run will use (read, never written)")
    functions = sub.add_parser("functions", help="list the function catalog")
    functions.add_argument("--json", action="store_true", help="machine-readable catalog")
    add_report_parser(sub)
    add_vision_parser(sub)
    run = sub.add_parser("run", help="run an application (default: on the Nextage kinematic simulator)")
    run.add_argument("file", metavar="FILE")
    run.add_argument("--speed-override", type=parse_override, default=100.0, metavar="P",
                     help="percent of the application's own speed every motion starts at, on its path, in (0, 100] (default 100; "
                          "changed while it runs with + - %% at the --interactive terminal or the engine's parameter speed_override)")
    run.add_argument("--speed", type=parse_speed, default=1.0, help="robot seconds per wall second, in [0.01, 1000]: 1 (the default) is real time, any other factor simulated time that counts only the computer's idle waits; or 'max': simulated time as fast as the computer goes")
    run.add_argument("--trace", metavar="PATH", help="write every event as a JSON line to PATH")
    run.add_argument("--robot", choices=("nextage-sim", "vplus", "kuka-rsi", "ros2-control"), help="back end (default: the application robot's)")
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
    camera_sim_cli.add_parser(sub)  # a mock robot's cameras
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
            explain(error, args.verbose, err)
            return EXIT_INTERNAL


# ------------------------------------------------------------------------------ settings
def backend_settings(args: argparse.Namespace, host: str | None, port: int | None) -> BackendSettings:
    """The back end of ``run``'s options (``studio`` takes them over; its controller's address is
    ``--controller-host``/``--controller-port``, given here as ``host`` and ``port``)."""
    return BackendSettings(
        name=args.robot, host=host, port=port, rsi_listen=args.rsi_listen, faults=tuple(args.fault or ()), seed=args.seed,
        options=tuple(args.backend_option or ()), speed_override=getattr(args, "speed_override", 100.0),
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
        from cell_runner.run_report import cmd_report  # slow to load: the recording's reader (mcap, its ROS 2 decoder)

        return cmd_report(report_settings(args), out, err)
    if args.command == "camera-sim":
        try:
            sim = camera_sim_cli.settings_of(args)
        except ValueError as error:
            err.write(f"error: camera-sim: {error}\n")
            return EXIT_USAGE
        from cell_runner.camera_sim import cmd_camera_sim  # slow to load: the renderer and the URDF model (numpy, OpenCV, pinocchio)

        return cmd_camera_sim(sim, out, err)
    if args.command == "vision":
        return run_vision(args, out, err)
    if Path(args.file).is_dir():
        err.write(f"error: {args.file}: is a directory, not an application file\n")
        return EXIT_INVALID
    if not Path(args.file).is_file():
        err.write(f"error: {args.file}: no such file\n")
        return EXIT_INVALID
    # slow to load: the run loads the back ends, the simulators and the dry run (numpy, pinocchio, coal)
    from cell_runner.run_command import cmd_run

    return cmd_run(args.file, run_settings(args), catalog, out, err)
