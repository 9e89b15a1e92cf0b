"""Drawing a :class:`~execution_engine.timeline.Timeline` as the paper's Fig. 12, with matplotlib.

One row per group; each function a bar in the colour of the state it spent most time in, edged
by its outcome, its primitives as slimmer bars inside it; idle gaps hatched; operation
boundaries as dashed lines labelled with the operation; errors and operator actions as markers.
SVG or PNG, by the file's extension.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: never a window, works without a display

import matplotlib.pyplot as plt  # noqa: E402 - after choosing the back end
from matplotlib.patches import Patch  # noqa: E402

from execution_engine.timeline import STATE_COLOURS, Timeline  # noqa: E402

FORMATS = (".svg", ".png")


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
        for row, group in enumerate(groups):
            lane = timeline.lanes[group]
            y = len(groups) - 1 - row
            for gap in lane.idle:
                if gap.waiting:  # sync="flags": a wait for a flag or zone, named on the bar
                    waited = True
                    axes.barh(y, gap.duration, left=gap.t_start, height=0.5, color="#fff2cc", edgecolor="#c9a227", hatch="..", linewidth=0.5)
                    if gap.duration > span / 40:
                        axes.text(gap.t_start + gap.duration / 2, y, f"waiting for {gap.waiting}", ha="center", va="center", fontsize=6, clip_on=True)
                    continue
                axes.barh(y, gap.duration, left=gap.t_start, height=0.5, color="#f4f4f4", edgecolor="#cccccc", hatch="//", linewidth=0.3)
            for bar in lane.bars:
                end = bar.end(timeline.t_end)
                used.add(bar.state)
                axes.barh(y, end - bar.t_start, left=bar.t_start, height=0.7, color=bar.colour, alpha=0.35, edgecolor=bar.edge, linewidth=1.2)
                for primitive in bar.primitives:
                    stop = primitive.t_end if primitive.t_end is not None else end
                    used.add(primitive.state)
                    axes.barh(y, max(stop - primitive.t_start, span * 1e-4), left=primitive.t_start, height=0.36, color=primitive.colour, linewidth=0)
                if end - bar.t_start > span / 40:
                    axes.text(bar.t_start + (end - bar.t_start) / 2, y + 0.42, bar.function, ha="center", va="bottom", fontsize=6, clip_on=True)
        for operation in timeline.operations:
            axes.axvline(operation.t_start, color="#555555", linestyle="--", linewidth=0.6)
            axes.text(operation.t_start, len(groups) - 0.45, f"op {operation.id}", fontsize=6, rotation=90, va="bottom", ha="right", color="#555555")
        for mark in timeline.marks:
            if mark.kind == "engine_state":
                continue
            row = groups.index(mark.group) if mark.group in groups else None
            y = len(groups) - 1 - row if row is not None else len(groups) - 0.5
            axes.plot(mark.t, y, marker="x" if mark.kind == "error" else "v", color="#d62728" if mark.kind == "error" else "#000000", markersize=7)
        axes.set_yticks(range(len(groups)), list(reversed(groups)))
        axes.set_xlim(timeline.t_start, timeline.t_start + span * 1.01)
        axes.set_ylim(-0.6, len(groups) + 0.3)
        axes.set_xlabel("run time (s)")
        axes.set_title(title or "timeline")
        handles = [Patch(color=STATE_COLOURS[s], label=s) for s in STATE_COLOURS if s in used]
        handles.append(Patch(facecolor="#f4f4f4", edgecolor="#cccccc", hatch="//", label="idle"))
        if waited:
            handles.append(Patch(facecolor="#fff2cc", edgecolor="#c9a227", hatch="..", label="waiting (flag, zone)"))
        axes.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
        figure.tight_layout()
        figure.savefig(out)
    finally:
        plt.close(figure)
