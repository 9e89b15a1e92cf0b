"""The station's audit trail: who did what to the cell, when, and what it changed -- one JSON line per action.

A cell that several people drive needs an answer to "who changed this program, and who started
the run that crashed?" days later, so every state-changing route of the station records its
action here, refusals included.  How a route calls it (new routes too)::

    from operator_station.audit import digest, record

    async def teach(request: Request) -> Response:
        before = digest(cell_path.read_bytes())
        ...                                   # the action
        record(request, "teach", ok=ok, answer=answer, before=before, after=digest(cell_path.read_bytes()),
               frame="drill_1", path="cells/rivet.xml")

``request`` is the Starlette request (or WebSocket) the guard let through: the guard left the
requester (:class:`operator_station.access.Who`: name, role, session) and the station's
:class:`AuditLog` in its scope, so a route needs nothing else.  ``what`` is a short verb phrase
(``save``, ``run start``, ``pause``, ``speed``, ``breakpoint set``, ``teach``, ``jog start``,
``safety stop raised``); ``before``/``after`` are :func:`digest` values of what the action
replaced (an application, a cell, a remainder); further keyword arguments are details (JSON
values).  A route whose action is refused records ``ok=False`` with the refusal as ``answer``.  What reaches
the cell without a route -- the terminal, a ROS service or parameter, another station, a light curtain -- is
recorded from the run's records by :mod:`operator_station.cell_audit`, under its source; a jog's starts and
stops from the jog's own loop (:mod:`operator_station.jog_station`).

Each entry is appended to the audit file (``studio --audit FILE``; JSON lines, opened for
appending only, mode 600 when created) and kept in memory for the page's Audit panel
(``GET /api/audit``), and logged on stderr through the logger ``operator_station.audit``.
A file that cannot be written is reported once on stderr and on the panel; the station goes on
(the robot is never stopped because a log failed), the memory keeps the entries.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import stat
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, Any

from operator_station.access import WHO, Who

log = logging.getLogger(__name__)

#: The scope key under which the guard leaves the station's audit log for the routes.
AUDIT = "studio.audit"
#: Entries kept in memory for the page (the file keeps all of them).
MAX_KEPT = 2000
#: Entries one ``GET /api/audit`` answers at most.
MAX_ANSWER = 500
#: Bytes of an existing audit file's end read to check that it is one (its last line).
TAIL = 64 << 10
#: The default audit file's name, in the station's folder (or beside ``--trace``).
DEFAULT_NAME = "studio.audit.jsonl"
#: Keys of an entry the station sets; details given by a route may not replace them.
RESERVED = ("seq", "when", "who", "role", "kind", "session", "address", "what", "ok", "answer", "before", "after")


class AuditError(Exception):
    """An audit file the station refuses (another file's, unreadable): one line naming it."""


def digest(data: bytes | str | None) -> str | None:
    """``sha256:<hex>`` of ``data`` (text as UTF-8); None for None, so "no file before" stays visible."""
    if data is None:
        return None
    raw = data.encode("utf-8") if isinstance(data, str) else data
    return "sha256:" + hashlib.sha256(raw).hexdigest()


def hex_digest(hexdigest: str | None) -> str | None:
    """A SHA-256 given as bare hex (a teach plan's, an application's form in the trace's swap record) in the audit's
    ``sha256:<hex>`` form, so every digest of the log reads alike; None (or "") stays None."""
    return f"sha256:{hexdigest}" if hexdigest else None


def file_digest(path: str | Path) -> str | None:
    """:func:`digest` of a file's bytes; None if there is no such file (yet)."""
    try:
        return digest(Path(path).read_bytes())
    except OSError:
        return None


def utc(seconds: float) -> str:
    """An instant as ISO 8601 UTC with milliseconds (the trace's and the safety log's form)."""
    return datetime.fromtimestamp(seconds, timezone.utc).isoformat(timespec="milliseconds")


def is_entry(line: bytes) -> bool:
    """Whether ``line`` is an audit entry (a JSON object with at least when, who and what)."""
    try:
        value = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return False
    return isinstance(value, dict) and all(isinstance(value.get(k), str) for k in ("when", "who", "what"))


def check_audit_file(path: Path, shown: str) -> int:
    """Refuse (AuditError, one line) a path the audit may not append to: a directory or device, or an existing
    file that is not an audit log (its last line no entry) -- appending would change another file.  The ``seq``
    of the file's last entry (0 for a new or empty file), which the next entry continues."""
    try:
        info = path.stat()
    except FileNotFoundError:
        return 0
    except OSError as error:
        raise AuditError(f"{shown}: cannot be read ({error.strerror or error})") from None
    if not stat.S_ISREG(info.st_mode):
        raise AuditError(f"{shown}: not a regular file; give a file for the audit log")
    if info.st_size == 0:
        return 0
    try:
        with open(path, "rb") as handle:
            handle.seek(max(0, info.st_size - TAIL))
            tail = handle.read()
    except OSError as error:
        raise AuditError(f"{shown}: cannot be read ({error.strerror or error})") from None
    last = tail.rstrip(b"\n").rsplit(b"\n", 1)[-1]
    if not is_entry(last):
        raise AuditError(f"{shown}: exists and is not an audit log (its last line is no audit entry); the station appends only to its own: give another file")
    seq = json.loads(last).get("seq")
    return seq if isinstance(seq, int) and 0 <= seq < 1 << 53 else 0


@dataclass
class AuditLog:
    """The entries of one station: appended to ``path`` (None: memory only, as in tests) and kept for the page."""

    path: Path | None = None
    wall: Callable[[], float] = time.time
    entries: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=MAX_KEPT))
    problem: str = ""  # why the file stopped being written, for the page
    _seq: int = 0
    _file: IO[bytes] | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @classmethod
    def open(cls, path: Path, shown: str, wall: Callable[[], float] = time.time) -> AuditLog:
        """The audit log appending to ``path`` (checked first, created with mode 600); AuditError if refused."""
        last = check_audit_file(path, shown)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600)
        except OSError as error:
            raise AuditError(f"{shown}: cannot be written ({error.strerror or error}); give a writable file") from None
        return cls(path, wall, _seq=last, _file=os.fdopen(fd, "ab", buffering=0))

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def append(self, who: Who | None, what: str, *, ok: bool = True, answer: str = "", before: str | None = None,
               after: str | None = None, details: Mapping[str, Any] | None = None, quiet: bool = False) -> dict[str, Any]:
        """Record one action; returns the entry as written.  ``quiet``: the caller logs it on stderr itself."""
        requester = who or Who("unknown", "", "unknown")
        entry: dict[str, Any] = {
            "when": utc(self.wall()), "who": requester.name or str(requester), "role": requester.role, "kind": requester.kind,
            "session": requester.ident, "address": requester.address, "what": what, "ok": ok,
        }
        if answer:
            entry["answer"] = answer
        if before is not None or after is not None:
            entry["before"], entry["after"] = before, after
        for key, value in (details or {}).items():
            entry[key if key not in RESERVED else f"detail_{key}"] = value
        with self._lock:
            self._seq += 1
            entry = {"seq": self._seq, **entry}
            self.entries.append(entry)
            self._write(entry)
        level = logging.INFO if ok else logging.WARNING
        if not quiet:
            log.log(level, "studio audit: %s by %s (%s) at %s%s", what, entry["who"], requester.role, entry["when"], f": {answer}" if answer else "")
        return entry

    def _write(self, entry: dict[str, Any]) -> None:
        if self._file is None:
            return
        try:
            self._file.write(json.dumps(entry, ensure_ascii=False, default=str).encode("utf-8") + b"\n")
        except OSError as error:
            self.problem = f"the audit file {self.path} could not be written ({error.strerror or error}); entries since are kept in memory only"
            log.error("studio: %s", self.problem)
            self._file.close()
            self._file = None

    def newest(self, after: int = 0, limit: int = MAX_ANSWER) -> list[dict[str, Any]]:
        """Entries with ``seq`` above ``after``, newest first, at most ``limit``."""
        with self._lock:
            fresh = [e for e in reversed(self.entries) if e["seq"] > after]
        return fresh[:max(0, min(limit, MAX_ANSWER))]


def log_of(connection: Any) -> AuditLog | None:
    """The audit log the guard left in a request's scope (None outside a station)."""
    scope = getattr(connection, "scope", connection)
    found = scope.get(AUDIT) if isinstance(scope, Mapping) else None
    return found if isinstance(found, AuditLog) else None


def requester(connection: Any) -> Who | None:
    """The requester the guard left in a request's scope."""
    scope = getattr(connection, "scope", connection)
    found = scope.get(WHO) if isinstance(scope, Mapping) else None
    return found if isinstance(found, Who) else None


def record(connection: Any, what: str, *, ok: bool = True, answer: str = "", before: str | None = None, after: str | None = None,
           **details: Any) -> dict[str, Any]:
    """Record ``what`` done by the requester of ``connection`` (a Request, a WebSocket or their scope).

    See the module's docstring for the arguments.  Outside a guarded station (no log in the scope)
    the entry still goes to the ``operator_station.audit`` logger and is returned."""
    audit = log_of(connection)
    if audit is None:
        audit = _LOOSE
    return audit.append(requester(connection), what, ok=ok, answer=answer, before=before, after=after, details=details)


#: Where entries of a route called without a station's guard go (memory, and the logger).
_LOOSE = AuditLog()
