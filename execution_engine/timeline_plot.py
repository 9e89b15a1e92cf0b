"""Drawing a :class:`~execution_engine.timeline.Timeline` as the paper's Fig. 12, with matplotlib.

One row per group; each function a bar in the colour of the state it spent most time in, edged
by its outcome, its primitives as slimmer bars inside it, the dry run's planned duration as a
thin bar under it (when the timeline has a plan), a retry labelled with its attempt; the critical
path (:mod:`.timeline_path`) outlined in red; idle gaps hatched, flag and zone waits named after
whom they waited on ("waiting for flag X set by left_arm"); operation boundaries as dashed lines
labelled with the operation; errors and operator actions as markers; run time in seconds, or
min:s past a minute, as the studio's axis.
SVG or PNG, by the file's extension.  Bars of one look are one collection and labels are capped,
so drawing costs in proportion to the run's length (a 3 MB trace of 13,000 operations took 55 s
with an artist per bar); names from the record are drawn with their control characters escaped.
"""
from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: never a window, works without a display

import matplotlib.pyplot as plt  # noqa: E402 - after choosing the back end
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from core_functions.printable import printable  # noqa: E402
from execution_engine.timeline import STATE_COLOURS, Lane, Timeline  # noqa: E402
from execution_engine.timeline_path import critical_path  # noqa: E402

FORMATS = (".svg", ".png")
#: Text labels drawn per lane and for the operations at most: each is an artist of its own, and past a
#: few hundred they overlap anyway (every bar and operation is still drawn).
MAX_LABELS = 300


def plot_timeline(timeline: Timeline, path: str | Path, title: str = "") -> Path:
    """Write the figure to ``path`` (.svg or .png); ValueError for another extension."""
    out = Path(path)
    if out.suffix.lower() not in FORMATS:
        raise ValueError(f"{out}: the timeline is written as .svg or .png")
    groups = list(timeline.lanes)
    span = max(timeline.t_end - timeline.t_start, 1e-6)
    with matplotlib.rc_context({"svg.fonttype": "none"}):  # SVG text stays text: searchable, selectable
        _draw(timeline, out, title, groups, span)
    return out


def _draw(timeline: Timeline, out: Path, title: str, groups: list[str], span: float) -> None:
    figure, axes = plt.subplots(figsize=(max(8.0, min(24.0, span / 4)), 1.2 + 0.9 * len(groups)))
    try:
        used: set[str] = set()
        waited = False
        critical = {step.bar.id for step in critical_path(timeline)}
        for row, group in enumerate(groups):
            waited = _lane(axes, timeline.lanes[group], len(groups) - 1 - row, span, timeline.t_end, used, critical) or waited
        _operations(axes, timeline, len(groups), span)
        _marks(axes, timeline, groups)
        axes.set_yticks(range(len(groups)), [printable(g) for g in reversed(groups)])
        axes.set_xlim(timeline.t_start, timeline.t_start + span * 1.01)
        axes.set_ylim(-0.6, len(groups) + 0.3)
        if timeline.t_end >= 60:  # as the studio's axis: min:s past a minute
            axes.xaxis.set_major_formatter(FuncFormatter(lambda t, _: f"{'-' if t < 0 else ''}{int(abs(t) // 60)}:{abs(t) % 60:02.0f}"))
        axes.set_xlabel("run time (min:s)" if timeline.t_end >= 60 else "run time (s)")
        axes.set_title(printable(title) or "timeline")
        handles = [Patch(color=STATE_COLOURS[s], label=s) for s in STATE_COLOURS if s in used]
        handles.append(Patch(facecolor="#f4f4f4", edgecolor="#cccccc", hatch="//", label="idle"))
        if waited:
            handles.append(Patch(facecolor="#fff2cc", edgecolor="#c9a227", hatch="..", label="waiting (flag, zone)"))
        if critical:
            handles.append(Patch(facecolor="none", edgecolor="#d50000", linewidth=2, label="critical path"))
        if any(bar.planned is not None for lane in timeline.lanes.values() for bar in lane.bars):
            handles.append(Patch(color="#263238", label="planned (dry run)"))
        axes.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
        figure.tight_layout()
        figure.savefig(out)
    finally:
        plt.close(figure)


def _lane(axes: Axes, lane: Lane, y: float, span: float, t_end: float, used: set[str], critical: set[str]) -> bool:
    """One group's row: one collection per look (not an artist per bar: a long run has tens of thousands),
    a label on what is wide enough to hold one, at most MAX_LABELS.  True when the group waited for a flag or zone."""
    plain = [(g.t_start, g.duration) for g in lane.idle if not g.waiting]
    waits = [g for g in lane.idle if g.waiting]
    axes.broken_barh(plain, (y - 0.25, 0.5), facecolor="#f4f4f4", edgecolor="#cccccc", hatch="//", linewidth=0.3)
    bars: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    steps: dict[str, list[tuple[float, float]]] = defaultdict(list)
    path: list[tuple[float, float]] = []
    planned: list[tuple[float, float]] = []
    labels: list[tuple[float, float, str, str]] = []  # x, y, text, vertical alignment
    for bar in lane.bars:
        end = bar.end(t_end)
        used.add(bar.state)
        bars[(bar.colour, bar.edge)].append((bar.t_start, end - bar.t_start))
        if bar.id in critical:
            path.append((bar.t_start, end - bar.t_start))
        if bar.planned is not None and bar.attempt == 1:
            planned.append((bar.t_start, bar.planned))
        for primitive in bar.primitives:
            stop = primitive.t_end if primitive.t_end is not None else end
            used.add(primitive.state)
            steps[primitive.colour].append((primitive.t_start, max(stop - primitive.t_start, span * 1e-4)))
        if end - bar.t_start > span / 40:
            labels.append((bar.t_start + (end - bar.t_start) / 2, y + 0.42, bar.function + (f" (attempt {bar.attempt})" if bar.attempt > 1 else ""), "bottom"))
    for (colour, edge), ranges in bars.items():
        axes.broken_barh(ranges, (y - 0.35, 0.7), facecolor=colour, alpha=0.35, edgecolor=edge, linewidth=1.2)
    for colour, ranges in steps.items():
        axes.broken_barh(ranges, (y - 0.18, 0.36), facecolor=colour, linewidth=0)
    # over the bars: a zone wait lies inside its function (the motion held), and is idle time all the same
    axes.broken_barh([(g.t_start, g.duration) for g in waits], (y - 0.25, 0.5), facecolor="#fff2cc", edgecolor="#c9a227", hatch="..", linewidth=0.5)
    for ranges, box, look in ((path, (y - 0.38, 0.76), {"facecolor": "none", "edgecolor": "#d50000", "linewidth": 2.0}),
                              (planned, (y - 0.47, 0.07), {"facecolor": "#263238", "linewidth": 0})):
        if ranges:  # one collection each, and none for a lane without
            axes.broken_barh(ranges, box, **look)
    labels += [(g.t_start + g.duration / 2, y, g.label, "center") for g in waits if g.duration > span / 40]
    for x, at, text, align in labels[:MAX_LABELS]:
        axes.text(x, at, printable(text), ha="center", va=align, fontsize=6, clip_on=True)
    return bool(waits)


def _operations(axes: Axes, timeline: Timeline, rows: int, span: float) -> None:
    """Each operation's start as a dashed line; a label where it has room (a span/100 from the last one), at most MAX_LABELS."""
    starts = [operation.t_start for operation in timeline.operations]
    if starts:
        axes.vlines(starts, -0.6, rows + 0.3, colors="#555555", linestyles="--", linewidth=0.6)
    shown, last = 0, -math.inf
    for operation in timeline.operations:
        if shown < MAX_LABELS and operation.t_start - last >= span / 100:
            made = f" ({printable(operation.iteration.split(' > ')[-1])})" if operation.iteration else ""  # the innermost loop's
            axes.text(operation.t_start, rows - 0.45, f"op {printable(operation.id)}{made}", fontsize=6, rotation=90, va="bottom", ha="right", color="#555555")
            shown, last = shown + 1, operation.t_start


def _marks(axes: Axes, timeline: Timeline, groups: list[str]) -> None:
    """Errors (x), operator actions (v) and tested functions' outcomes (o), one collection each."""
    rows = {group: len(groups) - 1 - row for row, group in enumerate(groups)}
    points: dict[str, tuple[list[float], list[float]]] = {"error": ([], []), "operator": ([], []), "outcome": ([], [])}
    for mark in timeline.marks:
        if mark.kind in points:
            points[mark.kind][0].append(mark.t)
            points[mark.kind][1].append(rows.get(mark.group, len(groups) - 0.5))
    for kind, (xs, ys) in points.items():
        if xs:
            marker = {"error": "x", "operator": "v"}.get(kind, "o")
            axes.plot(xs, ys, linestyle="none", marker=marker, color="#d62728" if kind == "error" else "#000000", markersize=7, fillstyle="none")
