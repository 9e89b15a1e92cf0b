"""The run summary the monitor shows after every run (live, and at the end of a replayed recording).

What an operator asks when a run has ended: how did it end; how long did the cycle take against what the
dry run predicted; how busy was each group, and what did the idle time wait for (the flag and zone waits that
cost most, named as the timeline names them); and every error, whether a retry recovered it, and what to do
about it.  It is computed from the run's records alone -- the trace, line for line, as the page has them --
through the same timeline model the ``report`` command and the timeline view use
(:func:`execution_engine.timeline.build_timeline`, :func:`cell_runner.run_report.waits_of`), so the three agree.

What to do about an error comes from two places: the operator actions the monitor offers for the state the
run ended in (an alarm: Reset (retry) or Stop; a failed run: fix the application in the builder, then Start),
and what the fault kind means at the cell (:data:`ADVICE`, keyed by :class:`node_transport.wire.FaultKind`);
where docs/faults.md has a row whose message the error matches, its number and title are given too.
"""
from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

from cell_runner.run_report import waits_of
from execution_engine.timeline import build_timeline
from node_transport.wire import FaultKind

#: The engine's states a run ends in.
ENDED = ("finished", "failed", "stopped")
#: The costliest waits listed (the rest are in the timeline).
MAX_WAITS = 5
#: docs/faults.md, for the rows an error's message matches (absent from an installed package: no hints then).
FAULTS_MD = Path(__file__).resolve().parent.parent / "docs" / "faults.md"

#: What an operator does at the cell about each kind of fault (the kind travels with the error).
ADVICE: Mapping[str, str] = {
    FaultKind.UNREACHABLE.value: "the target is out of the arm's reach: check the frame (or the vision correction) it was sent to, "
                                 "and the part's placement; change the target in the builder if it is wrong",
    FaultKind.JOINT_LIMIT.value: "a joint reached its limit: jog the arm back inside its range, check the target and the path to it "
                                 "(a different approach or configuration), then start again",
    FaultKind.COLLISION.value: "something is in the way: inspect the cell for a part or fixture out of place, clear it, and check "
                               "the path with validate --simulate before starting again",
    FaultKind.VISION.value: "the camera did not find the feature: check the part is there, the lighting and the lens, "
                            "and the camera's calibration",
    FaultKind.UNSUPPORTED.value: "the robot cannot do this primitive: change the function in the builder",
    FaultKind.STOPPED.value: "stopped on request: start again when ready",
    FaultKind.TIMEOUT.value: "the controller, the bridge or a partner did not answer in time: check it is running and connected",
    FaultKind.CONNECTION.value: "the link to the controller broke: check the cable and the controller, then start again",
    FaultKind.PROTOCOL.value: "the controller answered something unreadable: check its program version and its log",
    FaultKind.CONTROLLER.value: "the controller reported a fault: read it on the teach pendant, acknowledge it there, then start again",
    FaultKind.BUSY.value: "the group was still busy: wait until it is Ready, then retry",
    FaultKind.INTERNAL.value: "a defect of the software: keep the trace and report it",
    FaultKind.SKILL.value: "the function itself refused (a frame it cannot find, a part that does not fit): check its parameters in the builder",
    FaultKind.OUT_OF_RANGE.value: "a measured value is out of its range: inspect the part (the hole, the diameter) before going on",
}
_KIND = re.compile(r"\b(" + "|".join(re.escape(k.value) for k in FaultKind) + r"):")


@dataclass(frozen=True)
class ErrorItem:
    t: float
    group: str
    operation: str
    function: str
    error: str
    kind: str | None  # the fault kind the message names, if it does
    recovered: bool  # a later attempt of the same function succeeded (a retry)
    actions: tuple[str, ...]  # what to do, most direct first
    faults_row: str | None = None  # "docs/faults.md row 41: injected fault fails the run"


@dataclass(frozen=True)
class GroupShare:
    group: str
    busy: float
    idle: float
    waiting: float  # of the idle time, spent waiting for a flag or a zone
    functions: int
    failed: int


@dataclass(frozen=True)
class WaitItem:
    group: str
    what: str  # "flag part_ready" / "zone hole_area"
    seconds: float
    label: str  # the timeline's words for its longest wait: "waiting for flag part_ready set by right_arm"


@dataclass
class RunSummaryView:
    outcome: str  # finished / failed / stopped, "cut" when the record has no end, "running" while it goes
    exit_code: int | None
    operations_done: int
    operations_total: int
    cycle_time: float  # run seconds from the first record to the end
    predicted: float | None  # the dry run's predicted cycle time (the plan's total), if there was one
    retries: int
    groups: list[GroupShare] = field(default_factory=list)
    waits: list[WaitItem] = field(default_factory=list)
    errors: list[ErrorItem] = field(default_factory=list)
    t_end: float = 0.0  # run time of the end: the replay shows the summary from there on
    held: float = 0.0  # of the cycle, seconds paused or at an alarm (waiting for an operator, not the cell's time)

    @property
    def deviation(self) -> float | None:
        """Seconds longer than predicted (negative: faster)."""
        return None if self.predicted is None else self.cycle_time - self.predicted

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["deviation"] = self.deviation
        return out

    def lines(self) -> list[str]:
        """The summary as text, one line each (the page draws the same fields as a panel)."""
        predicted = "" if self.predicted is None else f" against {self.predicted:.2f} s predicted ({self.deviation:+.2f} s)"
        held = f" ({self.held:.2f} s of it paused or at an alarm)" if self.held > 0 else ""
        out = [f"{self.outcome}: operations {self.operations_done}/{self.operations_total}, cycle {self.cycle_time:.2f} s{held}{predicted}, retries {self.retries}"]
        out += [f"{g.group}: busy {g.busy:.2f} s, idle {g.idle:.2f} s (waiting {g.waiting:.2f} s)" for g in self.groups]
        out += [f"{w.group} {w.label}: {w.seconds:.2f} s" for w in self.waits]
        for e in self.errors:
            out.append(f"{e.group} at {e.t:.2f} s: {e.error}" + (" (recovered by a retry)" if e.recovered else ""))
            out += [f"  - {a}" for a in e.actions]
            if e.faults_row:
                out.append(f"  - see {e.faults_row}")
        return out


def summarize(records: Sequence[Mapping[str, Any]], plan: Sequence[float] = (), groups: Iterable[str] = ()) -> RunSummaryView:
    """The summary of a run's ``records`` (in order); ``plan``: the dry run's planned seconds per operation."""
    timeline = build_timeline(records, groups)
    end = next((r for r in reversed(records) if r.get("event") == "run_end"), None)
    t_end = float(end["t"]) if end is not None else timeline.t_end
    # a cell watched on the ROS graph (studio --transport ros) writes no run_end: the engine's last state says how it ended
    engine = next((str(r.get("to")) for r in reversed(records) if r.get("event") == "engine_state"), "")
    outcome = str(end.get("outcome", "?")) if end is not None else engine if engine in ENDED else "cut"
    shares, waits = [], []
    for group, lane in timeline.lanes.items():
        waited = waits_of(lane)
        shares.append(GroupShare(group, lane.busy, timeline.idle_total(group), sum(waited.values()), len(lane.bars),
                                 sum(1 for b in lane.bars if b.outcome in ("aborted", "preempted"))))
        for what, seconds in waited.items():
            longest = max((g for g in lane.idle if g.waiting == what), key=lambda g: g.duration)
            waits.append(WaitItem(group, what, seconds, longest.label))
    waits.sort(key=lambda w: -w.seconds)
    return RunSummaryView(
        outcome=outcome, exit_code=_count(end.get("exit_code")) if end is not None else None,
        operations_done=_count(end.get("operations_done")) or 0 if end is not None else sum(1 for o in timeline.operations if o.t_end is not None),
        operations_total=_count(end.get("operations_total")) or 0 if end is not None else len(timeline.operations),
        cycle_time=t_end - timeline.t_start, predicted=sum(plan) if plan else None, retries=timeline.retries,
        groups=shares, waits=waits[:MAX_WAITS], errors=errors_of(records, outcome), t_end=t_end, held=held_time(records, t_end),
    )


def held_time(records: Sequence[Mapping[str, Any]], t_end: float) -> float:
    """Run seconds the engine spent paused or at an alarm: the operator's time in the cycle, not the cell's."""
    held, since = 0.0, None
    for r in records:
        if r.get("event") != "engine_state":
            continue
        holding = r.get("to") in ("paused", "alarm")
        if holding and since is None:
            since = float(r["t"])
        elif not holding and since is not None:
            held, since = held + float(r["t"]) - since, None
    return held + (max(0.0, t_end - since) if since is not None else 0.0)


class SummaryOnEnd:
    """For a cell the station only watches (``studio --transport ros``): the summary, into the feed, as soon as the
    engine says the run ended -- nobody there writes a ``run_end``.  Fed the page's records in order."""

    def __init__(self, feed: Any) -> None:
        self.feed = feed

    def see(self, record: Mapping[str, Any]) -> None:
        if record.get("event") == "engine_state" and record.get("to") in ENDED:
            snapshot, records, _, _ = self.feed.read(0, 0)
            self.feed.update(summary=summarize(records, snapshot.plan, snapshot.groups).to_json())
        elif record.get("event") == "engine_state" and record.get("to") == "running" and self.feed.snapshot.summary is not None:
            self.feed.update(summary=None)  # started again: the last run's summary is no longer what the page shows


def _count(value: object) -> int | None:
    """A count or code the record gives (a replayed file is anyone's: anything else is none)."""
    return value if isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 1 << 53 else None


def errors_of(records: Sequence[Mapping[str, Any]], outcome: str) -> list[ErrorItem]:
    """Every error record, each with whether a retry recovered it and what to do."""
    out: list[ErrorItem] = []
    for i, r in enumerate(records):
        if r.get("event") != "error" or not isinstance(r.get("error"), str):
            continue
        group, operation = str(r.get("group", "?")), str(r.get("operation") or "")
        text = r["error"]
        same = next((k for k, e in enumerate(out) if group == "engine" and e.error in text), None)
        if same is not None:  # the run's failure in the words of the error above: one item, with the row it matches
            out[same] = replace(out[same], faults_row=out[same].faults_row or faults_row(text))
            continue
        recovered = group != "engine" and any(
            later.get("event") == "function_end" and later.get("group") == group and str(later.get("operation") or "") == operation
            and later.get("outcome") == "succeeded" for later in records[i + 1:])
        found = _KIND.search(text)
        kind = found.group(1) if found else FaultKind.STOPPED.value if text.startswith("stopped by ") else None
        out.append(ErrorItem(float(r["t"]), group, operation, str(r.get("function") or ""), text, kind, recovered,
                             actions_for(kind, recovered, outcome, group == "engine"), faults_row(text)))
    return out


def actions_for(kind: str | None, recovered: bool, outcome: str, engine: bool) -> tuple[str, ...]:
    """What the operator does: the monitor's own actions for the state the run ended in, then the fault's advice."""
    if recovered:
        return ("nothing now: a retry recovered it; if it comes back often, " + ADVICE.get(kind or "", "check the cell at this step"),)
    if kind == FaultKind.STOPPED.value and outcome == "failed":  # stopped by the engine because another group failed
        return ("nothing for this group: the engine stopped it when the run failed; see the error that failed it",)
    actions = []
    if outcome == "alarm":
        actions.append("answer the alarm: Reset (retry) once the cause is removed, or Stop")
    elif outcome == "failed":
        actions.append("remove the cause, then Start again (the dry run checks from where the robot is); "
                       "if the application is wrong, Open the builder at this operation")
    elif outcome == "stopped":
        actions.append("the run was stopped: Start again when the cell is ready")
    if kind in ADVICE:
        actions.append(ADVICE[kind])
    elif not engine:
        actions.append("read the message: it names the primitive and the target; check them in the builder")
    return tuple(actions)


@cache
def _faults_rows() -> tuple[tuple[str, str, re.Pattern[str]], ...]:
    """(row number, title, pattern of its message) of docs/faults.md's table; none when the file is not there."""
    try:
        text = FAULTS_MD.read_text(encoding="utf-8")
    except OSError:
        return ()
    rows = []
    for line in text.splitlines():
        cells = [c.strip() for c in line.split(" | ")]
        if len(cells) < 4 or not cells[0].lstrip("| ").isdigit():
            continue
        message = cells[3].strip("`")
        message = re.sub(r"^(error: |application [^:]+: [A-Z]+ - |\S+: error: )", "", message)
        pieces = [re.escape(p) for p in message.split("…") if p.strip()]
        if sum(len(p) for p in pieces) < 24:  # a row that is mostly '…' matches anything: no hint from it
            continue
        rows.append((cells[0].lstrip("| "), cells[1], re.compile(".*?".join(pieces), re.DOTALL)))
    return tuple(rows)


def faults_row(error: str) -> str | None:
    """"docs/faults.md row N: title" for the first row whose message ``error`` holds (its varying parts aside)."""
    for number, title, pattern in _faults_rows():
        if pattern.search(error):
            return f"docs/faults.md row {number}: {title}"
    return None
