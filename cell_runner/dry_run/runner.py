"""Run an application dry: the real engine, machines and skills, against the robot's simulator.

Nothing is modelled twice: the application goes through :func:`deploy_local` exactly as ``run``
does -- the same binding of params, the same skills pulling primitives, the same barriers -- on a
simulated clock, so minutes of robot work take a moment and the prediction is the run's own time.
Only the edges differ: the back end is wrapped by :class:`DryRunBackend` (problems become
findings and the run goes on), the groups share a throw-away copy of the trajectory database
(what earlier runs recorded is there, what this one records is thrown away), and the error
policy is ``abort``: when a function itself fails, the failure is a finding and the dry run goes
on.  In lock-step: the operation again without the failed calls (the groups stopped beside them
are checked to their end), then the next one.  With ``sync="flags"`` there is no operation to go
on from: the application is run again from its start without the failed calls (and their
synchronised partners), at most :data:`MAX_RERUNS` times, so every failure is reported, not only
the first; the timeline, the prediction and the collision sweep are the last run's.
"""
from __future__ import annotations

import logging
import sqlite3
import tempfile
from contextlib import closing
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from cell_runner.deployment import Deployment, deploy_local
from cell_runner.dry_run.backend import DryRunBackend, DryRunTrajectoryStore
from cell_runner.dry_run.branches import Assumption, assumptions, describe, fault_outcomes, has_branches, outcome_faults, resolved, sides
from cell_runner.dry_run.collisions import scene_of, sweep
from cell_runner.dry_run.placement import place
from cell_runner.dry_run.recorder import ClockTiming, CycleTiming, Recorder, Timing
from cell_runner.dry_run.report import CollisionCheck, DryRunReport, Finding, JointPositions, group_times, merged
from cell_runner.dry_run.simulators import DryRunSetup, setup_for
from core_functions.catalog import Catalog
from core_functions.trajectory_store import application_store
from execution_engine.app_model.model import WAIT, Application, Call, ErrorPolicy, Operation
from execution_engine.engine.report import GroupError
from node_transport import typed
from node_transport.clock import Clock, real_clock, run_with_clock, simulated_clock
from node_transport.qos import COMMANDS
from node_transport.wire import SmResult, sm_topic
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

log = logging.getLogger(__name__)

FUNCTION = "function"
_ABORT = ErrorPolicy(retries=0, action="abort")  # a retry would fail the same way; a safe pose would move
_QUIET_BRIDGE = {"state_period": 1.0}  # nobody watches joint_states in a dry run: the longest period a bridge takes
#: sync="flags": runs again without the calls that failed, at most this many times.
MAX_RERUNS = 25


class DryRunError(Exception):
    """The dry run itself could not be carried out (a defect, not a problem of the application)."""


def dry_run(
    app: Application, backend: str, options: BackendOptions, trajectory_db: str | None = None, start: JointPositions | None = None
) -> DryRunReport:
    """Dry-run ``app`` on the simulator of ``backend`` (a registry name) set up like ``options``.

    ``trajectory_db`` is the database the real run would use (default: the per-user one); it is
    copied, never written.  ``start``: the joints (names, rad) to put the simulated robot in
    first -- where the real robot is (:mod:`.start`); None: the simulator's own start.  Raises
    ``ValueError``/``KeyError`` for options the back end refuses, :class:`DryRunError` when the
    run breaks down.
    """
    setup = setup_for(backend, options)
    return dry_run_setup(app, setup, trajectory_db, start)


def dry_run_setup(app: Application, setup: DryRunSetup, trajectory_db: str | None = None, start: JointPositions | None = None) -> DryRunReport:
    """:func:`dry_run` with the simulator already chosen; on its own loop and clock (blocks)."""
    clock = simulated_clock() if setup.simulated_clock else real_clock()
    return run_with_clock(lambda c: run_dry(app, setup, c, trajectory_db, start), clock)


async def run_dry(
    app: Application, setup: DryRunSetup, clock: Clock, trajectory_db: str | None = None, start: JointPositions | None = None
) -> DryRunReport:
    """The dry run on ``clock`` (the caller's loop); see :func:`dry_run` (and the module, for sync="flags");
    an application with outcome branches once per set of outcomes assumed (:mod:`.branches`)."""
    if not has_branches(app):
        return await _run_plain(app, setup, clock, trajectory_db, start)
    passes = []
    catalog = full_catalog()
    view = PassView(sides=sides(app), fault_outcomes=fault_outcomes(app, catalog))
    for assumed in assumptions(app, catalog):
        branch = resolved(app, assumed)
        report = await _run_plain(branch, setup, clock, trajectory_db, start, replace(view, assumed=assumed))
        passes.append((describe(assumed), report, tuple(op.id for op in branch.operations)))
    return merged(app, passes)


@dataclass(frozen=True)
class PassView:
    """What a pass over assumed outcomes tells its recorder (:meth:`Recorder.defer`): the outcomes assumed, the
    outcome each tested function's faults stand for, the tested functions each side's operations depend on."""

    sides: dict[str, frozenset[tuple[str, str]]] = field(default_factory=dict)
    fault_outcomes: dict[tuple[str, str], dict[str, str]] = field(default_factory=dict)
    assumed: Assumption = field(default_factory=dict)


async def _run_plain(
    app: Application, setup: DryRunSetup, clock: Clock, trajectory_db: str | None = None, start: JointPositions | None = None,
    view: PassView | None = None,
) -> DryRunReport:
    left_out: dict[str, set[str]] = {}  # operation id -> groups whose failed call is left out
    earlier: list[Finding] = []  # the failures of the runs before
    for _ in range(MAX_RERUNS):
        report, failed = await _run_once(_leave_out(app, left_out), setup, clock, trajectory_db, start, view)
        fresh = {(f.operation, f.group) for f in failed} - {(op, g) for op, groups in left_out.items() for g in groups}
        if not fresh:
            break
        earlier += failed
        for operation, group in fresh:
            left_out.setdefault(operation, set()).add(group)
    else:
        report = replace(report, complete=False, notes=(*report.notes, f"sync=\"flags\": the application was run {MAX_RERUNS} times, each without the calls that had failed; the rest was not checked"))
    return replace(report, findings=(*earlier, *report.findings)) if earlier else report


def _leave_out(app: Application, left_out: dict[str, set[str]]) -> Application:
    """``app`` with the failed calls (and, for a synchronised one, its partners) as the implicit wait of a left-out group."""
    if not left_out:
        return app
    catalog = full_catalog()

    def sync(call: Call) -> bool:
        spec = catalog.get(call.function)
        return spec is not None and bool(spec.sync)

    operations = []
    for operation in app.operations:
        groups = left_out.get(operation.id, set())
        broken = any(sync(operation.calls[g]) for g in groups if g in operation.calls)
        out = {g for g, c in operation.calls.items() if g in groups or (broken and sync(c))}
        calls = {g: Call(g, WAIT, (), implicit=True, file=c.file, line=c.line, col=c.col) if g in out else c for g, c in operation.calls.items()}
        operations.append(replace(operation, calls=calls) if out else operation)
    return replace(app, operations=tuple(operations))


async def _run_once(
    app: Application, setup: DryRunSetup, clock: Clock, trajectory_db: str | None, start: JointPositions | None, view: PassView | None = None
) -> tuple[DryRunReport, list[Finding]]:
    """One dry run; with sync="flags" also the findings of the calls that failed (then not swept: it runs again)."""
    inner = await create_backend(setup.backend, clock, setup.options)
    timing: Timing = ClockTiming(clock) if setup.robot_seconds is None else CycleTiming(setup.robot_seconds(inner))
    recorder = Recorder(app, timing)
    recorder.outcome_faults = outcome_faults(app, full_catalog())
    if view is not None:
        recorder.sides, recorder.fault_outcomes, recorder.assumed = view.sides, view.fault_outcomes, view.assumed
    backend = DryRunBackend(inner, recorder)
    with tempfile.TemporaryDirectory(prefix="dry_run_") as folder:
        db = _copy_store(trajectory_db or str(application_store(app.path)), Path(folder) / "trajectories.sqlite")
        try:
            deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": db}, bridge_parameters=_QUIET_BRIDGE)
        except BaseException:
            await inner.close()
            raise
        store = DryRunTrajectoryStore(db, backend)
        try:
            if start is not None:
                await place(inner, app.robot, start)
            initial = backend.joint_state()
            _attach(deployment, recorder, store)
            total, failed = await _run_operations(app, deployment, recorder)
            final = backend.joint_state()
        finally:
            await deployment.close()
            store.close()
    scene = scene_of(app) if not failed else None
    stats = sweep(app, scene, initial, backend.motions, backend.grips, recorder) if scene is not None else None
    checked, notes = len(app.operations), list(recorder.notes)
    if backend.stuck is not None:
        notes.append(backend.stuck)
        ids = [op.id for op in app.operations]
        checked = ids.index(backend.stuck_at) + 1 if backend.stuck_at in ids else checked
    cycle_time = total if isinstance(timing, ClockTiming) else timing.elapsed()
    timeline = tuple(recorder.spans)
    found = recorder.findings()
    assumed_notes = tuple(recorder.assumption_notes())
    return DryRunReport(
        app=app.name,
        file=str(app.path),
        backend=setup.backend,
        time_base=timing.base,
        findings=found,
        timeline=timeline,
        cycle_time=cycle_time,
        groups=group_times(app.robot.group_names, timeline, cycle_time),
        operations_total=len(app.operations),
        operations_checked=checked,
        complete=not notes,
        notes=tuple(notes),
        assumptions=assumed_notes,
        waits=tuple(recorder.waits),
        collisions=None if stats is None else CollisionCheck(stats.motions, stats.samples, scene.margin if scene else 0.0),
        start=initial,
        end=final,
    ), [f for f in found if (f.operation, f.group) in failed]


def _attach(deployment: Deployment, recorder: Recorder, store: DryRunTrajectoryStore) -> None:
    """Let the recorder see which call each group runs, and give every group the shared store."""
    machines = deployment.machines

    def locate(group: str) -> tuple[str, str] | None:
        machine = machines.get(group)
        run = machine.ctx.run if machine is not None else None
        return None if run is None else (run.request.operation, run.request.function)

    recorder.locate = locate
    for machine in machines.values():
        machine.ctx.functions.ctx.trajectories = store


async def _run_operations(app: Application, deployment: Deployment, recorder: Recorder) -> tuple[float, set[tuple[str, str]]]:
    """Run every operation, going on after function failures (see the module's docstring).

    Returns the application's time: the engine's own total, summed over the parts it ran in; and
    with sync="flags", the calls (operation, group) that failed (the run ends at them).
    """
    results = _Results(deployment)
    total, offset = 0.0, 0
    operations = [replace(op, breakpoint=False) if op.breakpoint else op for op in app.operations]  # checked, never paused at
    dropped: dict[str, set[str]] = {}  # operation id -> groups whose failed call is not run again
    recorder.timing.start()
    while offset < len(operations):
        part = replace(app, operations=tuple(operations[offset:]), error_policy=_ABORT)
        report = await deployment.engine.run(part)
        total += report.total
        recorder.waits.extend(report.flag_waits)
        if report.outcome == "finished":
            break
        if report.outcome == "stopped" or not report.errors:
            raise DryRunError(f"the engine gave up on {app.name}: {report.message}")
        if app.sync == "flags":  # no operation boundary to go on from: run_dry runs it again without these calls
            for error in report.errors:
                recorder.add(error.group, error.operation, error.function, getattr(error, "fault", None) or FUNCTION, "", _own(error), recorder.timing.of_clock(error.t))
            return total, {(e.operation, e.group) for e in report.errors if getattr(e, "fault", None) != "stopped"}  # not the groups stopped with it
        offset += report.operations_done
        failed = operations[offset]
        for error in report.errors:
            kind = getattr(error, "fault", None) or FUNCTION  # the fault's kind where the engine reports it
            recorder.add(error.group, error.operation, error.function, kind, "", _own(error), recorder.timing.of_clock(error.t))
        out = dropped.setdefault(failed.id, set())
        known = len(out)
        out.update(e.group for e in report.errors if e.operation == failed.id)
        again = _without(failed, out, results.succeeded(failed.id), deployment.engine.catalog)
        if again is None or len(out) == known:  # nothing left, or nothing new to leave out: on to the next
            offset += 1
        else:
            operations[offset] = again
    return total, set()


def _own(error: GroupError) -> str:
    """An engine error's message without the function label the finding shows anyway."""
    label = f"{error.function} (operation {error.operation}): "
    return error.error[len(label):] if error.error.startswith(label) else error.error


def _without(operation: Operation, failed: set[str], done: set[str], catalog: Catalog) -> Operation | None:
    """``operation`` with only the calls that were stopped beside a failure (None: nothing left to check).

    The failed calls become waits; so do synchronised calls when one of them failed (their
    partners would wait at the barrier for nothing), and calls that had finished.
    """
    def sync(call: Call) -> bool:
        spec = catalog.get(call.function)
        return spec is not None and spec.sync is not None

    broken_barrier = any(sync(operation.calls[g]) for g in failed if g in operation.calls)
    keep = {
        g for g, call in operation.calls.items()
        if not call.is_wait and g not in failed and g not in done and not (broken_barrier and sync(call))
    }
    if not keep:
        return None
    calls = {g: call if g in keep else Call(g, WAIT, (), implicit=True, file=call.file, line=call.line, col=call.col) for g, call in operation.calls.items()}
    return replace(operation, calls=calls)


class _Results:
    """Which groups finished their function of an operation (the engine does not say, after a failure)."""

    def __init__(self, deployment: Deployment) -> None:
        self._outcomes: dict[tuple[str, str], str] = {}
        node = deployment.transport.create_node("dry_run_results")
        for group in deployment.machines:
            node.create_subscription(typed.MachineResultMsg, sm_topic(group, "result"), self._on_result, COMMANDS)
        self._clock = node.clock

    def _on_result(self, message: Any) -> None:
        result = typed.from_msg(SmResult, message, self._clock, source="dry run")
        self._outcomes[(result.operation, result.group)] = result.outcome

    def succeeded(self, operation: str) -> set[str]:
        return {g for (op, g), outcome in self._outcomes.items() if op == operation and outcome == "succeeded"}


def _copy_store(source: str, target: Path) -> str:
    """A copy of the trajectory database the run would use (empty if there is none yet)."""
    path = Path(source)
    if source != ":memory:" and path.is_file():
        try:
            with closing(sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)) as original, closing(sqlite3.connect(target)) as copy:
                original.backup(copy)
        except sqlite3.Error as error:
            log.warning("dry run: cannot read the trajectory database %s (%s); starting from an empty one", source, error)
    return str(target)
