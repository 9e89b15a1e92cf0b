"""The timeline the page draws: :mod:`execution_engine.timeline`'s model of the feed's records, as JSON.

The model is the project's one timeline (the run report draws the same); this module only feeds
it and flattens a snapshot for the browser: the bars with their ids, retries, errors and planned
seconds (the dry run's, when the run had one), the waits named after whom they waited on, the
critical path as bar ids and each planned function against its actual time.  Live, one builder
folds the records as they come (each record once); for a replay's time slider the records up to
that instant are folded afresh, so the page shows only what had happened by then.
"""
from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

from execution_engine.timeline import STATE_COLOURS, Timeline, TimelineBuilder, plan_deltas
from execution_engine.timeline_path import critical_path
from operator_station.feed import Feed


def timeline_json(timeline: Timeline, groups: Sequence[str], records: int, total_end: float) -> dict[str, Any]:
    order = [*groups, *(g for g in timeline.lanes if g not in groups)]
    lanes: dict[str, list[dict[str, Any]]] = {}
    for group in order:
        lane = timeline.lanes.get(group)
        lanes[group] = [] if lane is None else [{
            "id": bar.id, "operation": bar.operation, "function": bar.function, "start": bar.t_start, "end": bar.end(timeline.t_end),
            "open": bar.t_end is None, "state": bar.state, "colour": bar.colour, "edge": bar.edge, "outcome": bar.outcome,
            "attempt": bar.attempt, "error": bar.error, "planned": bar.planned,
            "primitives": [{"primitive": p.name, "state": p.state, "colour": p.colour, "start": p.t_start,
                            "end": p.t_end if p.t_end is not None else timeline.t_end, "outcome": p.outcome} for p in bar.primitives],
        } for bar in lane.bars]
    path = critical_path(timeline)
    return {
        "groups": order,
        "start": timeline.t_start,
        "end": timeline.t_end,
        "total_end": max(total_end, timeline.t_end),
        "operations": [{"id": op.id, "start": op.t_start, "end": op.t_end if op.t_end is not None else timeline.t_end, "iteration": op.iteration}
                       for op in timeline.operations],
        "lanes": lanes,
        "idle": {g: timeline.idle_total(g) if g in timeline.lanes else timeline.t_end - timeline.t_start for g in order},
        "busy": {g: timeline.lanes[g].busy if g in timeline.lanes else 0.0 for g in order},
        "marks": [{"t": m.t, "kind": m.kind, "group": m.group, "text": m.text} for m in timeline.marks],
        "waits": {g: [{"start": w.t_start, "end": w.t_end, "waiting": w.waiting, "by": w.by, "outcome": w.outcome, "label": w.label}
                      for w in timeline.lanes[g].idle if w.waiting] if g in timeline.lanes else [] for g in order},
        "critical": [{"id": s.bar.id, "group": s.bar.group, "via": s.via, "start": s.bar.t_start, "end": s.bar.end(timeline.t_end),
                      "wait": None if s.wait is None else {"group": s.wait.group, "start": s.wait.t_start, "end": s.wait.t_end}} for s in path],
        "plan": [{"group": d.group, "operation": d.operation, "function": d.function, "planned": d.planned, "actual": d.actual,
                  "delta": d.delta, "attempts": d.attempts, "done": d.done} for d in plan_deltas(timeline)],
        "retries": timeline.retries,
        "records": records,
        "bars": sum(len(bars) for bars in lanes.values()),
        "colours": STATE_COLOURS,
    }


class TimelineView:
    """The live timeline of a feed: records folded once each, a snapshot per request."""

    def __init__(self, feed: Feed) -> None:
        self.feed = feed
        self._lock = threading.Lock()
        self._run = -1
        self._builder = TimelineBuilder()
        self._folded = 0

    def model(self, until: float | None = None) -> dict[str, Any]:
        with self._lock:
            snapshot, records, _, _ = self.feed.read(0, 0)
            total_end = max((float(r.get("t", 0.0)) for r in records), default=0.0)
            planned = planned_of(snapshot)
            if until is not None:
                shown = [r for r in records if float(r.get("t", 0.0)) <= until]
                return timeline_json(TimelineBuilder(snapshot.groups, planned).add_all(shown).snapshot(until), snapshot.groups, len(shown), total_end)
            if snapshot.run != self._run or (planned and not self._builder.planned):  # the plan arrives once the dry run is done
                self._run, self._builder, self._folded = snapshot.run, TimelineBuilder(snapshot.groups, planned), 0
            self._builder.add_all(records[self._folded:])
            self._folded = len(records)
            status_t = float((snapshot.status or {}).get("t") or 0.0) if not snapshot.ended else None
            return timeline_json(self._builder.snapshot(status_t), snapshot.groups, len(records), total_end)


def planned_of(snapshot: Any) -> dict[tuple[str, str], float]:
    """The dry run's seconds per function of the run the feed shows ((group, operation) -> s; empty: no plan)."""
    return {(str(p["group"]), str(p["operation"])): float(p["planned"]) for p in getattr(snapshot, "plan_functions", None) or []}

