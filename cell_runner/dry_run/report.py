"""What a dry run found and what it predicts: findings at their XML lines, and each group's timeline.

The report is plain frozen data so that later checks can be built on it without re-running
anything -- the timeline in particular (every primitive of every group, start and end in the
application's time) is what a collision check between asynchronous arms needs.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Literal, Protocol

from core_functions.geometry import Pose
from execution_engine.app_model.diagnostics import Diagnostic, capped
from execution_engine.engine.waits import FlagWait, costliest, wait_totals

#: How the timeline's seconds were measured: the application's simulated clock (a simulator that
#: runs on it: every wait of the engine and the machines is in it too), or the robot's own cycles
#: (a controller simulator that keeps its own time, such as RSI's IPOC; primitives back to back), or the
#: wall clock (a cell of several robots one of which keeps its own time: every robot in real time).
TimeBase = Literal["simulated clock", "robot cycles", "wall clock"]
#: Joint names and positions (rad), as a back end's ``joint_state()`` gives them.
JointPositions = tuple[tuple[str, ...], tuple[float, ...]]


@dataclass(frozen=True)
class FoundBody:
    """One body of a collision finding: whose it is (a group, ``cell`` for a cell object, ``robot`` for a robot's fixed
    base), its name (a link of the URDF -- ``member/link`` in a cell of several robots --, a cell frame) and the label
    the message gives it (:meth:`robot_bridges.collision.scene.Body.label`)."""

    owner: str
    name: str
    label: str


@dataclass(frozen=True)
class Finding:
    """One problem of the application, found where the robot would have met it.

    ``kind`` is a :class:`robot_bridges.backend.FaultKind` value (``unreachable``, ``joint_limit``,
    ``unsupported``, ...), ``missing_trajectory`` for a replay of a trajectory never recorded, or
    ``function`` when the function itself failed (its skill code raised).  ``count`` says how many
    times the same kind of problem came up in the same call (a path with ten unreachable points is
    one finding, not ten).
    """

    kind: str
    group: str
    operation: str
    function: str
    primitive: str  # the primitive that met it (``describe()``), "" for a function-level problem
    message: str
    file: str
    line: int
    col: int
    t: float  # when, on the report's time base
    count: int = 1
    origin: str = ""  # the iteration of a loop or call the operation was made for (Operation.origin)
    assumed: str = ""  # the outcomes the dry run assumed where it met it (an application with <if>s)
    #: Where the robot was when it met it, kept as data so that a view can show the finding at its moment without
    #: reading the message: every joint of every group of every robot (the collision model's names, rad) at ``t``
    #: -- for a collision the instant of the closest contact, for a refused target where the arm stood --, the two
    #: bodies of a collision, and the TCP target (world frame) a refused motion asked for.  Empty/None where the
    #: dry run could not say (a function's own failure, a back end without joint states).
    joints: JointPositions | None = None
    bodies: tuple[FoundBody, ...] = ()
    target: Pose | None = None

    def diagnostic(self) -> Diagnostic:
        """The finding in the form validation prints: ``FILE:LINE:COL: operation 8 right_arm f: kind: ... (at 63.20 s)``;
        the time says how far into the run the robot would have got."""
        where = f"{self.primitive}: " if self.primitive else ""
        when = f"{self.count} times in this call, first at {self.t:.2f} s" if self.count > 1 else f"at {self.t:.2f} s"
        made = f" ({self.origin})" if self.origin else ""
        assumed = f"; assuming {self.assumed}" if self.assumed else ""
        text = f"operation {self.operation}{made} {self.group} {self.function}: {self.kind}: {where}{self.message} ({when}{assumed})"
        return Diagnostic(self.file, self.line, self.col, text)


@dataclass(frozen=True)
class Span:
    """One primitive on the timeline: who sent it, what it held, when it ran.

    ``groups`` are every group the primitive occupies (a full-body move holds all of them, a
    master/slave move both arms), ``group`` the one whose machine sent it.  A primitive that met a
    problem ends where it met it (``start == end`` when the target was refused before any motion),
    ``finding`` names the kind, and the dry run goes on from there.
    """

    group: str
    groups: tuple[str, ...]
    operation: str
    function: str
    primitive: str
    start: float
    end: float
    finding: str | None = None

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class GroupTime:
    """A group's share of the predicted cycle: busy while one of its primitives runs, idle otherwise."""

    busy: float
    idle: float
    primitives: int


@dataclass(frozen=True)
class CollisionCheck:
    """What the collision sweep covered: motions, configurations checked, the margin every pair keeps (m)."""

    motions: int
    samples: int
    margin: float


@dataclass(frozen=True)
class DryRunReport:
    """The outcome of one dry run of an application.

    ``complete`` is False when the dry run could not follow the whole application (the simulated
    controller stopped for good, or a function failed and the groups that ran beside it were
    stopped with it); ``notes`` say what was not checked.  ``cycle_time`` is the predicted time
    of the whole application on ``time_base``.
    """

    app: str
    file: str
    backend: str
    time_base: TimeBase
    findings: tuple[Finding, ...]
    timeline: tuple[Span, ...]
    cycle_time: float
    groups: Mapping[str, GroupTime]
    operations_total: int
    operations_checked: int
    complete: bool = True
    notes: tuple[str, ...] = ()
    collisions: CollisionCheck | None = None  # None: the robot has no collision model
    waits: tuple[FlagWait, ...] = ()  # every wait for a flag or a zone, on the application's clock
    #: The joints (names, rad) the dry run started from -- the simulator's own start, or the robot's
    #: measured state it was put in -- and where the application left them.
    start: JointPositions | None = None
    end: JointPositions | None = None
    #: The outcomes each pass assumed (an application with <if>s): every side of every <if> run in one.
    branches: tuple[str, ...] = ()
    #: Where the simulated cell contradicted an outcome a pass assumed (its camera did not find a hole the pass
    #: assumed found): what on that side was therefore not checked and what was checked instead -- no finding.
    assumptions: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.findings and self.complete

    def diagnostics(self) -> list[Diagnostic]:
        """The findings as diagnostics, by file, line and column: at most MAX_DIAGNOSTICS, then "and N more"."""
        return capped(f.diagnostic() for f in self.findings)

    def summary_lines(self) -> list[str]:
        """The prediction an integrator reads before the robot moves."""
        state = "no problems found" if not self.findings else f"{len(self.findings)} problem(s) found"
        lines = [
            f"dry run of {self.app} on {self.backend}: {state}; operations checked {self.operations_checked}/{self.operations_total}",
            f"  predicted cycle time {self.cycle_time:8.2f} s ({self.time_base})",
        ]
        for group, time in self.groups.items():
            share = 100.0 * time.busy / self.cycle_time if self.cycle_time > 0 else 0.0
            lines.append(f"  {group:<12} busy {time.busy:8.2f} s ({share:5.1f} %), idle {time.idle:8.2f} s, {time.primitives} primitives")
        lines += self.wait_lines()
        if self.collisions is not None:
            c = self.collisions
            lines.append(f"  collisions checked: {c.motions} motions, {c.samples} configurations, margin {c.margin * 1000:.0f} mm")
        else:
            lines.append("  collisions not checked: the robot has no collision model")
        lines += [f"  not checked: {note}" for note in self.notes]
        lines += [f"  branches, pass {i}{' (the prediction)' if i == 1 else ''}: assumed {text}" for i, text in enumerate(self.branches, start=1)]
        lines += [f"  assumed against the simulated cell: {note}" for note in self.assumptions]
        return lines


    def wait_lines(self) -> list[str]:
        """Idle time split into flag and zone waits, and the waits that cost the cycle most."""
        if not self.waits:
            return []
        out = []
        for group, time in self.groups.items():
            waited = wait_totals(self.waits, group)
            if waited:
                parts = ", ".join(f"waiting for {kind} {name!r} {d:.2f} s" for (kind, name), d in costliest(waited))
                out.append(f"  {group:<12} idle: {parts}, the rest {max(0.0, time.idle - sum(waited.values())):.2f} s")
        costly = costliest(wait_totals(self.waits), 3)
        out.append("  waits that cost most: " + ", ".join(f"{kind} {name!r} {d:.2f} s" for (kind, name), d in costly))
        return out


def group_times(groups: tuple[str, ...], timeline: tuple[Span, ...], cycle_time: float) -> dict[str, GroupTime]:
    """Busy and idle time of every group, from the spans that held it."""
    busy = {g: 0.0 for g in groups}
    count = {g: 0 for g in groups}
    for span in timeline:
        for group in span.groups:
            if group in busy:
                busy[group] += span.duration
                count[group] += 1
    return {g: GroupTime(busy[g], max(0.0, cycle_time - busy[g]), count[g]) for g in groups}


class _Sized(Protocol):
    name: str
    operations: tuple[object, ...]


def merged(app: _Sized, passes: list[tuple[str, DryRunReport, tuple[str, ...]]]) -> DryRunReport:
    """The passes of an application with <if>s (each: the outcomes assumed, its report, the ids of the
    operations it ran) as one report: the first pass's prediction (timeline, cycle time), every
    pass's findings (each naming the outcomes it assumed; one met in several passes said once), the
    motions every pass swept for collisions, what each left unchecked, every operation checked in one."""
    base = passes[0][1]
    findings: dict[tuple[str, str, str, str, str, str], Finding] = {}
    for assumed, report, _ in passes:
        for finding in report.findings:
            key = (finding.kind, finding.group, finding.operation, finding.function, finding.primitive, finding.message)
            findings.setdefault(key, replace(finding, assumed=assumed))
    notes = tuple(dict.fromkeys(f"{note} (assuming {assumed})" for assumed, report, _ in passes for note in report.notes))
    against = tuple(dict.fromkeys(f"{note} (assuming {assumed})" for assumed, report, _ in passes for note in report.assumptions))
    checked = {op for _, report, ids in passes for op in ids[:report.operations_checked]}
    swept = [r.collisions for _, r, _ in passes if r.collisions is not None]
    collisions = CollisionCheck(sum(c.motions for c in swept), sum(c.samples for c in swept), swept[0].margin) if len(swept) == len(passes) else None
    return replace(
        base, app=app.name, findings=tuple(findings.values()), notes=notes, complete=all(r.complete for _, r, _ in passes),
        operations_total=len(app.operations), operations_checked=len(checked), collisions=collisions,
        branches=tuple(assumed for assumed, _, _ in passes), assumptions=against,
    )
