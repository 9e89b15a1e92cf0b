"""Named joint trajectories kept in SQLite (paper Table 1: "stored in a database for a future use").

A trajectory is recorded once (planned or taught) and replayed many times, across runs and
restarts, so it lives in a file, not in memory.  One row per (group, name); recording a name
again replaces it, and the row keeps when and how it was made, so an integrator can tell a
taught path from a planned one.
"""
from __future__ import annotations

import json
import sqlite3
import threading
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


@dataclass(frozen=True)
class StoredTrajectory:
    group: str
    name: str
    trajectory: TrajectoryResult
    source: str  # "plan" or "teach"
    recorded_at: float  # run-clock seconds of the recording


class TrajectoryStore:
    """A small SQLite table of trajectories; ``":memory:"`` for a throw-away store."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        if self.path != ":memory:":
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(self.path, check_same_thread=False)
        with self._lock, self._db:
            self._db.execute(_SCHEMA)

    def save(self, group: str, name: str, trajectory: TrajectoryResult, source: str, recorded_at: float) -> None:
        if not trajectory.points:
            raise ValueError(f"trajectory {name!r} of {group} has no points")
        with self._lock, self._db:
            self._db.execute(
                "INSERT OR REPLACE INTO trajectories VALUES (?, ?, ?, ?, ?, ?, ?)",
                (
                    group,
                    name,
                    json.dumps(list(trajectory.joint_names)),
                    json.dumps([list(p) for p in trajectory.points]),
                    json.dumps(list(trajectory.times)),
                    source,
                    recorded_at,
                ),
            )

    def load(self, group: str, name: str) -> StoredTrajectory:
        with self._lock:
            row = self._db.execute(
                "SELECT joint_names, points, times, source, recorded_at FROM trajectories WHERE grp = ? AND name = ?",
                (group, name),
            ).fetchone()
        if row is None:
            known = ", ".join(self.names(group)) or "none"
            raise KeyError(f"no trajectory {name!r} recorded for {group} in {self.path} (recorded: {known})")
        joint_names, points, times, source, recorded_at = row
        trajectory = TrajectoryResult(
            joint_names=tuple(json.loads(joint_names)),
            points=tuple(tuple(float(v) for v in p) for p in json.loads(points)),
            times=tuple(float(t) for t in json.loads(times)),
        )
        return StoredTrajectory(group, name, trajectory, source, float(recorded_at))

    def names(self, group: str) -> list[str]:
        with self._lock:
            rows = self._db.execute("SELECT name FROM trajectories WHERE grp = ? ORDER BY name", (group,)).fetchall()
        return [r[0] for r in rows]

    def close(self) -> None:
        with self._lock:
            self._db.close()
