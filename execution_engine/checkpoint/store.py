"""The checkpoint file: a run's progress in SQLite, so a crash of the computer does not mean starting over.

SQLite in WAL mode with ``synchronous=FULL``: each change is one transaction, durable when its
commit returns (a power loss keeps every committed change; a torn write is rolled back, never
half-applied).  A checkpoint outlives the runs that write it: a resumed run goes on writing the
same file, so a second crash resumes from where the second run got to.

What it holds: the application and cell (paths and sha256 digests: a changed file refuses the
resume), each function start and result by operation and group (a function with a start and no
result was in flight), what each hand holds after its last completed function, the trajectories
recorded so far, the error-policy counters, each run with its trace and recording files, the named
outcome of every function an ``<if>`` tests (a resume takes the same branches; a function that ended
with an outcome -- a hole not found -- is done, not failed), and every edit of a paused run (both
applications' digests, where it happened; the meta then names the edited application, which a resume needs).
"""
from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs(run INTEGER PRIMARY KEY, started REAL NOT NULL, trace TEXT, recording TEXT, continues TEXT);
CREATE TABLE IF NOT EXISTS functions(
    run INTEGER NOT NULL, op_index INTEGER NOT NULL, operation TEXT NOT NULL, grp TEXT NOT NULL,
    function TEXT NOT NULL, attempt INTEGER NOT NULL, outcome TEXT NOT NULL, t REAL NOT NULL, wall REAL NOT NULL,
    PRIMARY KEY(run, op_index, grp, attempt));
CREATE TABLE IF NOT EXISTS hands(grp TEXT PRIMARY KEY, holds TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS trajectories(name TEXT NOT NULL, grp TEXT NOT NULL, operation TEXT NOT NULL, PRIMARY KEY(name, grp));
CREATE TABLE IF NOT EXISTS counters(key TEXT PRIMARY KEY, value INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS outcomes(op_index INTEGER NOT NULL, operation TEXT NOT NULL, grp TEXT NOT NULL, outcome TEXT NOT NULL,
    PRIMARY KEY(op_index, grp));
CREATE TABLE IF NOT EXISTS swaps(run INTEGER NOT NULL, t REAL NOT NULL, frontier INTEGER NOT NULL, operation TEXT,
    old_digest TEXT NOT NULL, new_digest TEXT NOT NULL, path TEXT NOT NULL, sha256 TEXT NOT NULL, wall REAL NOT NULL);
"""
STARTED, SUCCEEDED, SKIPPED = "started", "succeeded", "skipped"
DONE = (SUCCEEDED, SKIPPED)
#: What a resumed run does with a function a crash interrupted (``--on-interrupted``): ask the operator, run it again,
#: or skip it.  Here, with the file's states, so the command line reads them without loading the resume's planner.
ANSWERS = ("ask", "redo", "skip")


class CheckpointError(ValueError):
    """A checkpoint that cannot be used; the message names the file and what is wrong."""


@dataclass(frozen=True)
class FunctionRow:
    run: int
    op_index: int
    operation: str
    group: str
    function: str
    attempt: int
    outcome: str


class CheckpointStore:
    """One checkpoint file, opened for a run (``run`` is this run's number in it)."""

    def __init__(self, path: str | Path, *, read_only: bool = False) -> None:
        """Open (or create) a checkpoint; ``read_only`` only looks, and refuses a file that is not one
        (a resume must never add tables to some other database it was pointed at)."""
        self.path = Path(path)
        try:
            if read_only:
                # A read-only connection to a WAL database makes its -wal and -shm files and, being
                # read-only, cannot remove them when it closes: a refused --resume would leave two files
                # beside the checkpoint.  A checkpoint without a -wal file has everything in the file
                # itself (it was closed cleanly), so it is read as it stands (immutable: no lock, no side
                # file); after a crash the -wal is there and holds the latest results, and is read.
                immutable = "&immutable=1" if not Path(f"{self.path}-wal").exists() else ""
                self._db = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro{immutable}", uri=True, isolation_level=None, timeout=5.0)
                tables = {row[0] for row in self._db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
                missing = {"meta", "runs", "functions", "hands", "trajectories", "counters"} - tables
                if missing:
                    self._db.close()
                    raise CheckpointError(f"{self.path}: not a checkpoint file (it has no {', '.join(sorted(missing))} table)")
            else:
                self._db = sqlite3.connect(str(self.path), isolation_level=None, timeout=5.0)
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=FULL")
                self._db.executescript(SCHEMA)
        except sqlite3.Error as error:
            raise CheckpointError(f"{self.path}: not a checkpoint file ({error})") from None
        self.run = 0

    def close(self) -> None:
        self._db.close()

    @contextmanager
    def _change(self) -> Iterator[sqlite3.Connection]:
        """One change, one transaction: all of it on disk when this returns, or none of it."""
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    # ------------------------------------------------------------------------- writing
    def begin_run(self, meta: dict[str, str], trace: str, recording: str, continues: str) -> int:
        """Record what is run (first run only: a resume keeps the original) and a new run row."""
        with self._change() as db:
            for key, value in meta.items():
                db.execute("INSERT OR IGNORE INTO meta(key, value) VALUES (?, ?)", (key, value))
            cursor = db.execute(
                "INSERT INTO runs(started, trace, recording, continues) VALUES (?, ?, ?, ?)", (time.time(), trace, recording, continues)
            )
            self.run = int(cursor.lastrowid or 0)
        return self.run

    def function_event(
        self, op_index: int, operation: str, group: str, function: str, attempt: int, outcome: str, t: float, run: int | None = None
    ) -> None:
        with self._change() as db:
            db.execute(
                "INSERT OR REPLACE INTO functions VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (self.run if run is None else run, op_index, operation, group, function, attempt, outcome, t, time.time()),
            )

    def function_result(
        self, op_index: int, operation: str, group: str, function: str, attempt: int, outcome: str, t: float,
        holds: str | None, trajectory: str | None, counters: dict[str, int],
    ) -> None:
        """A function's result with everything it changed, in one transaction."""
        with self._change() as db:
            db.execute(
                "INSERT OR REPLACE INTO functions VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (self.run, op_index, operation, group, function, attempt, outcome, t, time.time()),
            )
            if outcome == SUCCEEDED and holds is not None:
                db.execute("INSERT OR REPLACE INTO hands(grp, holds) VALUES (?, ?)", (group, holds))
            if outcome == SUCCEEDED and trajectory is not None:
                db.execute("INSERT OR REPLACE INTO trajectories(name, grp, operation) VALUES (?, ?, ?)", (trajectory, group, operation))
            _add(db, counters)

    def outcome(self, op_index: int, operation: str, group: str, outcome: str) -> None:
        """The named outcome a tested function ended with: it chooses the branch, and the function is done."""
        with self._change() as db:
            db.execute("INSERT OR REPLACE INTO outcomes VALUES (?, ?, ?, ?)", (op_index, operation, group, outcome))

    def swap(self, t: float, frontier: int, operation: str | None, old_digest: str, new_digest: str, meta: dict[str, str]) -> None:
        """A paused run's remainder was edited: the row, and the application this checkpoint now belongs to (``meta``,
        :func:`~execution_engine.checkpoint.resume.app_meta` of the new one): a resume goes on with it, never the old."""
        with self._change() as db:
            db.execute("INSERT INTO swaps VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", (
                self.run, t, frontier, operation, old_digest, new_digest, meta["application_path"], meta["application_sha256"], time.time()))
            db.execute("DELETE FROM meta WHERE key = 'includes_sha256'")
            for key, value in meta.items():
                db.execute("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, value))

    def count(self, counters: dict[str, int]) -> None:
        """Add to the error-policy counters (an operator command, say)."""
        with self._change() as db:
            _add(db, counters)

    # ------------------------------------------------------------------------- reading
    def meta(self) -> dict[str, str]:
        return dict(self._db.execute("SELECT key, value FROM meta").fetchall())

    def functions(self) -> list[FunctionRow]:
        rows = self._db.execute(
            "SELECT run, op_index, operation, grp, function, attempt, outcome FROM functions ORDER BY run, wall"
        ).fetchall()
        return [FunctionRow(*row) for row in rows]

    def done(self) -> set[tuple[int, str]]:
        """(operation index, group) of every function completed (or skipped by an operator, or ended with a
        named outcome) in any run."""
        return {(r.op_index, r.group) for r in self.functions() if r.outcome in DONE} | {(i, g) for i, _, g, _ in self.outcomes()}

    def outcomes(self) -> list[tuple[int, str, str, str]]:
        """(operation index, operation, group, outcome) of every tested function (none in a checkpoint older than branches)."""
        try:
            rows = self._db.execute("SELECT op_index, operation, grp, outcome FROM outcomes ORDER BY op_index").fetchall()
        except sqlite3.OperationalError:  # written before the table existed, opened read-only
            return []
        return [(int(r[0]), str(r[1]), str(r[2]), str(r[3])) for r in rows]

    def swaps(self) -> list[tuple[int, int, str, str, str, str]]:
        """(run, frontier, operation, old digest, new digest, application path) of every edit of a paused run, oldest first."""
        try:
            rows = self._db.execute("SELECT run, frontier, operation, old_digest, new_digest, path FROM swaps ORDER BY wall").fetchall()
        except sqlite3.OperationalError:  # written before the table existed, opened read-only
            return []
        return [(int(r[0]), int(r[1]), str(r[2] or ""), str(r[3]), str(r[4]), str(r[5])) for r in rows]

    def hands(self) -> dict[str, str]:
        return dict(self._db.execute("SELECT grp, holds FROM hands").fetchall())

    def trajectories(self) -> list[tuple[str, str]]:
        return [tuple(r) for r in self._db.execute("SELECT name, grp FROM trajectories ORDER BY name").fetchall()]  # type: ignore[misc]

    def counters(self) -> dict[str, int]:
        return dict(self._db.execute("SELECT key, value FROM counters").fetchall())

    def runs(self) -> list[tuple[int, str, str]]:
        """(run, trace, recording) of every run that wrote this checkpoint, oldest first."""
        return [(int(r[0]), r[1] or "", r[2] or "") for r in self._db.execute("SELECT run, trace, recording FROM runs ORDER BY run")]


def _add(db: sqlite3.Connection, counters: dict[str, int]) -> None:
    for key, value in counters.items():
        if value:
            db.execute("INSERT INTO counters(key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = value + ?", (key, value, value))
