"""What ``run`` refuses before anything runs: the files it would write and the peers it would reach.

An option that cannot work must fail in one line at the start, naming the option and what to do,
and change nothing -- not after a dry run, not half-way through a shift, never as a traceback.
So the trace and trajectory-database paths are checked here without writing a byte (a trace
never overwrites the application, its cell or the trajectory database), controller names are
resolved once (the run then talks to addresses, and a name that resolves to nothing is an
option error, not a "no answer within 2 s" much later), and ``--fault`` is checked against the
robot's groups.  :class:`Refused` carries the line; the CLI prints it and exits with
``EXIT_USAGE``.
"""
from __future__ import annotations

import argparse
import ipaddress
import os
import socket
import sqlite3
import stat
from collections.abc import Iterable
from contextlib import closing
from pathlib import Path

from execution_engine.app_model.model import Application


class Refused(Exception):
    """An option ``run`` cannot work with; the message is the whole line the operator reads."""


def preflight(app: Application, args: argparse.Namespace) -> None:
    """Check every option that names a file or a peer; resolve names once (``args`` is updated).

    Raises :class:`Refused` with one line; writes nothing.
    """
    check_faults(args.fault or (), app.robot.group_names)
    if args.host is not None:
        args.host = resolve("--host", args.host)
    if args.rsi_listen is not None:
        args.rsi_listen = resolve_endpoint("--rsi-listen", args.rsi_listen)
    if args.trajectory_db:
        check_trajectory_db(args.trajectory_db, _inputs(app))
    if args.trace:
        protected = _inputs(app) + ([Path(args.trajectory_db)] if args.trajectory_db else [])
        check_trace(args.trace, protected)


def _inputs(app: Application) -> list[Path]:
    """The files the run reads: an output option naming one of them would destroy it."""
    return [app.path] + ([app.cell.path] if app.cell is not None and app.cell.path is not None else [])


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


def check_trace(path: str, protected: Iterable[Path]) -> None:
    """The trace can be created or appended to, and is none of the files the run reads."""
    target = Path(path)
    if target.is_dir():
        raise Refused(f"--trace {path}: is a directory; give a file name, e.g. {target / 'run.jsonl'}")
    _check_parent("--trace", target)
    if target.exists():
        for other in protected:
            if _same(target, other):
                raise Refused(f"--trace {path}: is {other}, which this run reads; the trace would overwrite it: give another file")
    _check_writable("--trace", target)


def check_trajectory_db(path: str, protected: Iterable[Path]) -> None:
    """The trajectory database is an SQLite file (or can be created), not a directory or another file."""
    target = Path(path)
    if target.is_dir():
        raise Refused(f"--trajectory-db {path}: is a directory; give an SQLite file, e.g. {target / 'trajectories.db'}")
    if not target.exists():
        _check_creatable("--trajectory-db", target, parents=True)  # the store makes missing directories
        return
    for other in protected:
        if _same(target, other):
            raise Refused(f"--trajectory-db {path}: is {other}, which this run reads as an application or cell; give another file")
    if not stat.S_ISREG(target.stat().st_mode):
        raise Refused(f"--trajectory-db {path}: is not a regular file; give an SQLite file")
    try:  # read-only: a refused file is left exactly as it was
        with closing(sqlite3.connect(f"{target.resolve().as_uri()}?mode=ro", uri=True)) as db:
            db.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.Error as error:  # sqlite3.DatabaseError is no OSError
        raise Refused(f"--trajectory-db {path}: is not an SQLite database ({error}); give the file RecordTrajectory wrote, or a new name") from None
    _check_writable("--trajectory-db", target)


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _check_parent(option: str, target: Path) -> None:
    parent = target.parent
    if not parent.exists():
        raise Refused(f"{option} {target}: the directory {parent} does not exist; create it first or give another path")
    if not parent.is_dir():
        raise Refused(f"{option} {target}: {parent} is not a directory")


def _check_writable(option: str, target: Path) -> None:
    if target.exists():
        try:  # append mode: opening changes nothing, and finds read-only files and file systems
            with open(target, "ab"):
                pass
        except OSError as error:
            raise Refused(f"{option} {target}: cannot be written ({error.strerror or error}); give a writable file") from None
        return
    _check_creatable(option, target, parents=False)


def _check_creatable(option: str, target: Path, *, parents: bool) -> None:
    """Create and remove the file: the only sure test of a path (permissions, read-only mounts, /proc)."""
    if parents:
        existing = target.parent
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        if not existing.is_dir():
            raise Refused(f"{option} {target}: {existing} is not a directory")
        if existing != target.parent:
            if not os.access(existing, os.W_OK | os.X_OK):
                raise Refused(f"{option} {target}: the directory {target.parent} cannot be created in {existing}")
            return
    else:
        _check_parent(option, target)
    try:
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except OSError as error:
        raise Refused(f"{option} {target}: cannot be created ({error.strerror or error}); give a writable path") from None
    os.close(fd)
    os.unlink(target)
