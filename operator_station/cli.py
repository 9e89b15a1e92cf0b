"""``python -m execution_engine studio [APP.xml] [--port 8080] [--host 127.0.0.1] [--robot ...] [--speed ...] [--replay TRACE.jsonl]``.

Serves the operator station (builder, monitor, timeline) with uvicorn.  It binds to loopback
unless ``--host`` names another address, and then says so: the station starts and stops robots,
and it has no login.  The run's settings (``--robot``, ``--speed``, ``--trace``, back-end
options) are those of ``run`` and apply to every run started from the page.
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import math
import sys
from pathlib import Path
from typing import IO, Any

from core_functions.catalog import Catalog

log = logging.getLogger(__name__)

LOOPBACK = ("127.0.0.1", "localhost", "::1")


#: Options ``studio`` takes over from ``run`` (same meaning, same parsing: the two cannot drift apart).
RUN_OPTIONS = ("robot", "speed", "trace", "rsi_listen", "fault", "seed", "backend_option", "trajectory_db", "no_check")


def add_parser(sub: Any) -> None:
    """Register ``studio`` on the CLI's subcommands, after ``run`` (whose run options it shares)."""
    studio = sub.add_parser("studio", help="the operator station in the browser: build, validate, run, watch and replay applications")
    studio.add_argument("file", nargs="?", metavar="APP.xml", help="the application to open in the builder")
    studio.add_argument("--port", type=int, default=8080, help="HTTP port of the station (default 8080)")
    studio.add_argument("--host", default="127.0.0.1", help="address to serve on (default loopback; anything else is reachable from the network)")
    studio.add_argument("--replay", metavar="TRACE.jsonl", help="show a finished run's trace instead of running anything")
    studio.add_argument("--transport", choices=("local", "ros"), default="local",
                        help="local: run the application in this process (default); ros: watch and command a cell running on the ROS graph (needs APP.xml for its groups, and rclpy)")
    studio.add_argument("--controller-host", dest="controller_host", help="V+ controller address (none starts the simulator); run's --host")
    studio.add_argument("--controller-port", dest="controller_port", type=int, help="V+ controller port; run's --port")
    for action in sub.choices["run"]._actions:  # noqa: SLF001 - argparse has no public way to share options
        if action.dest in RUN_OPTIONS:
            studio._add_action(action)  # noqa: SLF001


def build_station(args: argparse.Namespace, catalog: Catalog, root: Path) -> Any:
    """The station of these arguments (no server yet): what the tests serve with Starlette's TestClient."""
    from operator_station.feed import Feed
    from operator_station.replay import load_replay
    from operator_station.server import Station
    from operator_station.session import RunSession, RunSettings

    feed = Feed()
    app_path = (root / args.file).resolve() if args.file else None
    if args.replay:
        load_replay(feed, Path(args.replay))
        return Station(catalog, feed, None, root, app_path, replay=True)
    if getattr(args, "transport", "local") == "ros":
        return _attached(args, catalog, feed, root, app_path)
    options = {"host": args.controller_host, "port": args.controller_port, "rsi_listen": args.rsi_listen,
               "faults": tuple(args.fault or ()), "seed": args.seed, "extra": dict(args.backend_option or ())}
    settings = RunSettings(args.robot, options, args.speed, Path(args.trace) if args.trace else None, args.trajectory_db, not args.no_check)
    return Station(catalog, feed, RunSession(feed, settings), root, app_path)


class StudioError(Exception):
    """A setting the station cannot work with: one line for the operator."""


def _attached(args: argparse.Namespace, catalog: Catalog, feed: Any, root: Path, app_path: Path | None) -> Any:
    """A station watching a cell on the ROS graph: the application names the robot (its groups)."""
    import importlib.util

    from core_functions.robots import find_robot
    from execution_engine.app_model.document import read_document
    from operator_station.attach import AttachedSession, ros_connect
    from operator_station.server import Station

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
    return Station(catalog, feed, session, root, app_path)


def cmd_studio(args: argparse.Namespace, catalog: Catalog, out: IO[str] = sys.stdout, err: IO[str] = sys.stderr) -> int:
    try:
        import starlette  # noqa: F401
        import uvicorn
        import websockets  # noqa: F401 - uvicorn's WebSocket protocol: without it the live feed is refused
    except ImportError as missing:
        err.write(f"error: studio needs the web server: pip install 'dual_arm_executive[studio]' (starlette, uvicorn, websockets; missing {missing.name})\n")
        return 2
    if args.file and not Path(args.file).is_file():
        err.write(f"error: {args.file}: no such file\n")
        return 1
    if args.replay and not Path(args.replay).is_file():
        err.write(f"error: {args.replay}: no such trace file\n")
        return 1
    if args.host not in LOOPBACK:
        err.write(f"warning: serving on {args.host}: anyone who reaches this address can start and stop the robot (no login); use the default 127.0.0.1 unless the network is the cell's own\n")
    if not 0 <= args.port <= 65535:
        err.write(f"error: --port must be 0..65535, got {args.port}\n")
        return 2
    try:
        station = build_station(args, catalog, Path.cwd())
    except StudioError as error:
        err.write(f"error: {error}\n")
        return 2
    except OSError as error:
        err.write(f"error: {error}\n")
        return 1
    from operator_station.server import create_app

    config = uvicorn.Config(create_app(station), host=args.host, port=args.port, log_level="warning", lifespan="off", ws="websockets")
    server = uvicorn.Server(config)
    speed = "max" if math.isinf(args.speed) else f"x{args.speed:g}"
    what = f"replaying {args.replay}" if args.replay else f"runs at {speed}"
    out.write(f"operator station on http://{args.host if ':' not in args.host else f'[{args.host}]'}:{args.port}/ ({what}); Ctrl-C ends it\n")
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


async def _serve(server: Any, station: Any) -> None:
    try:
        await server.serve()
    finally:
        station.stopping.set()
        if station.session is not None and station.session.running:  # a run of its own: stopped with the station
            await station.session.command("stop")
            await asyncio.to_thread(station.session.join, 30.0)
        elif station.session is not None:  # an attached cell goes on; the station leaves its graph
            await asyncio.to_thread(station.session.join, 10.0)
