"""What ``run`` refuses before anything runs: the files it would write and the peers it would reach.

An option that cannot work must fail in one line at the start, naming the option and what to do,
and change nothing -- not after a dry run, not half-way through a shift, never as a traceback.
So every file the run reads or writes is listed here (:func:`run_files`) and checked by the one
rule of :mod:`cell_runner.output_files` without writing a byte, controller names are
resolved once (the run then talks to addresses, and a name that resolves to nothing is an
option error, not a "no answer within 2 s" much later), and ``--fault`` is checked against the
robot's groups.  :class:`Refused` carries the line; the CLI prints it and exits with
``EXIT_USAGE``.
"""
from __future__ import annotations

import ipaddress
import socket
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from cell_runner.output_files import FilePlan, Output, Refused
from cell_runner.settings import RunSettings
from execution_engine.app_model.model import Application

__all__ = ["Refused", "check_faults", "check_trajectory_db", "preflight", "resolve", "resolve_endpoint", "run_files", "app_inputs"]


def preflight(app: Application, settings: RunSettings) -> RunSettings:
    """Check the options that name a peer or a group; resolve names once (the settings returned
    name addresses).  The files come once the run has named them all (:func:`run_files`, from
    ``prepare_flight``).

    Raises :class:`Refused` with one line; writes nothing.
    """
    backend = settings.backend
    check_faults(backend.faults, app.robot.group_names)
    if backend.host is not None:
        backend = replace(backend, host=resolve("--host", backend.host))
    if backend.rsi_listen is not None:
        backend = replace(backend, rsi_listen=resolve_endpoint("--rsi-listen", backend.rsi_listen))
    return replace(settings, backend=backend)


def check_faults(faults: Iterable[str], groups: Iterable[str]) -> None:
    """Every ``--fault GROUP:KIND@F`` names a group of the robot (the back end checks the rest)."""
    known = tuple(groups)
    for text in faults:
        group = text.partition(":")[0].strip()
        if group not in known:
            raise Refused(f"--fault {text!r}: the robot has no group {group!r} (groups: {', '.join(known)})")


def resolve(option: str, name: str) -> str:
    """The address ``name`` stands for, resolved once at start; the name itself when it is an address."""
    try:
        return str(ipaddress.ip_address(name))
    except ValueError:
        pass
    try:
        found = socket.getaddrinfo(name, None, proto=socket.IPPROTO_TCP)
    except (socket.gaierror, UnicodeError) as error:
        reason = error.strerror if isinstance(error, socket.gaierror) else str(error)
        raise Refused(f"{option} {name}: the name does not resolve to an address ({reason}); give the controller's IP address or a name this machine can resolve") from None
    ipv4 = [entry[4][0] for entry in found if entry[0] == socket.AF_INET]
    return str(ipv4[0] if ipv4 else found[0][4][0])


def resolve_endpoint(option: str, text: str) -> str:
    """``HOST:PORT`` with HOST resolved once; the port is checked by the back end."""
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        return text  # the back end says what a HOST:PORT must look like
    return f"{resolve(option, host)}:{port}"


def run_files(
    inputs: Iterable[tuple[str, str | Path]], *, trace: str | None = None, record: str | None = None, checkpoint: str | None = None,
    resume: str | None = None, trajectory_db: str | None = None, extra: dict[str, str] | None = None,
    derived: dict[str, str] | None = None, command: str = "run",
) -> FilePlan:
    """Every file a run reads (``inputs``: the application and its cell, :func:`app_inputs`) and
    writes, as ``run`` (after ``prepare_flight``) or the studio names them.

    ``derived``: option -> where its path came from, for the paths the run chose itself (the
    checkpoint next to the trace, the application's own trajectory database, a resumed run's
    trace); the refusal then says so instead of naming an option nobody gave.  ``extra``: the
    back-end options (``config`` is read, ``feedback`` written)."""
    derived = derived or {}
    extra = extra or {}
    plan = FilePlan(command)
    for named, path in inputs:
        plan.read(named, path)
    if extra.get("config"):
        plan.read(f"--backend-option config={extra['config']}", extra["config"])

    def output(option: str, path: str | None, what: str, example: str, database: bool = False) -> Output | None:
        """An option's output (None when not given); a database is SQLite, and the trajectory database is read too."""
        if not path:
            return None
        read = option == "--trajectory-db"
        return Output(option, str(path), what, example, sqlite=database, reads=read, makes_folders=read, default=derived.get(option, ""))

    plan.write(output("--trace", trace, "the trace", "run.jsonl"))
    plan.write(output("--record", record, "the recording", "run.mcap"))
    if resume:  # read and written again: the run's own checkpoint
        plan.write(Output("--resume", str(resume), "the checkpoint", "run.checkpoint.sqlite", sqlite=True))
    else:
        plan.write(output("--checkpoint", checkpoint, "the checkpoint", "run.checkpoint.sqlite", database=True))
    plan.write(output("--trajectory-db", trajectory_db, "the trajectory database", "trajectories.db", database=True))
    if extra.get("feedback"):
        plan.write(Output("--backend-option feedback", extra["feedback"], "the feedback log", "feedback.csv", joiner="="))
    return plan


def app_inputs(app: Application) -> list[tuple[str, str | Path]]:
    """The application, its cell and the applications its ``<call>``s bring in, as a refusal names them."""
    found: list[tuple[str, str | Path]] = [(f"the application {app.path}", app.path)]
    if app.cell is not None and app.cell.path is not None:
        found.append((f"the cell {app.cell.path}", app.cell.path))
    found += [(f"the called application {path}", path) for path in app.includes]
    return found


def check_trajectory_db(path: str, applications: Iterable[Path]) -> None:
    """The database a dry run reads (``validate --simulate``): refused as ``run`` would refuse it."""
    plan = FilePlan("validate")
    for application in applications:
        plan.read(f"the application {application}", application)
    plan.write(Output("--trajectory-db", path, "the trajectory database", "trajectories.db", sqlite=True, reads=True, makes_folders=True))
    plan.check()
