"""Named joint trajectories kept in SQLite (paper Table 1: "stored in a database for a future use").

A trajectory is recorded once (planned or taught) and replayed many times, across runs and
restarts, so it lives in a file, not in memory.  One row per (group, name), keeping when it was
made (run time and wall-clock time) and for which cell model (``cell_sha256``), so an integrator
can tell a taught path from a planned one and a path taught for another cell.

A recorded trajectory is the result of work on the real cell (a taught path cannot be made
again by software), so recording a name that exists is refused unless the application says so
(``overwrite``).  The database of a run belongs to its application (:func:`application_store`,
next to the application file) rather than to a user's home directory; the file is created on
the first recording, so running an application that records nothing writes nothing.
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from core_functions.primitives import TrajectoryResult

_SCHEMA = """
CREATE TABLE IF NOT EXISTS trajectories (
    grp TEXT NOT NULL,
    name TEXT NOT NULL,
    joint_names TEXT NOT NULL,
    points TEXT NOT NULL,
    times TEXT NOT NULL,
    source TEXT NOT NULL,
    recorded_at REAL NOT NULL,
    PRIMARY KEY (grp, name)
)
"""
_ADDED_COLUMNS = {"recorded_wall": "REAL NOT NULL DEFAULT 0", "cell_sha256": "TEXT NOT NULL DEFAULT ''"}


def application_store(application: str | Path) -> Path:
    """The default database of an application: ``cells/app.xml`` -> ``cells/app.trajectories.sqlite``."""
    path = Path(application)
    return path.with_name(f"{path.stem}.trajectories.sqlite")


class TrajectoryExists(ValueError):
    """Recording a name that is already recorded, without the application's leave to overwrite it."""


@dataclass(frozen=True)
class StoredTrajectory:
    group: str
    name: str
    trajectory: TrajectoryResult
    source: str  # "plan" or "teach"
    recorded_at: float  # run-clock seconds of the recording
    recorded_wall: float = 0.0  # wall-clock time of the recording (seconds since 1970; 0: before it was kept)
    cell_sha256: str = ""  # the cell model it was recorded for ("" unknown)


class TrajectoryStore:
    """A small SQLite table of trajectories; ``":memory:"`` for a throw-away store.

    ``cell_sha256`` is stamped on every recording (the group machine sets it from the cell model
    the engine publishes); ``wall_time`` gives the wall-clock stamp (injectable for tests).
    """

    def __init__(self, path: str | Path, wall_time: Callable[[], float] = time.time) -> None:
        self.path = str(path)
        self.cell_sha256 = ""
        self._wall_time = wall_time
        self._lock = threading.Lock()
        self._db: sqlite3.Connection | None = None
        if self.path == ":memory:" or Path(self.path).exists():
            self._open()

    def _open(self) -> sqlite3.Connection:
        """Open (and on the first recording create) the file; ValueError naming it when it cannot be."""
        if self._db is not None:
            return self._db
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(self.path, check_same_thread=False)
            with db:
                db.execute(_SCHEMA)
                have = {row[1] for row in db.execute("PRAGMA table_info(trajectories)")}
                for column, declaration in _ADDED_COLUMNS.items():
                    if column not in have:  # a database from before these were kept
                        db.execute(f"ALTER TABLE trajectories ADD COLUMN {column} {declaration}")
        except (OSError, sqlite3.Error) as error:
            raise ValueError(f"trajectory database {self.path}: cannot be opened ({error}); give a writable file with --trajectory-db") from None
        self._db = db
        return db

    def recorded(self, group: str, name: str) -> StoredTrajectory | None:
        """The stored row, or None (never a subclass's stand-in for a missing name)."""
        try:
            return TrajectoryStore.load(self, group, name)
        except KeyError:
            return None

    def check_overwrite(self, group: str, name: str, overwrite: bool) -> None:
        """TrajectoryExists when ``name`` is recorded for ``group`` and the application did not allow replacing it."""
        if overwrite:
            return
        old = self.recorded(group, name)
        if old is not None:
            when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(old.recorded_wall)) if old.recorded_wall else "earlier"
            raise TrajectoryExists(
                f"trajectory {name!r} of {group} is already recorded in {self.path} ({old.source}, {when}); "
                "the application must say overwrite=true to record it again, or use another name"
            )

    def save(self, group: str, name: str, trajectory: TrajectoryResult, source: str, recorded_at: float, overwrite: bool = True) -> None:
        if not trajectory.points:
            raise ValueError(f"trajectory {name!r} of {group} has no points")
        self.check_overwrite(group, name, overwrite)
        with self._lock:
            db = self._open()
            with db:
                db.execute(
                    "INSERT OR REPLACE INTO trajectories (grp, name, joint_names, points, times, source, recorded_at, recorded_wall, cell_sha256) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        group,
                        name,
                        json.dumps(list(trajectory.joint_names)),
                        json.dumps([list(p) for p in trajectory.points]),
                        json.dumps(list(trajectory.times)),
                        source,
                        recorded_at,
                        self._wall_time(),
                        self.cell_sha256,
                    ),
                )

    def load(self, group: str, name: str) -> StoredTrajectory:
        with self._lock:
            row = None if self._db is None else self._db.execute(
                "SELECT joint_names, points, times, source, recorded_at, recorded_wall, cell_sha256 FROM trajectories WHERE grp = ? AND name = ?",
                (group, name),
            ).fetchone()
        if row is None:
            known = ", ".join(self.names(group)) or "none"
            raise KeyError(f"no trajectory {name!r} recorded for {group} in {self.path} (recorded: {known})")
        joint_names, points, times, source, recorded_at, recorded_wall, cell_sha256 = row
        trajectory = TrajectoryResult(
            joint_names=tuple(json.loads(joint_names)),
            points=tuple(tuple(float(v) for v in p) for p in json.loads(points)),
            times=tuple(float(t) for t in json.loads(times)),
        )
        return StoredTrajectory(group, name, trajectory, source, float(recorded_at), float(recorded_wall), str(cell_sha256))

    def names(self, group: str) -> list[str]:
        with self._lock:
            if self._db is None:
                return []
            rows = self._db.execute("SELECT name FROM trajectories WHERE grp = ? ORDER BY name", (group,)).fetchall()
        return [r[0] for r in rows]

    def close(self) -> None:
        with self._lock:
            if self._db is not None:
                self._db.close()
                self._db = None
