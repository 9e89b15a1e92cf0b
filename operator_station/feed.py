"""What the pages are shown: every record of the run (or the replayed trace) in order, plus the latest state.

The run lives on its own thread and event loop (a simulated clock needs a loop of its own); the
web server reads from another.  The feed is the one place they meet: the run appends under a
lock and wakes the server's waiters with ``call_soon_threadsafe``; each page connection keeps
its own read position, so a slow page gets everything late rather than something never -- the
timeline in the page is the trace, record for record.
"""
from __future__ import annotations

import asyncio
import threading
from collections import deque
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any

#: Joint samples kept for the plots (a ring): 20 minutes at the 0.1 s sampling.
MAX_JOINT_SAMPLES = 12_000
#: Run seconds between two joint samples kept for the plots (the bridge publishes every 0.05 s).
JOINT_SAMPLE_PERIOD = 0.1


@dataclass
class Snapshot:
    """Everything a page needs besides the records."""

    run: int
    mode: str  # "idle" (nothing run yet), "live", "replay"
    app: str = ""
    groups: list[str] = field(default_factory=list)
    structures: dict[str, Any] = field(default_factory=dict)
    status: dict[str, Any] | None = None
    plan: list[float] = field(default_factory=list)  # planned seconds per operation (dry run)
    plan_functions: list[dict[str, Any]] = field(default_factory=list)  # group, operation, planned: seconds per function (dry run)
    operations: list[dict[str, Any]] = field(default_factory=list)  # id, name, calls per operation
    joint_names: list[str] = field(default_factory=list)
    messages: list[dict[str, Any]] = field(default_factory=list)  # why a run was refused or broke down
    ended: bool = False
    eta: dict[str, Any] | None = None  # the time left (operator_station/eta.py), pushed as operations start
    summary: dict[str, Any] | None = None  # the run summary once it has ended (operator_station/run_summary.py)


class Feed:
    """Records and state of one run at a time; thread-safe appends, asyncio waits."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.records: list[dict[str, Any]] = []
        self.joints: deque[list[float]] = deque(maxlen=MAX_JOINT_SAMPLES)
        self.joints_total = 0  # samples ever appended (the ring forgets the oldest)
        self.snapshot = Snapshot(run=0, mode="idle")
        self._waiters: set[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = set()
        self._last_joint_t = -1e300
        #: Told of every record as it is appended, on the appending thread (the audit of the cell's operators:
        #: operator_station/cell_audit.py); a tap must not raise.
        self.taps: list[Callable[[dict[str, Any]], None]] = []

    # ---------------------------------------------------------------------------- writing
    def begin(self, mode: str, app: str, groups: list[str], **fields: Any) -> int:
        """A new run (or replay): the pages start over."""
        with self._lock:
            self.records = []
            self.joints = deque(maxlen=MAX_JOINT_SAMPLES)
            self.joints_total = 0
            self._last_joint_t = -1e300
            self.snapshot = Snapshot(run=self.snapshot.run + 1, mode=mode, app=app, groups=list(groups), **fields)
            run = self.snapshot.run
        self.wake()
        return run

    def append(self, record: dict[str, Any]) -> None:
        with self._lock:
            self.records.append(record)
        for tap in self.taps:
            tap(record)
        self.wake()

    def update(self, **fields: Any) -> None:
        with self._lock:
            for key, value in fields.items():
                setattr(self.snapshot, key, value)
        self.wake()

    def structure(self, group: str, structure: dict[str, Any]) -> None:
        with self._lock:
            self.snapshot.structures = {**self.snapshot.structures, group: structure}
        self.wake()

    def joint_sample(self, t: float, positions: list[float], force: bool = False) -> None:
        """Keep a sample when ``JOINT_SAMPLE_PERIOD`` has passed since the last one kept."""
        with self._lock:
            if not force and t - self._last_joint_t < JOINT_SAMPLE_PERIOD:
                return
            self._last_joint_t = t
            self.joints.append([float(t), *map(float, positions)])  # (a back end's numpy values: the page gets JSON numbers)
            self.joints_total += 1
        self.wake()

    # ---------------------------------------------------------------------------- reading
    def read(self, records_from: int, joints_from: int) -> tuple[Snapshot, list[dict[str, Any]], list[list[float]], int]:
        """The snapshot, records from ``records_from``, joint samples from ``joints_from`` (those still kept), joint total."""
        with self._lock:
            records = self.records[records_from:]
            first_kept = self.joints_total - len(self.joints)
            start = max(joints_from, first_kept) - first_kept
            joints = list(self.joints)[start:] if start < len(self.joints) else []
            return self.snapshot, records, joints, self.joints_total

    # ---------------------------------------------------------------------------- waking
    def waiter(self) -> asyncio.Event:
        """An event set whenever anything changes; ``forget`` it when the page leaves."""
        event = asyncio.Event()
        with self._lock:
            self._waiters.add((asyncio.get_running_loop(), event))
        return event

    def forget(self, event: asyncio.Event) -> None:
        with self._lock:
            self._waiters = {(loop, e) for loop, e in self._waiters if e is not event}

    def wake(self) -> None:
        with self._lock:
            waiters = list(self._waiters)
        for loop, event in waiters:
            if event.is_set():  # not read yet: one wake-up is enough (a benign race: at worst one more)
                continue
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:  # that loop is closed: its page is gone
                self.forget(event)
