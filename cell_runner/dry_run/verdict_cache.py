"""The dry run's verdict, kept: an application nothing of which changed is not checked twice.

A dry run of the demonstrator takes seconds; an integrator runs the same application again and again.
A verdict is kept under a key made of everything the dry run depends on (:func:`verdict_key`): the
application's place and bytes, the application as read (:mod:`.app_digest`: what the station's page or a
goal holds, the operations its included files brought), its cell's bytes, the robot, the simulator and its options (and the bytes of any file an
option names), the trajectory database the dry run copies, and the program itself (the bytes of its
packages, URDFs included, the Python and the numerical libraries' versions).  Any change gives another key,
so a kept verdict is never one of another application, cell, robot model or program.

Only a passed verdict is kept (a failed one is checked again, and prints its findings again); it is the
first check only: the run still checks from where the robot is measured to be (:mod:`.start`).  An entry is
read as anything from outside is: bounded, every field's type checked, a verdict that did not pass or names
another key refused; whatever cannot be read is ignored (and checked again), never trusted.  Entries are
written whole (a temporary file in the same folder, then renamed), bounded in size and in number, and never
over a file the run reads or writes.

Where: ``$XDG_CACHE_HOME/dual_arm_executive/dry_run`` (default ``~/.cache/...``); deleting the folder
clears it (docs/application_xml.md, "Checking before anything moves").
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import logging
import math
import os
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from cell_runner.dry_run.app_digest import NotDigestible, app_digest
from cell_runner.dry_run.report import CollisionCheck, DryRunReport, GroupTime, JointPositions, Span
from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.output_files import same_file
from core_functions.trajectory_store import application_store
from execution_engine.app_model.model import Application
from execution_engine.engine.waits import FlagWait

log = logging.getLogger(__name__)

#: The entries' format; another number is another key (an entry of an older format is never read as this one).
FORMAT = 1
#: The packages whose files make the program's digest (what a dry run runs; the station only shows it).
PACKAGES = ("core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges", "cell_runner")
#: The libraries whose version changes what the dry run computes (kinematics, collisions, arrays, XML).
LIBRARIES = ("pin", "coal", "numpy", "lxml")
#: An entry larger than this is not written (an application of many thousand operations), nor read.
MAX_ENTRY_BYTES = 8 * 1024 * 1024
#: Entries kept; the least recently written go first.
MAX_ENTRIES = 64
#: Bounds of what an entry may hold (a damaged or crafted file is refused before it is built into a report).
MAX_ITEMS = 1_000_000
MAX_TEXT = 100_000
SUFFIX = ".verdict.json"


def cache_dir(environ: Mapping[str, str] = os.environ) -> Path:
    """``$XDG_CACHE_HOME/dual_arm_executive/dry_run``, ``~/.cache/...`` when it is unset or not absolute (XDG's rule)."""
    base = environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and os.path.isabs(base) else Path.home() / ".cache"
    return root / "dual_arm_executive" / "dry_run"


# ------------------------------------------------------------------------------------ the key
def _feed(digest: Any, label: str, data: bytes) -> None:
    """One labelled, length-prefixed part: no two different sequences of parts give the same bytes."""
    digest.update(f"{label}:{len(data)}:".encode())
    digest.update(data)


def _file_bytes(path: str | Path) -> bytes | None:
    """The file's bytes, None when there is none (an absent file is a state of its own, not an error)."""
    try:
        with open(path, "rb") as handle:
            return handle.read()
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None


def _installed(libraries: Iterable[str]) -> list[str]:
    """``name-version`` of each library's installed distribution, from the ``.dist-info`` folders' names
    (importlib.metadata would cost 30 ms of start-up for the same answer)."""
    wanted = {name.lower() for name in libraries}
    found: set[str] = set()
    for entry in sys.path:
        try:
            names = os.listdir(entry or ".")
        except OSError:
            continue
        for name in names:
            if name.endswith(".dist-info") and name.partition("-")[0].lower().replace("_", "-") in wanted:
                found.add(name[: -len(".dist-info")])
    return sorted(found)


@lru_cache(maxsize=1)
def program_digest() -> str:
    """The program as it is on disk: every file of its packages (sources, URDFs), Python's version and the
    numerical libraries'.  A source checkout, a pip install and an edited file each give their own."""
    digest = hashlib.sha256()
    _feed(digest, "python", sys.version.encode())
    _feed(digest, "libraries", " ".join(_installed(LIBRARIES)).encode())
    for package in PACKAGES:
        spec = importlib.util.find_spec(package)
        for root in (spec.submodule_search_locations or ()) if spec is not None else ():
            for folder, dirs, files in os.walk(root):
                dirs[:] = sorted(d for d in dirs if d != "__pycache__")
                for name in sorted(files):
                    if not name.endswith((".pyc", ".pyo")):
                        path = os.path.join(folder, name)
                        _feed(digest, f"{package}/{os.path.relpath(path, root)}", _file_bytes(path) or b"")
    return digest.hexdigest()


def verdict_key(app: Application, setup: DryRunSetup, trajectory_db: str | None) -> str:
    """The key of a dry run of ``app`` on ``setup`` from the simulator's start, reading ``trajectory_db``
    (the run's; None: the application's own, as the dry run reads it).  ``app`` itself is in it
    (:mod:`.app_digest`), not only its file: :class:`~.app_digest.NotDigestible` when it cannot be."""
    if setup.unkept:
        raise NotDigestible(setup.unkept)
    digest = hashlib.sha256()
    _feed(digest, "format", str(FORMAT).encode())
    _feed(digest, "program", program_digest().encode())
    _feed(digest, "application", _file_bytes(app.path) or b"")
    _feed(digest, "where", os.path.realpath(app.path).encode())  # the report names its file; relative paths resolve from it
    _feed(digest, "parsed", app_digest(app).encode())  # what is run: a page's document, a goal's XML, included files
    cell = app.cell.path if app.cell is not None and app.cell.path is not None else None
    _feed(digest, "cell", b"" if cell is None else _file_bytes(cell) or b"")
    _feed(digest, "robot", app.robot.name.encode())
    options = setup.options
    described = {
        "backend": setup.backend, "simulated_clock": setup.simulated_clock, "robot": options.robot.name, "host": options.host,
        "port": options.port, "rsi_listen": options.rsi_listen, "faults": list(options.faults), "seed": options.seed,
        "extra": sorted(options.extra.items()),
        **({"speed_override": options.speed_override} if options.speed_override != 1.0 else {}),  # the dry run's times depend on it
    }
    _feed(digest, "setup", json.dumps(described, sort_keys=True).encode())
    for name, value in sorted(options.extra.items()):  # an option naming a file (an RSI configuration): its bytes
        if value and os.path.isfile(value):
            _feed(digest, f"option {name}", _file_bytes(value) or b"")
    database = trajectory_db or str(application_store(app.path))
    for suffix in ("", "-wal"):  # what SQLite holds of it: the file and its write-ahead log
        content = _file_bytes(database + suffix) if database != ":memory:" else None
        _feed(digest, f"trajectories{suffix}", b"absent" if content is None else b"present" + content)
    return digest.hexdigest()


# ---------------------------------------------------------------------------------- an entry
@dataclass(frozen=True)
class Verdict:
    """A kept verdict: the report and when its dry run ran (seconds since 1970)."""

    report: DryRunReport
    checked_at: float

    def line(self) -> str:
        """What the console says instead of the dry run's lines."""
        when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.checked_at))
        return (f"dry run: unchanged since the check of {when} (cached verdict: passed, "
                f"cycle time {self.report.cycle_time:.2f} s)")


class BadEntry(ValueError):
    """An entry that is not a kept verdict of this key (damaged, crafted, another format)."""


def _need(condition: bool, what: str) -> None:
    if not condition:
        raise BadEntry(what)


def _text(value: Any, what: str) -> str:
    _need(isinstance(value, str) and len(value) <= MAX_TEXT, f"{what}: not a text")
    return str(value)


def _number(value: Any, what: str) -> float:
    _need(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value), f"{what}: not a finite number")
    return float(value)


def _count(value: Any, what: str) -> int:
    _need(isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_ITEMS, f"{what}: not a count")
    return int(value)


def _items(value: Any, what: str) -> list[Any]:
    _need(isinstance(value, list) and len(value) <= MAX_ITEMS, f"{what}: not a list")
    return list(value)


def _fields(value: Any, what: str, names: Iterable[str]) -> dict[str, Any]:
    _need(isinstance(value, dict), f"{what}: not an object")
    missing = [n for n in names if n not in value]
    _need(not missing, f"{what}: no {', '.join(missing)}")
    return dict(value)


def _joints(value: Any, what: str) -> JointPositions | None:
    if value is None:
        return None
    pair = _items(value, what)
    _need(len(pair) == 2, f"{what}: not names and positions")
    names = tuple(_text(n, what) for n in _items(pair[0], what))
    positions = tuple(_number(p, what) for p in _items(pair[1], what))
    _need(len(names) == len(positions), f"{what}: {len(names)} names, {len(positions)} positions")
    return names, positions


def _span(value: Any) -> Span:
    f = _fields(value, "span", ("group", "groups", "operation", "function", "primitive", "start", "end", "finding"))
    _need(f["finding"] is None, "span: a finding in a passed verdict")
    start, end = _number(f["start"], "span start"), _number(f["end"], "span end")
    _need(start <= end, "span: ends before it starts")
    return Span(
        _text(f["group"], "span group"), tuple(_text(g, "span groups") for g in _items(f["groups"], "span groups")),
        _text(f["operation"], "span operation"), _text(f["function"], "span function"), _text(f["primitive"], "span primitive"),
        start, end,
    )


def _wait(value: Any) -> FlagWait:
    f = _fields(value, "wait", ("group", "operation", "flag", "t_start", "t_end", "outcome", "kind"))
    return FlagWait(
        _text(f["group"], "wait group"), _text(f["operation"], "wait operation"), _text(f["flag"], "wait flag"),
        _number(f["t_start"], "wait start"), _number(f["t_end"], "wait end"), _text(f["outcome"], "wait outcome"), _text(f["kind"], "wait kind"),
    )


def report_of(value: Any) -> DryRunReport:
    """The passed report an entry holds; BadEntry for anything else."""
    names = ("app", "file", "backend", "time_base", "findings", "timeline", "cycle_time", "groups", "operations_total",
             "operations_checked", "complete", "notes", "collisions", "waits", "start", "end")
    f = _fields(value, "report", names)
    _need(f["findings"] == [] and f["notes"] == [] and f["complete"] is True, "report: not a passed verdict")
    _need(f["time_base"] in ("simulated clock", "robot cycles", "wall clock"), "report: unknown time base")
    groups_in = _fields(f["groups"], "groups", ())
    _need(len(groups_in) <= MAX_ITEMS, "groups: too many")
    groups = {}
    for group, time_ in groups_in.items():
        g = _fields(time_, f"group {group}", ("busy", "idle", "primitives"))
        groups[_text(group, "group")] = GroupTime(_number(g["busy"], "busy"), _number(g["idle"], "idle"), _count(g["primitives"], "primitives"))
    collisions = None
    if f["collisions"] is not None:
        c = _fields(f["collisions"], "collisions", ("motions", "samples", "margin"))
        collisions = CollisionCheck(_count(c["motions"], "motions"), _count(c["samples"], "samples"), _number(c["margin"], "margin"))
    total, checked = _count(f["operations_total"], "operations"), _count(f["operations_checked"], "operations checked")
    _need(checked == total, "report: not every operation checked")
    return DryRunReport(
        app=_text(f["app"], "app"), file=_text(f["file"], "file"), backend=_text(f["backend"], "backend"), time_base=f["time_base"],
        findings=(), timeline=tuple(_span(s) for s in _items(f["timeline"], "timeline")), cycle_time=_number(f["cycle_time"], "cycle time"),
        groups=groups, operations_total=total, operations_checked=checked, complete=True, notes=(), collisions=collisions,
        waits=tuple(_wait(w) for w in _items(f["waits"], "waits")), start=_joints(f["start"], "start"), end=_joints(f["end"], "end"),
    )


def seal(key: str, checked_at: float, report: Any) -> str:
    """The digest an entry carries of what it says: a byte flipped or lost on the disk gives another."""
    text = json.dumps([FORMAT, key, checked_at, report], sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def decode(data: bytes, key: str) -> Verdict:
    """The verdict an entry's bytes hold for ``key``; BadEntry for anything else."""
    _need(len(data) <= MAX_ENTRY_BYTES, "larger than an entry may be")
    try:
        value = json.loads(data)
    except (ValueError, RecursionError) as error:  # UnicodeDecodeError is a ValueError
        raise BadEntry(f"not JSON ({error})") from None
    f = _fields(value, "entry", ("format", "key", "checked_at", "seal", "report"))
    _need(f["format"] == FORMAT, "another format")
    _need(f["key"] == key, "the verdict of another key")
    checked_at = _number(f["checked_at"], "checked_at")
    _need(0 <= checked_at <= 1e11, "checked_at: not a time")
    try:
        sealed = seal(key, checked_at, f["report"])
    except (ValueError, TypeError, RecursionError) as error:
        raise BadEntry(f"report: {error}") from None
    _need(f["seal"] == sealed, "its seal does not match what it says (damaged)")
    return Verdict(report_of(f["report"]), checked_at)


def encode(verdict: Verdict, key: str) -> bytes:
    """An entry's bytes (JSON: read back by :func:`decode`)."""
    report = json.loads(json.dumps(asdict(verdict.report), allow_nan=False))  # as it will be read: lists, not tuples
    entry = {"format": FORMAT, "key": key, "checked_at": verdict.checked_at, "seal": seal(key, verdict.checked_at, report), "report": report}
    return json.dumps(entry, separators=(",", ":"), allow_nan=False).encode()


# -------------------------------------------------------------------------------- the folder
class VerdictCache:
    """The kept verdicts in ``folder``; every failure to read or write one means only that the dry run runs."""

    def __init__(self, folder: Path | None = None) -> None:
        self.folder = folder if folder is not None else cache_dir()

    def path(self, key: str) -> Path:
        return self.folder / f"{key}{SUFFIX}"

    def get(self, key: str) -> Verdict | None:
        """The passed verdict kept for ``key``; None when there is none or it cannot be trusted (said in the log)."""
        path = self.path(key)
        try:
            with open(path, "rb") as handle:
                data = handle.read(MAX_ENTRY_BYTES + 1)
        except FileNotFoundError:
            return None
        except OSError as error:
            log.warning("dry run: the kept verdict %s cannot be read (%s); checking again", path, error.strerror or error)
            return None
        try:
            return decode(data, key)
        except BadEntry as error:
            log.warning("dry run: the kept verdict %s is not one (%s); checking again", path, error)
            return None

    def put(self, key: str, verdict: Verdict, avoid: Iterable[str | Path] = ()) -> bool:
        """Keep a passed verdict; False (and a line in the log) when it is not kept: it did not pass, it is too
        large, the entry would be a file the run reads or writes (``avoid``), or the folder cannot be written."""
        if not verdict.report.ok:
            return False
        data = encode(verdict, key)
        path = self.path(key)
        if len(data) > MAX_ENTRY_BYTES:
            log.info("dry run: the verdict is not kept: %d bytes, more than %d", len(data), MAX_ENTRY_BYTES)
            return False
        clash = next((str(p) for p in avoid if same_file(path, p)), None)
        if clash is not None:
            log.warning("dry run: the verdict is not kept: %s is %s, which the run reads or writes", path, clash)
            return False
        try:
            self.folder.mkdir(parents=True, exist_ok=True, mode=0o700)
            handle, temporary = tempfile.mkstemp(prefix=".", suffix=".tmp", dir=self.folder)
            try:
                with os.fdopen(handle, "wb") as out:
                    out.write(data)
                os.replace(temporary, path)  # whole or not at all: a reader never sees half an entry
            except BaseException:
                with contextlib.suppress(OSError):  # removed by another process first
                    os.unlink(temporary)
                raise
        except OSError as error:
            log.warning("dry run: the verdict is not kept in %s (%s)", self.folder, error.strerror or error)
            return False
        self.prune()
        return True

    def prune(self, keep: int = MAX_ENTRIES) -> None:
        """Only the ``keep`` entries written last stay (and no temporary file an interrupted write left)."""
        try:
            entries = [(e.stat().st_mtime, e.path) for e in os.scandir(self.folder) if e.name.endswith(SUFFIX) and e.is_file()]
            stale = [e.path for e in os.scandir(self.folder) if e.name.endswith(".tmp") and time.time() - e.stat().st_mtime > 3600]
        except OSError:
            return
        entries.sort(reverse=True)
        for path in [p for _, p in entries[keep:]] + stale:
            with contextlib.suppress(OSError):  # removed by another process first
                os.unlink(path)
