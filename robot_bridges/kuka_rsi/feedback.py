"""ITRA's saving thread: every timestamped feedback packet to a file, off the real-time path.

Writing to a file can stall for milliseconds, far more than a 4 ms cycle can spare.  So the loop
only appends a tuple to the robot's FIFO (``deque.append``: no lock, no I/O, never waits) and a
writer thread empties the FIFOs into one text file per robot.  The writer is woken every
:attr:`FeedbackLogger.batch` records rather than for each, and holds the GIL only to format a
batch.  Saving is off until enabled, per robot, and can be switched at run time.

A file starts with a header naming the columns and units; each line is one packet:
``t_us ipoc delay x y z a b c a1 a2 a3 a4 a5 a6`` -- the loop's receive time in microseconds of
the monotonic clock, the controller's IPOC, its late-packet count, the actual TCP (m; KUKA
A, B, C in rad) and the actual axes (rad).
"""
from __future__ import annotations

import math
import threading
from collections import deque
from pathlib import Path
from typing import TextIO

#: (t_ns, ipoc, delay, x, y, z, a, b, c, a1..a6) in protocol units (mm, deg), as the loop read them.
Record = tuple[float, ...]
HEADER = "# t_us ipoc delay x_m y_m z_m a_rad b_rad c_rad a1_rad a2_rad a3_rad a4_rad a5_rad a6_rad\n"
_DEG = math.pi / 180.0


def format_record(r: Record) -> str:
    t_ns, ipoc, delay = int(r[0]), int(r[1]), int(r[2])
    cart = (r[3] / 1000.0, r[4] / 1000.0, r[5] / 1000.0, r[6] * _DEG, r[7] * _DEG, r[8] * _DEG)
    axes = tuple(v * _DEG for v in r[9:15])
    return f"{t_ns / 1000.0:.1f} {ipoc} {delay} " + " ".join(f"{v:.9g}" for v in (*cart, *axes)) + "\n"


class _Switch:
    """A change of output file, queued in order with the records."""

    __slots__ = ("path",)

    def __init__(self, path: str | None) -> None:
        self.path = path


class FeedbackLogger:
    """Per-robot FIFOs and the writer thread that saves them."""

    batch = 32
    max_backlog = 2_000_000  # records per robot (over two hours at 4 ms) before dropping

    def __init__(self, robots: int) -> None:
        self._queues: list[deque[Record | _Switch]] = [deque() for _ in range(robots)]
        self._enabled = [False] * robots
        self._files: list[TextIO | None] = [None] * robots
        self._wake = threading.Event()
        self._closing = False
        self._pending = 0
        self.dropped = [0] * robots
        self.written = [0] * robots
        self.errors: deque[str] = deque(maxlen=16)
        self._thread = threading.Thread(target=self._run, name="rsi-feedback-writer", daemon=True)
        self._thread.start()

    @property
    def native_id(self) -> int:
        """The writer thread's kernel id (its scheduling class can be set)."""
        assert self._thread.native_id is not None
        return self._thread.native_id

    # ------------------------------------------------------------------ called by the loop
    def enabled(self, robot: int) -> bool:
        return self._enabled[robot]

    def push(self, robot: int, record: Record) -> None:
        """Queue one packet's record; O(1), never blocks, never raises."""
        queue = self._queues[robot]
        if len(queue) >= self.max_backlog:
            self.dropped[robot] += 1
            return
        queue.append(record)
        self._pending += 1
        if self._pending >= self.batch:
            self._pending = 0
            self._wake.set()

    def set_output(self, robot: int, path: str | None) -> None:
        """Start saving ``robot``'s packets to ``path`` (appending), or stop with None.

        The switch travels in the robot's FIFO, so records queued before it still go to the
        previous file and every record after it goes to the new one.
        """
        self._enabled[robot] = path is not None
        self._queues[robot].append(_Switch(path))
        self._wake.set()

    def flush(self) -> None:
        """Ask the writer to empty the FIFOs now (not waiting for a full batch)."""
        self._wake.set()

    def close(self, timeout: float = 5.0) -> None:
        self._closing = True
        self._wake.set()
        self._thread.join(timeout)

    # ------------------------------------------------------------------ the writer thread
    def _run(self) -> None:
        try:
            while True:
                self._wake.wait()  # bounded by close(), which sets the event
                self._wake.clear()
                self._drain()
                if self._closing:
                    self._drain()
                    return
        except Exception as error:  # noqa: BLE001 - the loop reports it; saving stops, the robot does not
            self.errors.append(f"the saving thread stopped: {type(error).__name__}: {error}")
            self._enabled = [False] * len(self._enabled)
        finally:
            for f in self._files:
                if f is not None:
                    f.close()

    def _drain(self) -> None:
        for robot, queue in enumerate(self._queues):
            lines: list[str] = []
            while queue:
                item = queue.popleft()
                if isinstance(item, _Switch):
                    self._write(robot, "".join(lines), len(lines))
                    lines = []
                    self._switch(robot, item.path)
                else:
                    lines.append(format_record(item))
            self._write(robot, "".join(lines), len(lines))

    def _write(self, robot: int, text: str, count: int) -> None:
        f = self._files[robot]
        if f is None or not count:
            return
        try:
            f.write(text)
            f.flush()
            self.written[robot] += count
        except OSError as error:
            self.errors.append(f"robot {robot}: cannot write feedback: {error}")

    def _switch(self, robot: int, path: str | None) -> None:
        old = self._files[robot]
        if old is not None:
            old.close()
            self._files[robot] = None
        if path is None:
            return
        try:
            target = Path(path)
            new = not target.exists() or target.stat().st_size == 0
            f = target.open("a", encoding="utf-8")
            if new:
                f.write(HEADER)
            self._files[robot] = f
        except OSError as error:
            self._enabled[robot] = False
            self.errors.append(f"robot {robot}: cannot open feedback file {path}: {error.strerror or error}")
