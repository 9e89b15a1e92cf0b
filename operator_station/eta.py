"""The time left of a run: in run time, and in the wall time it will take at the clock's speed.

The estimate is the dry run's plan (each operation's planned seconds, :func:`execution_engine.run_plan.operation_durations`)
of what is still to run: the operations after the current one whole, the current one less the run time it has
worked so far (never below zero); the current one is the earliest a group is still working in (sync="flags"
lets a group run ahead: the run is as far as its slowest group).  Every time in it is *run time* -- the trace's ``t``, the plan's seconds --
and only the last step turns it into wall seconds, by the speed of the clock the run is on: at ``--speed 10``
85 s of robot work is 8.5 s to wait.  (The top bar used to show the run seconds as the time to wait, and
froze between records: at ``--speed 10`` it said ten times too long.)

A pause stops the current operation's clock: time paused (or waiting at an alarm) is not work done, so the
estimate holds still while paused and goes on from there on resume.

The operator's speed override changes the pace too: the plan is the dry run's at the override the run started with,
and each change (the trace's ``speed_override`` records, with their ``percent``) makes a run second worth that
share of a planned one -- at 50 % of a start at 100 % the rest takes twice as long, work done counts half.  At 0 %
every motion holds on its path: like a pause, the estimate holds.  Motions scale with the override, dwells and
camera captures do not, so between the two this overestimates what is left of an operation that is mostly waiting.

Its error is bounded by the dry run's own: in lock-step, at any instant, |ETA - time actually left| is at most
the sum over the current and later operations of |planned - actual| seconds (test/test_eta.py checks it at a
scaled speed, and the sync="flags" variant within the whole run's such error).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: Engine states in which the run does no work: the current operation's clock stands still.
HELD = ("paused", "alarm", "error")
#: Engine states after which nothing is left.
ENDED = ("finished", "failed", "stopped")


@dataclass(frozen=True)
class Eta:
    """One estimate: ``remaining`` run seconds left as of run time ``t``; the wall seconds at ``speed``."""

    t: float
    remaining: float
    speed: float  # run seconds per wall second of the run's clock (math.inf: simulated time, no wait)
    planned: float  # the dry run's predicted cycle time (the plan's total)
    operation: int  # 1-based index of the operation running, 0 before the first
    held: bool = False  # paused or at an alarm: the estimate stands still until the run goes on

    @property
    def wall(self) -> float:
        """Wall seconds left at the clock's speed."""
        return 0.0 if math.isinf(self.speed) else self.remaining / self.speed

    def to_json(self) -> dict[str, Any]:
        return {"t": self.t, "remaining": self.remaining, "wall": self.wall, "speed": None if math.isinf(self.speed) else self.speed,
                "planned": self.planned, "operation": self.operation, "held": self.held}


class EtaTracker:
    """Fed the run's records in order; :meth:`at` estimates at any run time after the last one seen.

    The operation the estimate counts from is the earliest one a group is working in: with sync="flags" a
    group runs ahead (the head moves to its last pose while the arms are still at the first holes), and the
    run is as far as its slowest group.  Between operations (no group in a function) it is the latest started."""

    def __init__(self, plan: Sequence[float], operations: Sequence[str], start_percent: float = 100.0) -> None:
        """``plan``: planned seconds per operation (the dry run's at ``start_percent``); ``operations``: their ids, in
        the same order."""
        self.plan = [max(0.0, float(p)) for p in plan]
        self.start_percent = start_percent if start_percent > 0 else 100.0
        self.paces: list[tuple[float, float]] = [(-math.inf, 1.0)]  # (from run time, planned seconds per run second)
        self.index = {op: i for i, op in enumerate(operations)}
        self.starts: dict[int, float] = {}  # operation index -> run time its first function started
        self.working: dict[str, int] = {}  # group -> index of the operation of the function it is in
        self.latest = -1  # index of the latest operation started
        self.holds: list[list[float]] = []  # [from, to] of each pause or alarm (to: inf while it lasts)
        self.ended = False

    def see(self, record: Mapping[str, Any]) -> None:
        event, t, group = record.get("event"), float(record.get("t", 0.0)), str(record.get("group"))
        if event == "function_start":
            i = self.index.get(str(record.get("operation")), -1)
            if i >= 0:
                self.starts.setdefault(i, t)
                self.working[group] = i
                self.latest = max(self.latest, i)
        elif event == "function_end":
            self.working.pop(group, None)
        elif event == "engine_state":
            state = record.get("to")
            holding = bool(self.holds) and math.isinf(self.holds[-1][1])
            if state in HELD and not holding:
                self.holds.append([t, math.inf])
            elif state not in HELD and holding:
                self.holds[-1][1] = t
            if state in ENDED:
                self.ended = True
        elif event == "run_end":
            self.ended = True
        elif event == "operator" and record.get("command") == "speed_override" and record.get("accepted") and "percent" in record:
            self.paces.append((t, max(0.0, float(record["percent"])) / self.start_percent))

    def current(self) -> int:
        """Index of the operation the estimate counts from (-1 before the first)."""
        return min(self.working.values()) if self.working else self.latest

    def held(self, since: float, now: float) -> float:
        """Run seconds held (paused, at an alarm) between ``since`` and ``now``."""
        return sum(max(0.0, min(b, now) - max(a, since)) for a, b in self.holds)

    def worked(self, since: float, now: float) -> float:
        """Planned seconds of work done between ``since`` and ``now``: each run second not held, at its pace."""
        done = 0.0
        for i, (start, pace) in enumerate(self.paces):
            end = self.paces[i + 1][0] if i + 1 < len(self.paces) else math.inf
            a, b = max(start, since), min(end, now)
            if b > a:
                done += pace * (b - a - self.held(a, b))
        return done

    def at(self, now: float, speed: float) -> Eta | None:
        """The estimate at run time ``now`` (at or after the last record seen); None without a plan."""
        if not self.plan:
            return None
        planned = sum(self.plan)
        pace = self.paces[-1][1]
        holding = (bool(self.holds) and math.isinf(self.holds[-1][1])) or pace == 0.0
        per = 1.0 / pace if pace > 0 else 1.0  # run seconds per planned second from now on (at 0 %: held, as planned)
        current = self.current()
        if self.ended:
            return Eta(now, 0.0, speed, planned, current + 1)
        if current < 0:
            return Eta(now, planned * per, speed, planned, 0, holding)
        started = self.starts[current]
        left = max(0.0, self.plan[current] - self.worked(started, now)) + sum(self.plan[current + 1:])
        return Eta(now, left * per, speed, planned, current + 1, holding)


class EtaFeed:
    """The station's side: the records the page gets, the feed's plan and operations, the run's clock -> ``eta`` in the feed.

    An estimate is pushed whenever an operation starts or the engine changes state; between them the page
    counts the wall seconds down itself (the speed is in the estimate)."""

    def __init__(self, feed: Any, clock: Any, start_percent: float = 100.0) -> None:
        self.feed = feed
        self.clock = clock
        self.start_percent = start_percent  # the speed override the run starts at, which its dry run planned
        self.tracker: EtaTracker | None = None

    def see(self, record: Mapping[str, Any]) -> None:
        if self.tracker is None:
            snapshot = self.feed.snapshot
            self.tracker = EtaTracker(snapshot.plan, [str(op.get("id")) for op in snapshot.operations], self.start_percent)
        self.tracker.see(record)
        if record.get("event") in ("function_start", "engine_state", "run_end") or record.get("command") == "speed_override":
            eta = self.tracker.at(float(record.get("t", 0.0)), wall_speed(self.clock))
            if eta is not None:
                self.feed.update(eta=eta.to_json())


def wall_speed(clock: Any) -> float:
    """Run seconds per wall second of ``clock``: its speed factor; ``--speed max`` (simulated time at 1) has no
    wall time to wait (inf).  A simulated clock at another factor is a test's: its loop's time is the wall."""
    return math.inf if clock.simulated and clock.speed == 1.0 else float(clock.speed)
