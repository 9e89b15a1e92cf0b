"""The critical path of a run: the chain of functions, across groups, that made the cycle as long as it was.

Walked backwards from the function that ended last.  What let a function end when it did is, in
this order: a flag or zone wait inside it (a zone holds a function before its motion; in lock-step
a wait_flag is a function) -- then the group that set the flag or left the zone is on the path; a
named wait right before it on its lane -- the same; otherwise what let it start: its own group's
previous function, when that ended about when it started (the group simply went on), or else the
function of any group that ended last before it started (an operation's barrier in lock-step: the
next operation starts when the slowest group of this one is done).  Shortening a function off the
path does not shorten the cycle; shortening one on it does, until another chain takes over.

Only the timeline's own times are used, so the path is the same for a live run, a trace, a
recording and any prefix of them a replay's slider cuts.  Linear in the run's length but for a
sort and a binary search per step.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from execution_engine.timeline import FunctionBar, IdleGap, Timeline

#: Run seconds within which an end and a start count as one instant: the engine takes a few
#: milliseconds from a result to the next request (more under a loaded wall clock).
TOLERANCE = 0.05


@dataclass(frozen=True)
class PathStep:
    """A function on the critical path and how the one after it depended on it."""

    bar: FunctionBar
    via: str  # how the next step (later in time) waited on this one: "" (the last), "then", "flag X", "zone Z", "barrier"
    wait: IdleGap | None = None  # the wait of the next step that this one ended (a flag set, a zone left)


def critical_path(timeline: Timeline, tolerance: float = TOLERANCE) -> list[PathStep]:
    """The critical path in time order (empty for a timeline without functions)."""
    bars = [bar for lane in timeline.lanes.values() for bar in lane.bars]
    if not bars:
        return []
    now = timeline.t_end
    by_end = sorted(bars, key=lambda b: b.end(now))
    ends = [b.end(now) for b in by_end]
    lanes = {group: sorted(lane.bars, key=lambda b: b.t_start) for group, lane in timeline.lanes.items()}
    starts = {group: [b.t_start for b in lane] for group, lane in lanes.items()}
    waits = {group: sorted((g for g in lane.idle if g.waiting), key=lambda g: g.t_end) for group, lane in timeline.lanes.items()}
    wait_ends = {group: [g.t_end for g in gaps] for group, gaps in waits.items()}

    def releaser(gap: IdleGap) -> FunctionBar | None:
        """The function of the group the wait waited on that was running (or had just ended) when it ended."""
        if gap.by is None or gap.by not in lanes:
            return None
        at = gap.released if gap.released is not None else gap.t_end
        index = bisect.bisect_left(starts[gap.by], at) - 1  # one that started at that very instant did not release it
        if index < 0:
            index = bisect.bisect_right(starts[gap.by], at) - 1
        return lanes[gap.by][index] if index >= 0 else None

    def last_wait(group: str, after: float, before: float) -> IdleGap | None:
        """The group's latest named wait ending in (after, before]."""
        index = bisect.bisect_right(wait_ends[group], before) - 1
        if index >= 0 and waits[group][index].t_end > after:
            return waits[group][index]
        return None

    def before(bar: FunctionBar) -> tuple[FunctionBar, str, IdleGap | None] | None:
        own = lanes[bar.group]
        index = bisect.bisect_left(starts[bar.group], bar.t_start)
        while index < len(own) and own[index] is not bar:
            index += 1
        previous = own[index - 1] if index > 0 else None
        gap = last_wait(bar.group, previous.end(now) if previous is not None else -math.inf, bar.end(now))
        if gap is not None and gap.t_end >= bar.t_start - tolerance:  # a wait inside it, or right before it
            source = releaser(gap)
            if source is not None and source is not bar and source.t_start < bar.end(now):
                return source, str(gap.waiting), gap
        latest = bisect.bisect_right(ends, bar.t_start + 1e-9) - 1
        while latest >= 0 and by_end[latest] is bar:
            latest -= 1
        if latest < 0:
            return (previous, "then", None) if previous is not None else None
        other = by_end[latest]
        if previous is not None and previous.end(now) >= other.end(now) - tolerance:
            return previous, "then", None
        return other, "barrier", None

    path: list[PathStep] = []
    current, via, wait = by_end[-1], "", None
    seen: set[int] = set()
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        path.append(PathStep(current, via, wait))
        found = before(current)
        if found is None:
            break
        current, via, wait = found
    path.reverse()
    return path


def path_ids(path: list[PathStep]) -> list[str]:
    """The bar ids of a path, in time order (what the page marks)."""
    return [step.bar.id for step in path]
