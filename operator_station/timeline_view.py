"""The timeline the page draws: :mod:`execution_engine.timeline`'s model of the feed's records, as JSON.

The model is the project's one timeline (the run report draws the same); this module only feeds
it and flattens a snapshot for the browser.  Live, one builder folds the records as they come
(each record once); for a replay's time slider the records up to that instant are folded afresh.
"""
from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

from execution_engine.timeline import STATE_COLOURS, Timeline, TimelineBuilder
from operator_station.feed import Feed


def timeline_json(timeline: Timeline, groups: Sequence[str], records: int, total_end: float) -> dict[str, Any]:
    order = [*groups, *(g for g in timeline.lanes if g not in groups)]
    lanes: dict[str, list[dict[str, Any]]] = {}
    for group in order:
        lane = timeline.lanes.get(group)
        lanes[group] = [] if lane is None else [{
            "operation": bar.operation, "function": bar.function, "start": bar.t_start, "end": bar.end(timeline.t_end),
            "open": bar.t_end is None, "state": bar.state, "colour": bar.colour, "edge": bar.edge, "outcome": bar.outcome,
            "attempt": bar.attempt, "error": bar.error,
            "primitives": [{"primitive": p.name, "state": p.state, "colour": p.colour, "start": p.t_start,
                            "end": p.t_end if p.t_end is not None else timeline.t_end, "outcome": p.outcome} for p in bar.primitives],
        } for bar in lane.bars]
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
            if until is not None:
                shown = [r for r in records if float(r.get("t", 0.0)) <= until]
                return timeline_json(TimelineBuilder(snapshot.groups).add_all(shown).snapshot(until), snapshot.groups, len(shown), total_end)
            if snapshot.run != self._run:
                self._run, self._builder, self._folded = snapshot.run, TimelineBuilder(snapshot.groups), 0
            self._builder.add_all(records[self._folded:])
            self._folded = len(records)
            status_t = float((snapshot.status or {}).get("t") or 0.0) if not snapshot.ended else None
            return timeline_json(self._builder.snapshot(status_t), snapshot.groups, len(records), total_end)
