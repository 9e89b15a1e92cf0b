"""The console's log: each kind of warning once, then at most one line per kind and second, with a count.

A warning that repeats -- the KUKA RSI controller counting another late reply, every cycle a busy
computer holds the loop back -- is one fact, not hundreds of lines: a run on a loaded machine that
finished printed 519 of them and buried the one line that said why.  So the command line's log
handler passes the first record of a kind at once (a first warning is never delayed), holds the
others of that kind for a window (1 s), and at the window's end prints the latest of them once
with the number it stands for: ``WARNING robot_bridges.kuka_rsi.backend: kuka_rsi ...: the
controller counts 519 late replies (IPOC 3741927000) (x137 in the last 1 s)``.  While the kind
keeps coming that is one line a second; after a quiet window the next one is printed at once
again.  What is still held when the command ends is printed then.

Every process of ours prints its log this way: each command of the command line
(:class:`ConsoleLog`), each node process -- under ``launch`` or ``ros2 run`` -- whether it prints
its own log (over DDS: :func:`node_console`) or hands it to rcutils under rclpy
(:mod:`node_transport.ros_logging` aggregates before it forwards), and the operator
station, whose web server logs through the root logger.  So a bridge flooding a warning under
``launch`` is one line a second there too, not the flood.

A *kind* is the logger, the level and the message with its numbers masked: the same warning with
another count, time, IPOC or port is the same kind; two different warnings never are.  The
window's end is kept by a :class:`~node_transport.wall_clock.WallClock` (tests move a
:class:`~node_transport.wall_clock.ManualWallClock`), so nothing here sleeps.
"""
from __future__ import annotations

import copy
import logging
import re
from dataclasses import dataclass
from typing import IO

from node_transport.wall_clock import RealWallClock, WallClock, WallTimer

FORMAT = "%(levelname)s %(name)s: %(message)s"
NODE_FORMAT = "[%(levelname)s] [%(name)s]: %(message)s"  # a node process's lines, as rcutils prints them
WINDOW = 1.0  # s: at most one line per kind in this time
MAX_KINDS = 1000  # kinds remembered at once; beyond it, records pass as they come (memory stays bounded)
#: A record logged with ``extra={ONCE: True}`` states a fact (what an RSI configuration lacks): printed the first
#: time its kind comes, never again in this console -- a checked run starts a back end more than once.
ONCE = "console_once"

_NUMBER = re.compile(r"\d+(?:[.,]\d+)*")


def kind_of(record: logging.LogRecord) -> tuple[str, int, str]:
    """What makes two records "the same warning": logger, level, message without its numbers."""
    try:
        text = record.getMessage()
    except Exception:  # noqa: BLE001 - a record whose args do not fit its format: its template is its kind
        text = str(record.msg)
    return record.name, record.levelno, _NUMBER.sub("#", text)


@dataclass
class _Kind:
    opened: float  # wall time the kind's current window began
    held: int = 0  # records of the kind in this window not printed one by one
    last: logging.LogRecord | None = None  # the latest of them: printed for all


class AggregatingHandler(logging.Handler):
    """Hands records to ``target``: the first of each kind at once, the rest as one counted line per window."""

    def __init__(self, target: logging.Handler, window: float = WINDOW, wall_clock: WallClock | None = None) -> None:
        super().__init__(logging.NOTSET)
        self.target = target
        self.window = window
        self.wall_clock: WallClock = wall_clock or RealWallClock()
        self._kinds: dict[tuple[str, int, str], _Kind] = {}
        self._timer: WallTimer | None = None
        self.held_total = 0  # records not printed one by one (for tests and the curious)
        self._once: set[tuple[str, int, str]] = set()  # the kinds of facts said already (ONCE)

    def emit(self, record: logging.LogRecord) -> None:
        now = self.wall_clock.now()
        self._flush(now, everything=False)
        key = kind_of(record)
        if getattr(record, ONCE, False):  # a fact, not an event: said once in this console, never counted
            if key not in self._once and len(self._once) < MAX_KINDS:
                self._once.add(key)
                self.target.handle(record)
            return
        kind = self._kinds.get(key)
        if kind is None:
            if len(self._kinds) < MAX_KINDS:
                self._kinds[key] = _Kind(opened=now)
            self.target.handle(record)
            return
        kind.held += 1
        kind.last = record
        self.held_total += 1
        self._arm(kind.opened + self.window - now)

    def flush(self) -> None:
        """Print what is held whose window has ended; then the target's flush."""
        with self._locked():
            self._flush(self.wall_clock.now(), everything=False)
        self.target.flush()

    def close(self) -> None:
        """Print everything still held (the command is ending), stop the timer; the target stays open."""
        with self._locked():
            self._flush(self.wall_clock.now(), everything=True)
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        self.target.flush()
        super().close()

    # ---------------------------------------------------------------------------- inside
    def _locked(self) -> _Lock:
        return _Lock(self)

    def _flush(self, now: float, everything: bool) -> None:
        for key, kind in list(self._kinds.items()):
            elapsed = now - kind.opened
            if elapsed < self.window and not everything:
                continue
            if kind.held and kind.last is not None:
                self.target.handle(self._counted(kind.last, kind.held, min(elapsed, self.window)))
                kind.held, kind.last, kind.opened = 0, None, now  # still coming: the next ones are held again
            else:
                del self._kinds[key]  # a quiet window: the next one is printed at once

    def _counted(self, record: logging.LogRecord, count: int, seconds: float) -> logging.LogRecord:
        line = copy.copy(record)
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - as the target would have shown it
            text = str(record.msg)
        line.msg, line.args = f"{text} (x{count} in the last {seconds:.3g} s)", None
        return line

    def _arm(self, delay: float) -> None:
        """One timer for the earliest window's end, so a held count is printed on time even if nothing else is logged."""
        if self._timer is not None:
            return
        self._timer = self.wall_clock.call_later(max(0.0, delay), self._due)

    def _due(self) -> None:
        with self._locked():
            self._timer = None
            now = self.wall_clock.now()
            self._flush(now, everything=False)
            pending = [k.opened + self.window - now for k in self._kinds.values() if k.held]
            if pending:
                self._arm(min(pending))


class _Lock:
    """The handler's own lock around work that does not come through :meth:`logging.Handler.handle`."""

    def __init__(self, handler: logging.Handler) -> None:
        self.handler = handler

    def __enter__(self) -> None:
        self.handler.acquire()

    def __exit__(self, *exc: object) -> None:
        self.handler.release()


class ConsoleLog:
    """The root logger's console output for one command: installed by the CLI, removed when it ends.

    Only what this installs is removed again (a test's capture handler, or an embedding program's
    own handlers, stay), and the root level is put back: each in-process ``main()`` logs to its own
    streams at its own ``-v``.
    """

    def __init__(self, stream: IO[str], verbose: bool = False, wall_clock: WallClock | None = None, window: float = WINDOW) -> None:
        target = logging.StreamHandler(stream)
        target.setFormatter(logging.Formatter(FORMAT))
        self.handler = AggregatingHandler(target, window, wall_clock)
        self.level = logging.INFO if verbose else logging.WARNING
        self._previous_level: int | None = None

    def __enter__(self) -> ConsoleLog:
        root = logging.getLogger()
        self._previous_level = root.level
        root.setLevel(self.level)
        root.addHandler(self.handler)
        return self

    def __exit__(self, *exc: object) -> None:
        root = logging.getLogger()
        root.removeHandler(self.handler)
        self.handler.close()
        if self._previous_level is not None:
            root.setLevel(self._previous_level)


def node_console(stream: IO[str], level: int, wall_clock: WallClock | None = None) -> AggregatingHandler:
    """The console of a node process that prints its own log (over DDS, where no rcutils prints it):
    on the root logger for the process's life, in rcutils' line format, each kind of warning once and
    then one counted line per kind and second.  logging's own shutdown at the process's exit closes it
    (before the stream's handler, made first), which prints what is still held."""
    target = logging.StreamHandler(stream)
    target.setFormatter(logging.Formatter(NODE_FORMAT))
    handler = AggregatingHandler(target, WINDOW, wall_clock)
    root = logging.getLogger()
    root.setLevel(level)
    root.addHandler(handler)
    return handler
