"""The run the station starts: engine, group machines and bridge in-process, watched like any viewer would.

The run gets a thread and an event loop of its own (``run_with_clock``: a ``--speed max`` run needs
a virtual-time loop, which the web server's loop is not).  Everything the page shows comes from
plain subscriptions on the run's transport -- the machines' status, structure and the engine's
status and events (:class:`~execution_engine.observers.RunObserver`), ``joint_states`` -- so it
sees what a tool on a ROS graph would.  Operator commands go to the engine's own entry for them
(:meth:`ExecutionEngine.operator_command`, source ``studio``), the safety stop to the cell's
``cell/safety_stop`` input, so the trace and the run report record both as for any other operator.
"""
from __future__ import annotations

import asyncio
import json
import logging
import threading
from collections.abc import Callable, Coroutine
from concurrent.futures import Future
from dataclasses import replace
from typing import IO, Any

from cell_runner.deployment import Deployment, deploy_local
from cell_runner.dry_run.check import keeping_for
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.runner import DryRunError, dry_run
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.start import StartRefused, backend_measure, backend_source, check_run
from cell_runner.output_files import FilePlan, Output, Refused, WriteFailure
from cell_runner.run_checks import app_inputs, run_files
from cell_runner.settings import RunSettings
from core_functions.robots import RobotModel
from core_functions.trajectory_store import application_store
from execution_engine.app_model import Application
from execution_engine.engine.report import RunReport
from execution_engine.engine.speed import speed_for_next_run
from execution_engine.observers import RunObserver, TraceWriter
from execution_engine.run_plan import PlanReader, plan_of
from node_transport import codec, typed
from node_transport.clock import Clock, run_with_clock
from node_transport.msgs import Bool, JointState
from node_transport.port import Node
from node_transport.qos import LATCHED, SENSOR
from node_transport.wire import JOINT_STATES, SAFETY_STOP, EngineStatus, SmStructure, sm_topic
from operator_station.cell_audit import watch_safety
from operator_station.eta import EtaFeed
from operator_station.feed import Feed
from operator_station.paused_edit import EditTarget
from operator_station.replay import show_plan
from operator_station.run_summary import summarize
from operator_station.scene3d import begin_run, keep_dry_run
from operator_station.scene3d_live import observe as observe_scene
from robot_bridges import registry
from robot_bridges.backend import BackendOptions

log = logging.getLogger(__name__)

#: How the page names itself in the trace and the run report.
SOURCE = "studio"
#: Exit codes as ``run`` gives them, for the trace's run_end record.
EXIT_OK, EXIT_FAILED, EXIT_STOPPED = 0, 1, 3


class RunSession:
    """At most one run at a time; :meth:`start` another once it has ended."""

    def __init__(self, feed: Feed, settings: RunSettings) -> None:
        """``settings``: what ``studio`` was started with (``run``'s options), for every run it starts."""
        self.feed = feed
        self.settings = settings
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._deployment: Deployment | None = None
        self._safety: Any = None  # the studio node's publisher on cell/safety_stop
        self._ready = threading.Event()
        self.report: RunReport | None = None
        self._verdict: DryRunReport | None = None  # the dry run before connecting, from the simulator's start
        self._kept: str | None = None  # the line saying the verdict was kept (no dry run this time)
        self.edit_target: EditTarget | None = None  # the run an edit of the paused run goes to (operator_station/paused_edit.py)
        self.speed_percent = 100.0  # the speed override the next run starts with; a run's own is its engine's (engine/speed.py)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def backend_name(self, app: Application) -> str:
        return self.settings.backend.backend_for(app)

    def start(self, app: Application, operations: list[dict[str, Any]]) -> tuple[bool, str]:
        """Start ``app`` (validated) on a fresh deployment; False and why when a run is still going,
        or when a file it would write is one it reads or another it writes (nothing written then)."""
        if self.running:
            return False, "a run is still going: stop it first"
        try:
            self.files(app).check()
        except Refused as refusal:
            return False, f"not run: {refusal}"
        self._ready.clear()
        self.report = None
        self.feed.begin("live", app.name, list(app.robot.group_names), operations=operations)
        begin_run(self.feed, app)  # the 3D view shows its robot and cell, also if the dry run refuses it
        self._thread = threading.Thread(target=self._main, args=(app,), name="studio run", daemon=True)
        self._thread.start()
        return True, "starting"

    def wait_started(self, timeout: float) -> bool:
        """Wait until the run's nodes are up (or it was refused or failed); False if neither within ``timeout`` s."""
        return self._ready.wait(timeout) and self._deployment is not None

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def trajectory_db(self, app: Application) -> str:
        """``--trajectory-db``, else the application's own database (as ``run`` uses), never a home directory's."""
        return self.settings.outputs.trajectory_db or str(application_store(app.path))

    def files(self, app: Application) -> FilePlan:
        """Every file a run of ``app`` reads and writes, under ``run``'s rule (:mod:`cell_runner.output_files`)."""
        derived = {} if self.settings.outputs.trajectory_db else {"--trajectory-db": "the application's own"}
        return run_files(app_inputs(app), trace=self.settings.outputs.trace, trajectory_db=self.trajectory_db(app),
                         extra=self.settings.backend.extra, derived=derived, command="studio run")

    def outputs(self) -> list[Output]:
        """The files every run of this station writes, whatever the application: a saved application is none of them."""
        outputs = self.settings.outputs
        return run_files((), trace=outputs.trace, trajectory_db=outputs.trajectory_db, extra=self.settings.backend.extra).outputs

    # ------------------------------------------------------------------------ the run thread
    def _options(self, app: Application) -> BackendOptions:
        """The back end's options, at the override the page set for the next run (its dry run's times too)."""
        return replace(self.settings.backend.backend_options(app), speed_override=self.speed_percent / 100.0)

    def _main(self, app: Application) -> None:
        try:
            if self.settings.check and not self._checked(app):
                return
            clock = self.settings.clock()
            trace_path = self.settings.outputs.trace
            trace = open(trace_path, "w", encoding="utf-8") if trace_path else None  # noqa: SIM115 - closed below
            try:
                self.report = run_with_clock(lambda c: self._run(app, c, trace), clock)
            finally:
                if trace is not None:
                    trace.close()
        except StartRefused as refusal:  # the dry run from where the robot is: nothing moved
            if refusal.report is not None and refusal.report.findings:
                keep_dry_run(self.feed, refusal.report, app)  # the 3D view: each finding at its moment
            found = [{"severity": "error", "message": line} for line in refusal.lines]
            self.feed.update(messages=[{"severity": "error", "message": f"not run: {refusal.reason}"}, *found])
        except Exception as error:  # noqa: BLE001 - the page must hear of it; the thread must not die silently
            log.exception("the studio run failed")
            self.feed.update(messages=[{"severity": "error", "message": f"the run could not go on: {type(error).__name__}: {error}"}])
        finally:
            self._loop = None
            self._deployment = None
            self._ready.set()
            self.feed.update(ended=True)

    def _checked(self, app: Application) -> bool:
        """The dry run ``run`` does first: its planned durations give the ETA; findings refuse the run.
        A passed verdict is kept and used as ``run``'s is (:func:`~cell_runner.dry_run.check.keeping_for`,
        keyed by the page's application as validated, not by the file on the disk)."""
        self._kept = None
        try:
            keeping = keeping_for(app, setup_for(self.backend_name(app), self._options(app)), self.trajectory_db(app))
            kept = keeping.kept() if keeping is not None else None
            if kept is not None:  # said on the page as run says it on its console
                self._kept = kept.line()
                self.feed.update(messages=[{"severity": "info", "message": self._kept}])
                report = kept.report
            else:
                report = dry_run(app, self.backend_name(app), self._options(app), self.trajectory_db(app))
                if keeping is not None:
                    plan = self.files(app)
                    keeping.keep(report, [i.path for i in plan.inputs] + [o.path for o in plan.outputs])
        except (KeyError, ValueError, OSError, ConnectionError, DryRunError) as error:
            self.feed.update(messages=[{"severity": "error", "message": f"not run: the dry run could not be done: {error}"}])
            return False
        if not report.ok:
            keep_dry_run(self.feed, report, app)  # the 3D view: the robot where the run would start, the bodies, the places
            found = [{"severity": "error", "message": str(d), "line": d.line} for d in report.diagnostics()]
            found += [{"severity": "error", "message": f"not checked: {note}"} for note in report.notes]
            self.feed.update(messages=[{"severity": "error", "message": f"not run: {len(report.findings)} problem(s) found by the dry run"}, *found])
            return False
        show_plan(self.feed, plan_of(report, [op.id for op in app.operations]))  # the ETA and the timeline's planned bars until the start check's plan comes
        self._verdict = report
        return True

    async def _run(self, app: Application, clock: Clock, trace: IO[str] | None) -> RunReport:
        backend = await registry.create_backend(self.backend_name(app), clock, self._options(app))
        parameters = {"trajectory_db": self.trajectory_db(app)}
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters=parameters, engine_parameters={"autostart": False, "speed_override": self.speed_percent})
        deployment.engine.hold_for_operators = True  # the operator is a person at a page: simulated time waits
        node = deployment.transport.create_node("operator_station")
        iterations = app.iterations()  # the loop iteration or call of each expanded operation, on its records
        writer = TraceWriter(trace, iterations) if trace is not None else None
        page = TraceWriter(FeedStream(self.feed, EtaFeed(self.feed, clock, self.speed_percent).see), iterations)  # the page gets the trace's records, written by the same code; the ETA follows them
        observe(node, app.robot, self.feed, [w for w in (writer, page) if w is not None])
        self._safety = node.create_publisher(Bool, SAFETY_STOP, LATCHED)
        self._loop, self._deployment = asyncio.get_running_loop(), deployment
        setup = setup_for(self.backend_name(app), self._options(app)) if self.settings.check else None  # an edit is checked as the Start is
        self.edit_target = EditTarget.of(deployment.engine, app, backend, clock, setup, self.trajectory_db(app))
        deployment.engine.remainder.hooks += [w.swapped for w in (writer, page) if w is not None]  # an edit's iterations in the records
        self._ready.set()
        try:
            run = asyncio.get_running_loop().create_task(await self._started(app, deployment, backend, clock))
            await asyncio.sleep(0)  # the engine takes its first steps: a start now is this run's
            await deployment.engine.operator_command("start", SOURCE)
            report = await run
            final_joint_sample(self.feed, app.robot, backend, clock.now())
            code = EXIT_OK if report.ok else EXIT_STOPPED if report.outcome == "stopped" else EXIT_FAILED
            t_end = clock.now()
            for each in (writer, page):
                if each is not None:
                    each.finish(t_end, report.outcome, code, report.operations_done, report.operations_total)
            snapshot, records, _, _ = self.feed.read(0, 0)
            self.feed.update(summary=summarize(records, snapshot.plan, snapshot.groups).to_json())  # the monitor's run summary
            if writer is not None and writer.error is not None:  # said on the page, as run says it on its console
                lost = WriteFailure("--trace", str(self.settings.outputs.trace), writer.error.strerror or str(writer.error),
                                    f"{writer.lost} record(s) lost, the trace is incomplete")
                self.feed.update(messages=[{"severity": "error", "message": lost.line(report.outcome, "the run's report").removeprefix("error: ")}])
            return report
        finally:
            self._loop, self.edit_target = None, None
            await deployment.close()

    async def _started(self, app: Application, deployment: Deployment, backend: Any, clock: Clock) -> Coroutine[Any, Any, RunReport]:
        """The run to start: checked from where the robot is now, as ``run`` does (StartRefused with
        the findings when it must not start; a way back first when the robot is elsewhere)."""
        if not self.settings.check:
            return deployment.engine.run(app)
        notes: list[dict[str, Any]] = [{"severity": "info", "message": self._kept}] if self._kept else []

        def say(line: str) -> None:
            notes.append({"severity": "info", "message": line})
            self.feed.update(messages=list(notes))

        measure = backend_measure(app.robot, backend, backend_source(backend))
        setup = setup_for(self.backend_name(app), self._options(app))
        checked = await check_run(deployment.engine, app, setup, self.trajectory_db(app), measure, clock, checked=self._verdict, say=say)
        return checked.run()

    # ------------------------------------------------------------------------ the page's side
    async def command(self, command: str) -> tuple[bool, str]:
        """An operator command from the page, given to the engine on the run's loop; the engine's answer."""
        loop, deployment = self._loop, self._deployment
        if loop is None or deployment is None:
            return False, "no run is going"
        future: Future[tuple[bool, str]] = asyncio.run_coroutine_threadsafe(deployment.engine.operator_command(command, SOURCE), loop)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), 30.0)
        except asyncio.TimeoutError:
            return False, f"{command}: the engine did not answer within 30 s"

    async def breakpoint(self, action: str, operation: str) -> tuple[bool, str, list[str]]:
        """A breakpoint or run-to command from the page (engine/breakpoints.py, source ``studio``): the engine's
        answer and the operations the run pauses before now."""
        loop, deployment = self._loop, self._deployment
        if loop is None or deployment is None:
            return False, "no run is going: a breakpoint in the file is set in the builder (the gutter of its operation)", []
        engine = deployment.engine
        future = asyncio.run_coroutine_threadsafe(engine.breakpoint_command(action, operation, SOURCE), loop)
        ok, answer = await asyncio.wait_for(asyncio.wrap_future(future), 30.0)
        return ok, answer, engine.breakpoints.ids()

    async def speed_override(self, percent: object) -> tuple[bool, str]:
        """The page's speed override: the running motion's (the engine records it, source ``studio``), or the next run's."""
        loop, deployment = self._loop, self._deployment
        if loop is None or deployment is None:
            ok, answer = speed_for_next_run(percent)
            self.speed_percent = float(percent) if ok else self.speed_percent  # type: ignore[arg-type] - checked
            return ok, answer
        future: Future[tuple[bool, str]] = asyncio.run_coroutine_threadsafe(_set_speed(deployment, percent), loop)
        ok, answer = await asyncio.wait_for(asyncio.wrap_future(future), 30.0)
        self.speed_percent = deployment.engine.speed.percent
        return ok, answer

    def safety_stop(self, active: bool) -> tuple[bool, str]:
        """Raise or clear the cell's safety stop input: the engine pauses every group and records it."""
        return publish_safety(self._loop, self._safety, active, "no run is going")


async def _set_speed(deployment: Deployment, percent: object) -> tuple[bool, str]:
    return deployment.engine.speed.set(percent, SOURCE)


def publish_safety(loop: asyncio.AbstractEventLoop | None, publisher: Any, active: bool, absent: str) -> tuple[bool, str]:
    """Raise or clear the cell's safety stop from the page's thread, on the loop of the node that publishes it."""
    if loop is None or publisher is None:
        return False, absent
    loop.call_soon_threadsafe(publisher.publish, Bool(active))
    return True, "safety stop raised: every group pauses" if active else "safety stop cleared: resume to continue"


def final_joint_sample(feed: Feed, robot: RobotModel, backend: Any, t: float) -> None:
    """Where the robot came to rest, read from the back end as the run ends: the bridge publishes joint_states every
    ``state_period``, so its last message may be from before the last motion's end -- and the page's robot and plots
    must end where the robot is."""
    names, positions = backend.joint_state()
    known = dict(zip(names, positions))
    if all(name in known for name in robot.joint_names):
        feed.joint_sample(t, [known[name] for name in robot.joint_names], force=True)


def observe(node: Node, robot: RobotModel, feed: Feed, writers: list[TraceWriter]) -> None:
    """Subscribe ``node`` to what the page shows of a cell: every record through ``writers`` (the trace file
    first, as run does, then the page's feed), the engine's status, each machine's structure, joint positions."""
    observer = RunObserver(node, robot.group_names)
    observe_scene(node, robot, feed)  # the 3D view: goals, located frames, the cell
    watch_safety(node, feed)  # the safety stop's raises and clears by anyone, for the audit (operator_station/cell_audit.py)
    for writer in writers:
        observer.sinks.append(writer.on_status)
        observer.engine_sinks.append(writer.on_engine)
        observer.event_sinks.append(writer.on_event)
        observer.plan_sinks.append(writer.on_plan)  # the plan the start check proved: the trace's and the page's
    observer.engine_sinks.append(lambda status: feed.update(status=_status_json(status)))
    for group in robot.group_names:
        node.create_subscription(typed.MachineStructureMsg, sm_topic(group, "structure"), _decoded(node, SmStructure, lambda s: feed.structure(s.group, _structure_json(s))), LATCHED)
    order = list(robot.joint_names)
    feed.update(joint_names=order)

    known: dict[str, float] = {}  # a cell of several robots: each bridge publishes its own robot's joints

    def on_joints(msg: JointState) -> None:
        known.update(zip(msg.name, msg.position))
        if all(name in known for name in order):
            feed.joint_sample(node.clock.now(), [known[name] for name in order])

    node.create_subscription(JointState, JOINT_STATES, on_joints, SENSOR)


class FeedStream:
    """A text stream of trace lines into the feed: the page's records are the trace's, line for line."""

    def __init__(self, feed: Feed, on_record: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.feed = feed
        self.on_record = on_record
        self.plan = PlanReader("the run")

    def write(self, text: str) -> int:
        for line in text.splitlines():
            if line:
                record = json.loads(line)
                if self.plan.take(record):  # the plan the run was checked against: the timeline's planned bars, as a replay's
                    show_plan(self.feed, self.plan.plan)
                self.feed.append(record)
                if self.on_record is not None:
                    self.on_record(record)
        return len(text)

    def flush(self) -> None:
        """Nothing is buffered."""


def _decoded(node: Node, cls: type[Any], sink: Callable[[Any], None]) -> Callable[[Any], None]:
    def deliver(msg: Any) -> None:
        try:
            sink(typed.from_msg(cls, msg, node.clock))
        except codec.WireError as error:
            log.warning("studio: %s", error)

    return deliver


def _status_json(status: EngineStatus) -> dict[str, Any]:
    return {
        "app": status.app, "state": status.state, "operation_index": status.operation_index, "operation_count": status.operation_count,
        "t": status.t, "operation_id": status.operation_id, "message": status.message, "speed_override": status.speed_override,
        "groups": {g: {"state": p.state, "operation": p.operation, "function": p.function, "position": p.position} for g, p in status.groups.items()},
    }


def _structure_json(structure: SmStructure) -> dict[str, Any]:
    return {"group": structure.group, "initial": structure.initial, "states": list(structure.states),
            "transitions": [{"from": t.source, "signal": t.signal, "to": t.target} for t in structure.transitions]}
