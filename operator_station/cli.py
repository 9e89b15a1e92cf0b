"""``python -m execution_engine studio [APP.xml] [--port 8080] [--host 127.0.0.1] [--robot ...] [--speed ...] [--replay RUN.mcap|TRACE.jsonl]``.

Serves the operator station (builder, monitor, timeline) with uvicorn.  It binds to loopback
unless ``--host`` names another address; then every page must present a token, made when the
station starts and printed in the address to open, or kept by the integrator in
``--token-file`` (which also asks for it on loopback).  The run's settings (``--robot``,
``--speed``, ``--trace``, back-end options) are those of ``run`` and apply to every run started
from the page.
"""
from __future__ import annotations

import argparse
import asyncio
import importlib.util
import logging
import math
import socket
import sys
from pathlib import Path
from typing import IO, Any

from cell_runner.output_files import FilePlan, Output, Refused
from cell_runner.run_checks import run_files
from cell_runner.settings import BackendSettings, Outputs, RunSettings
from core_functions.catalog import Catalog
from core_functions.option_ranges import RangeError, bounds
from core_functions.printable import printable
from core_functions.robots import find_robot
from execution_engine.app_model.document import read_document
from execution_engine.record_reader import NotARecording, OverLimit
from operator_station.access import Access, AccessError, is_loopback, is_wildcard, read_token_file
from operator_station.attach import AttachedSession, ros_connect
from operator_station.audit import DEFAULT_NAME, AuditError, AuditLog, check_audit_file
from operator_station.feed import Feed
from operator_station.replay import load_replay
from operator_station.session import RunSession
from operator_station.users import read_users_file

log = logging.getLogger(__name__)


def build_station(args: argparse.Namespace, catalog: Catalog, root: Path, access: Any = None) -> Any:
    """The station of these arguments (no server yet): what the tests serve with Starlette's TestClient.

    ``access`` (:class:`operator_station.access.Access`): who may use it; default loopback pages."""
    from operator_station.server import Station  # optional: starlette, pip extra 'studio'

    feed = Feed()
    app_path = (root / args.file).resolve() if args.file else None
    if args.replay:
        load_replay(feed, Path(args.replay))
        return Station(catalog, feed, None, root, app_path, replay=True, access=access)
    if getattr(args, "transport", "local") == "ros":
        return _attached(args, catalog, feed, root, app_path, access)
    return Station(catalog, feed, RunSession(feed, run_settings(args)), root, app_path, access=access)


def run_settings(args: argparse.Namespace) -> RunSettings:
    """Every run the station starts goes as ``run`` would with these options (its controller is
    ``--controller-host``/``--controller-port``: ``--host``/``--port`` are the station's own)."""
    return RunSettings(
        backend=BackendSettings(
            name=args.robot, host=args.controller_host, port=args.controller_port, rsi_listen=args.rsi_listen, faults=tuple(args.fault or ()),
            seed=args.seed, options=tuple(args.backend_option or ()),
        ),
        speed=args.speed,
        outputs=Outputs(trace=args.trace, trajectory_db=args.trajectory_db),
        check=not args.no_check,
    )


def studio_files(args: argparse.Namespace) -> FilePlan:
    """The files the station's runs write whatever the application (``--trace``, ``--trajectory-db``,
    a back end's feedback log) and read (the application given, a back end's config)."""
    inputs = [(f"the application {args.file}", args.file)] if args.file else []
    return run_files(inputs, trace=args.trace, trajectory_db=args.trajectory_db, extra=dict(args.backend_option or ()), command="studio")


def audit_output(args: argparse.Namespace) -> Output:
    """The audit file: ``--audit``, else ``studio.audit.jsonl`` beside ``--trace`` or in the folder the station starts in."""
    if getattr(args, "audit", None):
        return Output("--audit", str(args.audit), "the audit log", DEFAULT_NAME)
    folder = Path(args.trace).parent if getattr(args, "trace", None) else Path(".")
    where = "beside --trace" if getattr(args, "trace", None) else "in the station's folder"
    return Output("--audit", str(folder / DEFAULT_NAME), "the audit log", DEFAULT_NAME, default=where)


def read_access(args: argparse.Namespace) -> Access:
    """Who may use the station: its token (engineer), the operators' token, the users file (AccessError, one line)."""
    token = read_token_file(Path(args.token_file)) if getattr(args, "token_file", None) else None
    operator = read_token_file(Path(args.operator_token_file), "--operator-token-file") if getattr(args, "operator_token_file", None) else None
    users = read_users_file(Path(args.users)) if getattr(args, "users", None) else None
    return Access.for_address(args.host, token, tuple(getattr(args, "allowed_host", None) or ()), operator, users)


class StudioError(Exception):
    """A setting the station cannot work with: one line for the operator."""


def _attached(args: argparse.Namespace, catalog: Catalog, feed: Any, root: Path, app_path: Path | None, access: Any) -> Any:
    """A station watching a cell on the ROS graph: the application names the robot (its groups)."""
    from operator_station.server import Station  # optional: starlette, pip extra 'studio'

    if app_path is None:
        raise StudioError("--transport ros needs the application the cell runs (APP.xml): it names the robot and its groups")
    if importlib.util.find_spec("rclpy") is None:
        raise StudioError("--transport ros needs rclpy: source a ROS 2 installation first (docs/ros2.md)")
    document, problems = read_document(app_path)
    if document is None:
        raise StudioError(str(problems[0]) if problems else f"{app_path}: cannot be read")
    try:
        robot = find_robot(document.robot)
    except KeyError as error:
        raise StudioError(f"{app_path}: {error.args[0]}") from None
    session = AttachedSession(feed, robot, document.name, ros_connect(["operator_station"]))
    session.attach()
    return Station(catalog, feed, session, root, app_path, access=access)


def cmd_studio(args: argparse.Namespace, catalog: Catalog, out: IO[str] = sys.stdout, err: IO[str] = sys.stderr) -> int:
    try:  # optional: pip extra 'studio' (the web server), refused in one line when missing
        import starlette  # noqa: F401 - optional: the station's routes
        import uvicorn  # noqa: F401 - optional: the server
        import websockets  # noqa: F401 - optional: uvicorn's WebSocket protocol: without it the live feed is refused
    except ImportError as missing:
        err.write(f"error: studio needs the web server: pip install 'dual_arm_executive[studio]' (starlette, uvicorn, websockets; missing {missing.name})\n")
        return 2
    if args.file and not Path(args.file).is_file():
        err.write(f"error: {args.file}: no such file\n")
        return 1
    if args.replay and not Path(args.replay).is_file():
        err.write(f"error: {args.replay}: no such trace file\n")
        return 1
    audit_file = audit_output(args)
    try:  # every run's files, by run's rule (the page's application is checked again at each start), and the audit's
        plan = studio_files(args) if not args.replay else FilePlan("studio").read(f"the replay {args.replay}", args.replay)
        plan.write(audit_file).check()
    except Refused as refusal:
        err.write(f"error: {refusal}\n")
        return 2
    if not is_loopback(args.host):
        err.write(f"warning: serving on {args.host}: reachable from the network; every page and script must present the token\n")
    try:  # after the warning: whoever asked for the network learns it even from a typo in the port
        bounds("port").check("--port", args.port)
    except RangeError as error:
        err.write(f"error: {error}\n")
        return 2

    try:
        access = read_access(args)
        check_audit_file(Path(audit_file.path), f"--audit {audit_file.path}")  # appended to only if it is one
    except (AccessError, AuditError) as error:
        err.write(f"error: {error}\n")
        return 2
    try:
        station = build_station(args, catalog, Path.cwd(), access)
    except StudioError as error:
        err.write(f"error: {error}\n")
        return 2
    except (NotARecording, OverLimit) as error:  # --replay: refused as report refuses it, in one line naming the file
        err.write(f"error: {printable(error)}\n")
        return 1
    except OSError as error:
        err.write(f"error: {error}\n")
        return 1
    try:  # last: a refused start leaves no file behind
        station.audit_log = AuditLog.open(Path(audit_file.path), f"--audit {audit_file.path}", station.wall)  # every action, appended
    except AuditError as error:
        err.write(f"error: {error}\n")
        return 2
    from operator_station.server import create_app  # optional: starlette, pip extra 'studio'
    from operator_station.serving import StationServer, server_config  # optional: uvicorn, pip extra 'studio'

    server = StationServer(server_config(create_app(station), args.host, args.port), station)
    speed = "max" if math.isinf(args.speed) else f"x{args.speed:g}"
    what = f"replaying {args.replay}" if args.replay else f"runs at {speed}"
    out.write(f"operator station on {_url(args.host, args.port)} ({what}); Ctrl-C ends it\n")
    if access.token_needed:
        page = _url(socket.gethostname() if is_wildcard(args.host) else args.host, args.port)
        if access.users:
            out.write(f"open {page} and log in ({len(access.users)} user(s) of {args.users}); scripts send a token\n")
        elif not getattr(args, "token_file", None):
            out.write(f"open {page}?token={access.token} (a token made for this start, the engineer's; keep one with --token-file)\n")
        else:
            out.write(f"open {page}?token=TOKEN with the token of {args.token_file} (engineer)\n")
        if getattr(args, "operator_token_file", None):
            out.write(f"operators open {page}?token=TOKEN with the token of {args.operator_token_file}\n")
        out.write(f"pages may reach it as: {access.shown_hosts()} (others with --allowed-host NAME)\n")
    out.write(f"audit log: {audit_file.path} (appended)\n")
    out.flush()
    try:
        asyncio.run(_serve(server, station))
    except (OSError, SystemExit) as error:  # uvicorn exits when it cannot bind
        why = error.strerror if isinstance(error, OSError) else "the address is in use or not this machine's"
        err.write(f"error: cannot serve on {args.host}:{args.port}: {why}\n")
        return 2
    except KeyboardInterrupt:
        pass
    return 0


def _url(host: str, port: int) -> str:
    return f"http://{host if ':' not in host else f'[{host}]'}:{port}/"


async def _serve(server: Any, station: Any) -> None:
    """Serve until a signal or an error; the server's shutdown stops the run first (operator_station.serving)."""
    from operator_station.serving import STOP_BOUND, stop_station  # optional: uvicorn, pip extra 'studio'

    try:
        await server.serve()
    finally:
        if not station.stopped:  # ended without the server's shutdown (it could not bind): nothing may be left running
            await stop_station(station, server.clock, STOP_BOUND)
