"""``studio``'s command line: its options, and the ones it takes over from ``run``.

Apart from :mod:`operator_station.cli` (the station itself: sessions, simulators, the server), so that
the program builds its parser without loading what only ``studio`` needs.
"""
from __future__ import annotations

from typing import Any

from core_functions.option_ranges import argument_type


#: Options ``studio`` takes over from ``run`` (same meaning, same parsing: the two cannot drift apart).
RUN_OPTIONS = ("robot", "speed", "trace", "rsi_listen", "fault", "seed", "backend_option", "trajectory_db", "no_check")


def add_parser(sub: Any) -> None:
    """Register ``studio`` on the CLI's subcommands, after ``run`` (whose run options it shares)."""
    studio = sub.add_parser("studio", help="the operator station in the browser: build, validate, run, watch and replay applications")
    studio.add_argument("file", nargs="?", metavar="APP.xml", help="the application to open in the builder")
    studio.add_argument("--port", type=int, default=8080, help="HTTP port of the station, in [0, 65535] (default 8080; 0: a free one)")
    studio.add_argument("--host", default="127.0.0.1", help="address to serve on (default loopback; anything else is reachable from the network and needs the token)")
    studio.add_argument("--token-file", dest="token_file", metavar="FILE",
                        help="the token pages must present, kept in FILE (one line, mode 600); default: made at start and printed when not on loopback")
    studio.add_argument("--operator-token-file", dest="operator_token_file", metavar="FILE",
                        help="a second token, of the operator role (run, pause, step, speed, alarms; no edit, save or teach), kept in FILE (one line, mode 600)")
    studio.add_argument("--users", metavar="FILE",
                        help="users who log in on the page: lines name:role:hash, role operator or engineer (make one: python -m operator_station.users NAME ROLE); mode 600")
    studio.add_argument("--audit", metavar="FILE",
                        help="the audit log, appended to (JSON lines: who, role, when, what, digests); default studio.audit.jsonl beside --trace or in the current folder")
    studio.add_argument("--allowed-host", dest="allowed_host", action="append", default=[], metavar="NAME",
                        help="a host name pages reach the station by, besides its address, this computer's name and localhost (repeatable)")
    studio.add_argument("--replay", metavar="RUN.mcap|TRACE.jsonl",
                        help="show a finished run's recording or trace instead of running anything (read as report reads it)")
    studio.add_argument("--transport", choices=("local", "ros"), default="local",
                        help="local: run the application in this process (default); ros: watch and command a cell running on the ROS graph (needs APP.xml for its groups, and rclpy)")
    studio.add_argument("--controller-host", dest="controller_host", help="V+ controller address (none starts the simulator); run's --host")
    studio.add_argument("--controller-port", dest="controller_port", type=argument_type("port", label="controller port"),
                        help="V+ controller port, in [0, 65535]; run's --port")
    for action in sub.choices["run"]._actions:  # noqa: SLF001 - argparse has no public way to share options
        if action.dest in RUN_OPTIONS:
            studio._add_action(action)  # noqa: SLF001
