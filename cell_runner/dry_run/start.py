"""Every run is checked from where the robot is, and a robot left elsewhere is first brought back.

The dry run before ``run`` starts the simulator in its own start pose; the robot may be anywhere
(an earlier run cancelled in the middle, a robot jogged by hand, a controller that was not at
home).  So whatever starts a run -- ``run``, the studio, ``launch``, ``ros2 launch``, a
RunApplication goal, a goal after a cancelled one, ``run --resume`` -- measures the robot first
(the back end's joints at connect, or ``joint_states`` on a graph) and :func:`plan_start` decides:

* the robot is where the check assumed (within :data:`TOLERANCE`): that check's verdict holds;
* it is where the application starts: the application is dry-run from the measured joints;
* it is elsewhere: a resumed run goes on from there if the dry run proves it safe; otherwise --
  and for a fresh run always -- the run starts with a *way back* (:mod:`.way_back`): the
  candidates are dry-run from the measured joints until one is free of collisions and ends where
  the application starts, and the application is dry-run from there.  None: the run is refused
  with the findings.

A refusal is :class:`StartRefused` (the findings, then one line saying why); a plan is
:class:`StartPlan`, which :func:`execute` carries out -- after measuring again: a robot that moved
while it was being checked is not run, nor an application after a way back that did not end
where it should.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol
from weakref import WeakKeyDictionary

from cell_runner.dry_run.placement import PlacementError
from cell_runner.dry_run.report import DryRunReport, Finding, JointPositions
from cell_runner.dry_run.runner import DryRunError, dry_run_setup
from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.dry_run.way_back import WayBack, away, candidates
from core_functions.robots import RobotModel
from execution_engine.app_model.model import WAIT, Application, Call
from execution_engine.engine.report import RunReport
from execution_engine.run_plan import PlanPublisher, plan_of
from node_transport.clock import Clock
from node_transport.port import Node, TransportError

#: Joints closer than this (rad, 0.06 deg) are where a check assumed them: encoder noise, not a move.
TOLERANCE = 1e-3


class UntrustedState(ValueError):
    """What the robot reports cannot be checked from: a joint missing, not a number, beyond its limits."""


@dataclass(frozen=True)
class MeasuredState:
    """The robot's joints as measured now, and where that came from (for every message)."""

    names: tuple[str, ...]
    positions: tuple[float, ...]
    source: str

    @property
    def joints(self) -> JointPositions:
        return self.names, self.positions


def measured(robot: RobotModel, names: Sequence[str], positions: Sequence[float], source: str) -> MeasuredState:
    """The robot's joints from ``names``/``positions``, checked: every joint of ``robot``, finite,
    within its limits (a hair beyond, within :data:`TOLERANCE`, is put on the limit)."""
    where = dict(zip(names, positions))
    missing = [j for j in robot.joint_names if j not in where]
    if missing:
        raise UntrustedState(f"{source} gives no position for {', '.join(missing)}")
    values = []
    for group in robot.groups:
        for joint in group.joints:
            value = where[joint.name]
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise UntrustedState(f"{source} gives {joint.name} = {value!r}, not a number")
            if not joint.contains(value, TOLERANCE):
                raise UntrustedState(
                    f"{source} gives {joint.name} at {math.degrees(value):.2f} deg, outside its limits "
                    f"[{math.degrees(joint.lower):.1f}, {math.degrees(joint.upper):.1f}] deg: bring it inside them on the controller first"
                )
            values.append((joint.name, min(max(float(value), joint.lower), joint.upper)))
    order = {name: k for k, name in enumerate(robot.joint_names)}
    values.sort(key=lambda item: order[item[0]])
    return MeasuredState(tuple(n for n, _ in values), tuple(v for _, v in values), source)


def farthest(a: JointPositions, b: JointPositions) -> tuple[str, float]:
    """The joint of ``a`` farthest from its value in ``b``, and how far (rad)."""
    other = dict(zip(*b))
    worst = ("", 0.0)
    for name, value in zip(*a):
        distance = abs(value - other.get(name, math.inf))
        if distance > worst[1] or not worst[0]:
            worst = (name, distance)
    return worst


def close(a: JointPositions, b: JointPositions | None) -> bool:
    return b is not None and farthest(a, b)[1] <= TOLERANCE


@dataclass(frozen=True)
class ResumeFrom:
    """Where a resumed run starts: the operation's index and its groups that had completed."""

    index: int
    done: frozenset[str] = frozenset()


@dataclass(frozen=True)
class StartPlan:
    """What a run does, proved by the dry run from the measured joints: the way back first (or
    None), then the application.  ``lines`` tell the operator what is planned and why."""

    app: Application
    state: MeasuredState
    report: DryRunReport
    way_back: WayBack | None = None
    way_back_report: DryRunReport | None = None
    start: JointPositions | None = None  # where the way back ends: the application's start
    lines: tuple[str, ...] = ()


class StartRefused(Exception):
    """The run is not started: ``lines`` are the findings, ``reason`` one line saying why."""

    def __init__(self, reason: str, lines: Sequence[str] = (), report: DryRunReport | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.lines = tuple(lines)
        self.report = report


def remaining(app: Application, resume: ResumeFrom) -> Application:
    """What a resumed run still does: the operations from ``resume.index``, its completed groups waiting."""
    operations = list(app.operations[resume.index:])
    if operations and resume.done:
        first = operations[0]
        calls = {g: Call(g, WAIT, ("0",), implicit=True, file=c.file, line=c.line, col=c.col) if g in resume.done else c for g, c in first.calls.items()}
        operations[0] = replace(first, calls=calls)
    return replace(app, operations=tuple(operations))


def plan_start(
    app: Application,
    setup: DryRunSetup,
    state: MeasuredState,
    trajectory_db: str | None = None,
    *,
    checked: DryRunReport | None = None,
    resume: ResumeFrom | None = None,
) -> StartPlan:
    """How to start ``app`` from ``state`` (see the module); blocks for the dry runs it needs.

    ``checked``: a dry run of the whole application from the simulator's own start, already done
    (``run`` does one before it connects); reused where the robot is where it started."""
    target = app if resume is None else remaining(app, resume)
    if resume is None and checked is not None and checked.ok and close(state.joints, checked.start):
        return StartPlan(app, state, checked)
    start = checked.start if checked is not None and checked.start is not None else _simulator_start(app, setup, trajectory_db)
    if close(state.joints, start):
        report = _dry(target, setup, trajectory_db, state.joints)
        if not report.ok:
            raise _refusal(report, f"{_count(report)} found by the dry run from where the robot is ({state.source})")
        return StartPlan(app, state, report)
    joint, distance = farthest(state.joints, start)
    there = f"the robot is not where {app.name} starts ({joint} {math.degrees(distance):.1f} deg from it, {state.source})"
    if resume is not None:
        report = _dry(target, setup, trajectory_db, state.joints)
        if report.ok:
            return StartPlan(app, state, report, lines=(f"{there}: the resumed run goes on from there (the dry run found no problem)",))
    way, way_report = _way_back(app, setup, trajectory_db, state, start, there)
    if resume is not None or checked is None or not checked.ok:
        report = _dry(target, setup, trajectory_db, start)
    else:
        report = checked
    if not report.ok:
        raise _refusal(report, f"{_count(report)} found by the dry run from the application's start, where the way back would take the robot")
    line = f"{there}: the run starts with the way back, proved free of collisions by the dry run: {way.description}"
    return StartPlan(app, state, report, way, way_report, start, (line,))


def _way_back(
    app: Application, setup: DryRunSetup, trajectory_db: str | None, state: MeasuredState, start: JointPositions, there: str
) -> tuple[WayBack, DryRunReport]:
    """The first way back the dry run proves: no finding, and it ends where the application starts."""
    tried: list[tuple[WayBack, DryRunReport]] = []
    for way in candidates(app, start, away(app, state.joints, start, TOLERANCE)):
        report = _dry(way.app, setup, trajectory_db, state.joints)
        if report.ok and report.end is not None and close(report.end, start):
            return way, report
        tried.append((way, report))
    lines = [f"{app.path}: way back ({way.description}): {_finding(f)}" for way, report in tried[:1] for f in report.findings]
    for way, report in tried:
        if report.ok and report.end is not None:
            joint, distance = farthest(report.end, start)
            lines.append(f"{app.path}: way back ({way.description}): ends {math.degrees(distance):.2f} deg from the start at {joint}")
        lines += [f"{app.path}: way back ({way.description}): not checked: {note}" for note in report.notes]
    raise StartRefused(
        f"{there}, and none of {len(tried)} way(s) back to it is free of collisions in the dry run: bring the robot to the start by hand",
        lines, tried[0][1] if tried else None,
    )


def _finding(finding: Finding) -> str:
    where = f"{finding.primitive}: " if finding.primitive else ""
    return f"{finding.group} {finding.function}: {finding.kind}: {where}{finding.message}"


def _dry(app: Application, setup: DryRunSetup, trajectory_db: str | None, start: JointPositions) -> DryRunReport:
    try:
        return dry_run_setup(app, setup, trajectory_db, start)
    except PlacementError as error:
        raise StartRefused(f"cannot check the run from where the robot is: {error}") from None
    except DryRunError as error:
        raise StartRefused(f"the dry run from where the robot is broke down: {error}") from None


def _simulator_start(app: Application, setup: DryRunSetup, trajectory_db: str | None) -> JointPositions:
    """Where the simulator starts: the application's start pose (a dry run without operations)."""
    report = dry_run_setup(replace(app, operations=()), setup, trajectory_db)
    if report.start is None:
        raise StartRefused(f"the {setup.backend} simulator gave no start pose")
    return report.start


def _count(report: DryRunReport) -> str:
    if report.findings:
        return f"{len(report.findings)} problem(s)"
    return "parts not checked"


def _refusal(report: DryRunReport, reason: str) -> StartRefused:
    lines = [str(d) for d in report.diagnostics()]
    lines += [f"{report.file}: not checked: {note}" for note in report.notes]
    return StartRefused(reason, lines, report)


async def check_start(clock: Clock, plan: Callable[[], StartPlan]) -> StartPlan:
    """Run ``plan`` (blocking dry runs) off the loop; a simulated clock stands still meanwhile."""
    with clock.held():
        return await asyncio.to_thread(plan)


# ------------------------------------------------------------------------------- carrying out
Measure = Callable[[], Awaitable[MeasuredState]]


class Engine(Protocol):
    """What carrying a plan out needs of the engine (:class:`~execution_engine.engine.engine.ExecutionEngine`)."""

    stops_asked: int
    autostart: bool
    node: Node  # where the run's plan is published (announce)

    async def run(self, app: Application, resume: Any = None) -> RunReport: ...


def backend_measure(robot: RobotModel, backend: Any, source: str) -> Measure:
    """Measuring a back end of this process (``joint_state()``): ``run`` and the studio, at connect."""
    async def measure() -> MeasuredState:
        names, positions = backend.joint_state()
        try:
            return measured(robot, names, positions, source)
        except UntrustedState as error:
            raise StartRefused(str(error)) from None

    return measure


async def execute(
    engine: Engine, plan: StartPlan, measure: Measure, resume: Any = None, stopped: Callable[[], bool] = lambda: False
) -> tuple[RunReport | None, RunReport | None]:
    """Carry out ``plan``: (the way back's report or None, the application's report or None when
    it was not started).  StartRefused when the robot moved since it was measured; nothing more
    is started once ``stopped()`` says an operator stopped the run.  An engine that waits for the
    operator's start (``autostart`` off) waits once, before the first motion, way back included."""
    now = await measure()
    if not close(now.joints, plan.state.joints):
        joint, distance = farthest(now.joints, plan.state.joints)
        raise StartRefused(f"the robot moved while its run was being checked ({joint} by {math.degrees(distance):.2f} deg, {now.source}): start it again")
    if plan.way_back is None:
        return None, await engine.run(plan.app, resume)
    back = await engine.run(plan.way_back.app)
    if not back.ok or stopped():
        return back, None
    assert plan.start is not None
    now = await measure()
    if not close(now.joints, plan.start):
        joint, distance = farthest(now.joints, plan.start)
        back.outcome, back.message = "failed", (
            f"after the way back the robot is {math.degrees(distance):.2f} deg from the start at {joint} ({now.source}): "
            f"{plan.app.name} is not started"
        )
        return back, None
    autostart, engine.autostart = engine.autostart, True  # the start that began the way back begins the application
    try:
        return back, await engine.run(plan.app, resume)
    finally:
        engine.autostart = autostart


@dataclass
class CheckedRun:
    """A run whose start was checked (:func:`check_run`): :meth:`run` carries it out."""

    engine: Engine
    plan: StartPlan
    measure: Measure
    clock: Clock
    resume: Any
    say: Callable[[str], None]
    asked: int  # the engine's stops asked for when the check began

    def stopped(self) -> bool:
        return self.engine.stops_asked != self.asked

    async def run(self) -> RunReport:
        """The application's report (or that of the way back that failed, under the application's
        name); StartRefused when the robot moved since it was measured."""
        app = self.plan.app
        if self.stopped():
            return not_started(app, self.clock, "stopped by the operator while the run was being checked")
        back, report = await execute(self.engine, self.plan, self.measure, self.resume, self.stopped)
        if back is not None:
            for line in back.summary_lines():
                self.say(line)
        if report is not None:
            return report
        assert back is not None
        if back.ok:  # the way back went well, then a stop came
            return not_started(app, self.clock, "stopped by the operator after the way back")
        return replace(back, app=app.name, operations_total=len(app.operations), operations_done=0,
                       message=f"the way back failed, {app.name} was not started: {back.message}")


async def check_run(
    engine: Engine,
    app: Application,
    setup: DryRunSetup,
    trajectory_db: str | None,
    measure: Measure,
    clock: Clock,
    *,
    checked: DryRunReport | None = None,
    resume: Any = None,
    say: Callable[[str], None] = lambda line: None,
) -> CheckedRun:
    """Measure and plan (:func:`plan_start`), say what is planned; StartRefused when the run must
    not start.  A stop asked for from here on ends the run before anything moves."""
    asked = engine.stops_asked
    state = await measure()
    where = None if resume is None else ResumeFrom(resume.index, frozenset(getattr(resume, "done", ())))
    plan = await check_start(clock, lambda: plan_start(app, setup, state, trajectory_db, checked=checked, resume=where))
    for line in plan.lines:
        say(line)
    announce(engine, plan, "start" if checked is not None and plan.report is checked else "measured")
    return CheckedRun(engine, plan, measure, clock, resume, say, asked)


#: Each engine's latched plan topic (an engine on a graph checks one run after another).
_PLANS: WeakKeyDictionary[Any, PlanPublisher] = WeakKeyDictionary()


def announce(engine: Engine, plan: StartPlan, basis: str) -> None:
    """The plan the run was proved against, on the engine's latched plan topic, so the trace and the recording
    keep it and a replay draws it (:mod:`execution_engine.run_plan`)."""
    try:
        publisher = _PLANS.get(engine)
        if publisher is None:
            publisher = _PLANS[engine] = PlanPublisher(engine.node)
        publisher.publish(plan_of(plan.report, [op.id for op in plan.app.operations], basis, plan.app.name))
    except (TransportError, LookupError, TypeError, ValueError, ImportError) as error:  # e.g. an interface package built before RunPlan
        engine.node.logger.warning("the run's plan is not published (a replay will show no planned bars): %s", error)


def not_started(app: Application, clock: Clock, why: str) -> RunReport:
    """The report of a run stopped before its first operation."""
    now = clock.now()
    return RunReport(app=app.name, operations_total=len(app.operations), t_start=now, t_end=now, outcome="stopped", message=why)


async def start_checked(
    engine: Engine,
    app: Application,
    backend: Any,
    clock: Clock,
    setup: DryRunSetup | None,
    trajectory_db: str | None,
    checked: DryRunReport | None,
    resume: Any,
    out: Any,
) -> RunReport:
    """``run``: the run, checked from the joints of ``backend`` (this process's, connected) --
    ``setup`` None: unchecked (``--no-check``).  ``checked``: the dry run done before connecting,
    from the simulator's start; ``out`` hears what is planned."""
    if setup is None:
        return await engine.run(app, resume)
    measure = backend_measure(app.robot, backend, backend_source(backend))
    run = await check_run(engine, app, setup, trajectory_db, measure, clock, checked=checked, resume=resume, say=lambda line: out.write(f"{line}\n"))
    return await run.run()


def backend_source(backend: Any) -> str:
    """How messages name a back end of this process as the source of the joints."""
    return f"the {getattr(backend, 'label', backend.name)} back end"
