"""``python -m execution_engine report RUN.mcap|TRACE.jsonl``: what a run did, read back from its record.

The same summary whichever record is at hand -- a recording (:mod:`execution_engine.recorder`)
or a JSON-lines trace (:mod:`execution_engine.trace_report`), read as every reader of one reads it
(:mod:`execution_engine.record_reader`: bounded, one-line refusals): whether the record is whole or was
cut (and where), what ran (a recording says which application, robot, back end and version),
the operations, each group's busy and idle time, errors, retries, operator actions and vision
corrections; and the Fig. 12 timeline of every group as SVG or PNG (:mod:`.timeline_plot`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from cell_runner.output_files import FilePlan, Output, Refused
from cell_runner.settings import ReportSettings
from core_functions.printable import printable
from execution_engine.record_limits import TIME_BOUND
from execution_engine.record_reader import NotARecording, OverLimit, read_record
from execution_engine.run_plan import PlanReader, RunPlan
from execution_engine.timeline import Lane, Timeline, TimelineBuilder

EXIT_OK, EXIT_UNREADABLE, EXIT_USAGE, EXIT_OUTPUT = 0, 1, 2, 4  # as run's: a refused option 2, an output not written 4


@dataclass
class RunSummary:
    source: str
    header: list[str]  # what the record itself says: whole or cut, what ran
    timeline: Timeline
    cut: bool
    extra: list[str] = field(default_factory=list)  # errors and operator actions, for a recording
    plan: RunPlan | None = None  # the dry run's plan the run was checked against, when the record holds it

    def lines(self) -> list[str]:
        t = self.timeline
        out = list(self.header)
        done = sum(1 for o in t.operations if o.t_end is not None)
        out.append(f"  operations: {len(t.operations)} started, {done} complete; run time {t.t_end - t.t_start:.3f} s")
        if self.plan is not None:  # the cycle against the prediction, as the station's summary says it
            took = t.t_end - t.t_start
            where = "the simulator's start" if self.plan.basis == "start" else "the measured joints"
            out.append(f"  predicted: cycle {self.plan.cycle_time:.3f} s by the dry run from {where}; the run {took:.3f} s ({took - self.plan.cycle_time:+.3f} s)")
        made = [o for o in t.operations if o.iteration]
        if made:  # operations a loop or a call made: where the run got to, by iteration
            last = max(t.operations, key=lambda o: o.t_start)
            where = f"; the last started: {last.id}" + (f" ({last.iteration})" if last.iteration else "")
            out.append(f"  iterations: {len(made)} of them made by loops or calls{where}")
        for group, lane in t.lanes.items():
            total = max(t.t_end - t.t_start, 1e-9)
            failed = sum(1 for b in lane.bars if b.outcome in ("aborted", "preempted"))
            out.append(
                f"  {group:<12} busy {lane.busy:9.3f} s ({100 * lane.busy / total:5.1f} %), idle {t.idle_total(group):9.3f} s, "
                f"{len(lane.bars)} function(s)" + (f", {failed} failed" if failed else "")
            )
            waited = waits_of(lane)
            if waited:  # sync="flags": the idle time the waits for flags and zones account for
                rest = t.idle_total(group) - sum(waited.values())
                parts = ", ".join(f"waiting for {what} {d:.3f} s" for what, d in sorted(waited.items(), key=lambda kv: -kv[1]))
                out.append(f"  {'':<12} idle: {parts}, the rest {max(0.0, rest):.3f} s")
        out.append(f"  retries: {t.retries}")
        out.extend(f"  {m.kind}: {m.text}" for m in t.marks if m.kind in ("outcome", "branch"))  # which branch each <if> took
        out.extend(self.extra)
        out.extend(vision_lines(t))
        return [printable(line) for line in out]  # every name and text in them came from the file


def waits_of(lane: Lane) -> dict[str, float]:
    """The idle seconds of a lane each flag or zone wait accounts for (sync="flags"), by what it waited for
    (``flag part_ready``, ``zone hole_area``); the run summary of the studio names the costliest the same way."""
    waited: dict[str, float] = {}
    for gap in lane.idle:
        if gap.waiting:
            waited[gap.waiting] = waited.get(gap.waiting, 0.0) + gap.duration
    return waited


def vision_lines(timeline: Timeline) -> list[str]:
    """Every located feature: where vision found it (the corrected frame the next moves used)."""
    found: list[tuple[float, str]] = []
    for lane in timeline.lanes.values():
        for bar in lane.bars:
            for p in bar.primitives:
                result: Any = p.result or {}
                pose = result.get("pose") if isinstance(result, dict) and result.get("kind") == "vision" else None
                if isinstance(pose, dict):
                    xyz = ", ".join(f"{1000 * _number(pose.get(k)):.2f}" for k in ("x", "y", "z"))
                    score = result.get("score")
                    score_text = f"{score:.3f}" if isinstance(score, (int, float)) else "?"
                    found.append((p.t_start, f"  vision: {p.t_start:9.3f} s {lane.group} {p.name}: at ({xyz}) mm, score {score_text}"))
    return [line for _, line in sorted(found, key=lambda item: item[0])]


def _number(value: object) -> float:
    """A coordinate the file gives; NaN (printed as such) when it is none."""
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan


def summarize(path: str | Path) -> RunSummary:
    """Read a recording or a trace (:func:`read_record`: bounded, as every reader of one); OSError
    when the file cannot be read, NotARecording or OverLimit (one line naming the file) when it is
    no run's record or asks more than one can."""
    builder = TimelineBuilder()
    planned = PlanReader(printable(str(path)))

    def take(record: dict[str, Any]) -> None:
        planned.take(record)
        builder.add(record)

    read = read_record(path, take)
    plan = planned.finish()
    recording = read.recording
    if recording is None:
        assert read.trace is not None
        return RunSummary(str(path), read.trace.lines() + [f"  {note}" for note in planned.notes], builder.snapshot(), read.trace.cut, plan=plan)
    header = [f"recording {path}: {recording.messages} message(s)"]
    meta = recording.metadata.get("dual_arm_executive", {})
    if meta:
        header.append(
            f"  ran: {meta.get('application', '?')} ({meta.get('application_path', '?')}) on {meta.get('robot', '?')} "
            f"via {meta.get('backend', '?')}, software {meta.get('software_version', '?')}"
        )
        if meta.get("continues"):
            header.append(f"  continues: {meta['continues']}")
    if recording.skipped:
        header.append(f"  {recording.skipped} event(s) at a time no run has (not finite, or past ±{TIME_BOUND:.0f} s) skipped")
    if recording.cut:
        last = f" at {builder.t_last:.3f} s" if builder.t_first is not None else ""
        header.append(f"  CUT: the recording has no end (the run was killed or crashed); readable up to its last chunk{last}")
        if recording.problem:
            header.append(f"  reading stopped at damaged data: {recording.problem}")
    timeline = builder.snapshot()
    extra = [f"  {m.kind}: {m.t:.3f} s {m.group}: {m.text}" for m in timeline.marks if m.kind in ("error", "operator", "breakpoint")]
    header += [f"  {note}" for note in planned.notes]
    return RunSummary(str(path), header, timeline, recording.cut, extra, plan)


def cmd_report(settings: ReportSettings, out: IO[str], err: IO[str]) -> int:
    path = Path(settings.file)
    if not path.is_file():
        err.write(f"error: {path}: no such file\n")
        return EXIT_UNREADABLE
    target = None if not settings.draw else Path(settings.timeline) if settings.timeline else path.with_name(path.stem + ".timeline.svg")
    if target is not None:
        try:  # before reading: the timeline is never the record it is drawn from
            timeline_files(path, target, given=bool(settings.timeline)).check()
        except Refused as refusal:
            err.write(f"error: {refusal}\n")
            return EXIT_USAGE
    try:
        summary = summarize(path)
    except OSError as error:
        err.write(f"error: {path}: cannot read: {error.strerror or error}\n")
        return EXIT_UNREADABLE
    except (NotARecording, OverLimit) as error:
        err.write(f"error: {printable(error)}\n")
        return EXIT_UNREADABLE
    out.write("\n".join(summary.lines()) + "\n")
    if target is not None:
        from execution_engine.timeline_plot import plot_timeline  # matplotlib is slow to load (0.4 s): only when drawing

        try:
            plot_timeline(summary.timeline, target, title=f"{path.name}{' (CUT)' if summary.cut else ''}")
        except OSError as error:
            err.write(f"error: --timeline {target}: could not be written ({error.strerror or error}); the summary above is whole; free space or give another --timeline\n")
            return EXIT_OUTPUT
        out.write(f"timeline: {target}\n")
    return EXIT_OK


def timeline_files(record: Path, timeline: Path, *, given: bool) -> FilePlan:
    """The record ``report`` reads and the timeline it writes (.svg or .png), by run's rule."""
    from execution_engine.timeline_plot import FORMATS  # matplotlib is slow to load; asked for only when a timeline is drawn

    if timeline.suffix.lower() not in FORMATS:
        raise Refused(f"--timeline {timeline}: the timeline is written as .svg or .png")
    default = "" if given else "next to the record"
    return FilePlan("report").read(f"the record {record}", record).write(Output("--timeline", str(timeline), "the timeline", "run.timeline.svg", default=default))
