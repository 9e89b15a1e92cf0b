"""The execution engine node (paper §2.2.2): orchestrates an application over the group machines.

Operations run in document order.  Within an operation every group's function is dispatched at
once and runs concurrently; operation N+1 is dispatched only when every group has returned a
result for N and is back in Ready -- the paper's guarantee that keeps the arms coordinated.  A
group whose function is ``wait`` (no seconds) sits the operation out.

When a function fails, dispatching stops, the other groups are paused, and the application's
error policy decides: retry (reset the machine, send the function again) -- only when the
fault's kind can go away by itself (:mod:`.faults`) --, then either ``abort`` (stop everything,
end), ``safe_pose`` (stop; retreat, slow down and move every group to a named joint pose,
:mod:`.safe_pose`; end) or ``alarm`` (hold everything until an operator resets, then retry; or
stops; ``alarm_timeout`` on the operator's wall clock, :mod:`.wall_clock`).
Operators start, pause, resume, step, stop and reset the whole application through the engine's
services (or, in its own process, :meth:`ExecutionEngine.operator_command`); a ``true`` on
``/cell/safety_stop`` pauses every group until an operator resumes.  Every command and every
change of the engine's state is published on ``execution_engine/events`` (traces) and every
command is listed in the run report with its run time and source (:mod:`.commands`).
"""
from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Protocol

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.engine.branches import OutcomeBoard, branch_taken, ended_with_outcome
from execution_engine.engine.cell_tf import CellFramesBroadcaster
from execution_engine.engine.breakpoints import BreakpointControl
from execution_engine.engine.dispatch import ApplicationAborted, Dispatch, ResultWaiter
from execution_engine.engine.faults import verdict
from execution_engine.engine.flags import ENGINE_FUNCTIONS, FlagBoard
from execution_engine.engine.flags_mode import FlagsMode
from execution_engine.engine.group_link import GroupLink
from execution_engine.engine.remainder_swap import Remainder
from execution_engine.engine.remainder_groups import bare_wait
from execution_engine.engine.report import GroupError, RunReport
from execution_engine.engine.safe_pose import SafePosePlan, go_safe
from execution_engine.engine.speed import SpeedOverride
from execution_engine.engine.zones import ZoneBoard
from execution_engine.machine.table import ERROR_HANDLING, FINISH, PAUSE, READY, WORKING_STATES
from node_transport import typed
from node_transport.bounded import declare_bounded
from node_transport.carriage import TypedPublisher
from node_transport.msgs import Bool, Trigger
from node_transport.port import Node
from node_transport.qos import EVENTS, LATCHED
from node_transport.wall_clock import RealWallClock, WallClock
from node_transport.wire import (
    ENGINE_CELL,
    ENGINE_EVENTS,
    ENGINE_SERVICES,
    ENGINE_STATUS,
    SAFETY_STOP,
    CellSnapshot,
    EngineEvent,
    EngineStatus,
    GroupProgress,
    SmRequest,
    SmResult,
    engine_service,
)


class ResumePoint(Protocol):
    """Where a resumed run starts (:class:`execution_engine.checkpoint.resume.ResumePlan`)."""

    index: int
    outcomes: dict[str, str]  # the tested functions' outcomes before the crash: the same branches again

    async def first_operation(self, engine: ExecutionEngine, operation: Operation) -> Operation: ...
    async def position_groups(self, engine: ExecutionEngine, steps: Mapping[str, Sequence[tuple[Operation, Call]]]) -> dict[str, int]: ...


class ExecutionEngine(BreakpointControl, FlagsMode):  # BreakpointControl extends OperatorCommands
    """One engine node; runs one application at a time."""

    def __init__(
        self,
        node: Node,
        catalog: Catalog,
        wall_clock: WallClock | None = None,
        *,
        operators: bool = True,
        hold_for_operators: bool = False,
    ) -> None:
        self.node = node
        self.clock = node.clock
        #: Whether anyone can answer an alarm (a terminal console or service clients); if not, an
        #: alarm ends the run at once instead of waiting for nobody.
        self.operators = operators
        #: Whether the operators are outside the process (a terminal): then simulated time stands
        #: still while the run waits for them (Clock.held); tests that play the operator on the
        #: run's own clock leave it off.
        self.hold_for_operators = hold_for_operators
        #: The operator's clock (alarm_timeout): wall time even when the run clock is scaled or simulated.
        self.wall_clock: WallClock = wall_clock or RealWallClock()
        #: The functions applications may call: the library the wiring chose (execution_engine.function_library).
        self.catalog = catalog
        self.autostart = bool(node.declare_parameter("autostart", True, "start running as soon as the machines are ready"))
        self.startup_timeout = float(declare_bounded(node, "startup_timeout", 15.0, "how long to wait for the group machines (s)"))
        self.function_timeout = float(declare_bounded(node, "function_timeout", 3600.0, "longest a function may take (s)"))
        self.service_timeout = float(declare_bounded(node, "service_timeout", 5.0, "machine service call timeout (s)"))
        # in one process both cross as the objects themselves (node_transport/carriage.py)
        self._status_pub = TypedPublisher(node, EngineStatus, ENGINE_STATUS, LATCHED)  # late joiners see where the run stands
        self._events_pub = TypedPublisher(node, EngineEvent, ENGINE_EVENTS, EVENTS)  # every state change and command, once
        self._cell_pub = node.create_publisher(typed.CellSnapshotMsg, ENGINE_CELL, LATCHED)
        self._cell_frames = CellFramesBroadcaster(node)  # the cell's frames on tf_static, for RViz
        node.create_subscription(Bool, SAFETY_STOP, self._on_safety, LATCHED)
        for command in ENGINE_SERVICES:
            node.create_service(Trigger, engine_service(command), lambda req, c=command: self._on_service(c, req))
        self.links: dict[str, GroupLink] = {}
        self.app: Application | None = None
        self._cell_name = ""  # the cell model the requests of this run refer to
        self.report: RunReport | None = None
        self.state = "idle"
        self._op_index = 0
        self._operation: Operation | None = None
        self.tested: frozenset[tuple[str, str]] = frozenset()  # the functions an <if> tests (their outcomes are kept)
        self.outcome_board = OutcomeBoard()  # sync="flags": which tested functions have ended
        self._message = ""
        self._paused = False
        self._stepping = False
        self._stop_reason: str | None = None
        self._safety_active = False
        self._control = asyncio.Event()  # set whenever pause/resume/stop/step/reset/start happens
        self._start_requested = False
        self._alarm_reset = False
        self._alarm_skip = self._skippable = False  # an interrupted function's alarm can be answered with skip
        self._progress: dict[str, GroupProgress] = {}
        self._tasks: set[asyncio.Task[tuple[bool, str]]] = set()  # safety-stop pauses under way
        self._results = ResultWaiter(self.clock)  # the operation loop's wait for a result: the links wake it
        self.flags = FlagBoard(self.clock, self._publish_flag, lambda: self._stop_reason is not None)  # set_flag / wait_flag (engine/flags.py)
        self.zones = ZoneBoard(node, self.catalog, self._publish_flag)  # interference zones, both modes (engine/zones.py)
        self.breakpoints = self._serve_breakpoints()  # break="true" and the run-time ones (engine/breakpoints.py)
        self.speed = SpeedOverride(node, self._record_target, self._publish_status, lambda: self.state)  # on the path, every back end (engine/speed.py)
        self.remainder = Remainder(self._publish_event, self._cell_frames.located)  # a paused run's edit (engine/remainder_swap.py)

    # ============================================================================ running
    async def run(self, app: Application, resume: ResumePoint | None = None) -> RunReport:
        """Run ``app`` to its end; always returns a report, never raises for robot faults.

        ``resume`` (after a crash, :mod:`execution_engine.checkpoint.resume`): operations before
        ``resume.index`` completed in an earlier run and are not run again; the operation at it is
        run as ``resume.first_operation`` makes it, which first asks about interrupted groups."""
        self._reset_run_state()
        self.app = app
        self.tested = app.tested()
        self.outcome_board.start()
        report = RunReport(app=app.name, operations_total=len(app.operations), t_start=self.clock.now())
        if resume is not None:
            report.outcomes.update(resume.outcomes)
        self.report = report
        self.zones.start(app, self.flags.waits, resume.index if resume is not None else 0)
        self.flags.zones = self.zones
        self._set_state("idle", "")
        for group in app.robot.group_names:
            if group not in self.links:
                self.links[group] = GroupLink(self.node, group, self.service_timeout)
                self.links[group].on_result = self._results.wake
            report.group_busy.setdefault(group, 0.0)
            report.group_functions.setdefault(group, 0)
        self._cell_name = ""
        if app.cell is not None:
            snapshot: CellSnapshot = app.cell.to_snapshot()
            self._cell_name = snapshot.name
            self._cell_pub.publish(typed.to_msg(snapshot, self.clock))
            self._cell_frames.publish_cell(snapshot, app.robot)
        try:
            await self._await_machines()
            await self._await_start()
            await asyncio.sleep(0)  # what came meanwhile (a simulator's /clock) is taken in before the time is read
            report.t_start = self.clock.now()  # the cycle starts with the first operation, as the dry run's does
            self._set_state("running")
            if app.sync == "flags":  # no barrier per operation: each group in its own order (engine/flags_mode.py)
                await self._run_groups(app, resume)
                report.operations_done = len((self.app or app).operations)  # the edited application's, after a swap
            for index, operation in self.remainder.operations(self, resume.index + 1 if resume is not None else 0) if app.sync != "flags" else ():
                if resume is not None and index < resume.index:
                    report.operations_done = index + 1  # done before the crash
                    continue
                if resume is not None and index == resume.index:
                    operation = await resume.first_operation(self, operation)
                if not await self._gate_at(index, operation):  # paused there at a breakpoint (engine/breakpoints.py)
                    break
                operation = self.remainder.take(self, index, operation)  # an edit while paused before it may have changed it
                if not branch_taken(self, operation, report):
                    for group in operation.calls:  # left out: it holds no zone
                        self.zones.ended(operation.id, group)
                    report.operations_done = index + 1
                    continue
                self._op_index, self._operation = index, operation
                self._set_state("stepping" if self._stepping else "running")
                await self._run_operation(operation)
                report.operations_done = index + 1
                if self._stepping:
                    self._paused = True
            if self._stop_reason is not None:
                report.outcome, report.message = "stopped", self._stop_reason
        except ApplicationAborted as abort:
            report.outcome = "stopped" if self._stop_reason is not None else "failed"
            report.message = str(abort)
        self._set_state("stopping", report.message)  # why it stops: the operator's stop, the failure, or nothing to say
        report.finished_cleanly = await self._end_all()
        report.t_end = self.clock.now()
        self.zones.close()
        for group, seconds in self.zones.waited().items():  # a zone wait falls inside a function: idle, not busy
            report.group_busy[group] = max(0.0, report.group_busy.get(group, 0.0) - seconds)
        report.flag_waits = list(self.flags.waits)
        self._set_state({"finished": "finished", "failed": "failed", "stopped": "stopped"}[report.outcome], report.message)
        return report

    def _reset_run_state(self) -> None:
        """A long-lived engine node runs one application after another: nothing carries over."""
        self._op_index, self._operation, self._message = 0, None, ""
        self._paused = self._stepping = self._alarm_reset = False
        self._stop_reason = None
        self._start_requested = False
        self._progress.clear()
        self.flags = FlagBoard(self.clock, self._publish_flag, lambda: self._stop_reason is not None)

    async def _await_machines(self) -> None:
        """Every group machine must be up (Ready, or Finish from an earlier run) before we start."""
        waits = {g: link.wait_state((READY, FINISH, ERROR_HANDLING), self.startup_timeout) for g, link in self.links.items()}
        results = dict(zip(waits, await asyncio.gather(*waits.values())))
        missing = [g for g, ok in results.items() if not ok]
        if missing:
            raise ApplicationAborted(
                f"no group machine answered for {', '.join(missing)} within {self.startup_timeout:g} s "
                "(is group_machine running for each group, and the bridge?)"
            )
        unlinked = [g for g, ok in zip(self.links, await asyncio.gather(*(link.link(self.startup_timeout) for link in self.links.values()))) if not ok]
        if unlinked:
            raise ApplicationAborted(
                f"the request and result topics of {', '.join(unlinked)} did not match within {self.startup_timeout:g} s"
            )
        for group, link in self.links.items():
            if link.state == ERROR_HANDLING:
                ok, message = await link.command("reset")
                if not ok or not await link.wait_state((READY,), self.service_timeout):
                    raise ApplicationAborted(f"{group} is in ErrorHandling from an earlier run and would not reset: {message}")

    async def _await_start(self) -> None:
        if self.autostart:
            return
        self._set_state("idle", "waiting for start")
        while not self._start_requested and self._stop_reason is None:
            await self._wait_control()
        if self._stop_reason is not None:
            raise ApplicationAborted(self._stop_reason)

    async def _gate(self) -> bool:
        """Hold between operations while paused; False when the application must stop."""
        while self._paused and self._stop_reason is None:
            stepped = f"one step done (operation {self._operation.id}): step or resume to go on" if self._stepping and self._operation else "paused"
            self._set_state("paused", None if self.state == "paused" else stepped)
            with self._operator_wait():  # between operations, only an operator moves the run on
                await self._wait_control()
        return self._stop_reason is None

    async def _wait_control(self) -> None:
        self._control.clear()
        await self._control.wait()

    def _poke(self) -> None:
        self._control.set()

    def _operator_wait(self) -> contextlib.AbstractContextManager[None]:
        return self.clock.held() if self.hold_for_operators else contextlib.nullcontext()

    # ---------------------------------------------------------------------- operations
    def _sits_out(self, call: Call) -> bool:
        assert self.app is not None
        return bare_wait(call, self.catalog, self.app)

    def _requests(self, operation: Operation, calls: dict[str, Call], attempt: int) -> dict[str, SmRequest]:
        """One request per group; synchronised functions get a shared barrier key and partner list."""
        assert self.app is not None
        by_sync: dict[str, list[str]] = {}
        for group, call in calls.items():
            spec = self.catalog.get(call.function)
            if spec is not None and spec.sync:
                by_sync.setdefault(spec.sync, []).append(group)
        requests = {}
        for group, call in calls.items():
            spec = self.catalog.get(call.function)
            sync, partners = "", ()
            if spec is not None and spec.sync:
                members = by_sync[spec.sync]
                leaders = [g for g in members if calls[g].function == "master_move"]
                partners = tuple(leaders + [g for g in members if g not in leaders])
                sync = f"{self.app.name}:{operation.id}:{spec.sync}:{attempt}"
            requests[group] = SmRequest(
                id=self.links[group].new_id(),
                operation=operation.id,
                function=call.function,
                params=call.params,
                attempt=attempt,
                sync=sync,
                partners=partners,
                cell=self._cell_name,
            )
        return requests

    def _dispatch(self, operation: Operation, calls: dict[str, Call], attempt: int, only: str | None = None) -> dict[str, Dispatch]:
        """Send each call's request (``only``: just that group's, the others only share its barrier key)."""
        sent = {}
        deadline = self.clock.now() + self.function_timeout
        for group, request in self._requests(operation, calls, attempt).items():
            if only is not None and group != only:
                continue
            wakes = request.function not in ENGINE_FUNCTIONS
            if not wakes:  # flags are the engine's own
                assert self.app is not None
                future = self.flags.result(request, group, self.catalog, self.app)
            else:
                future = self.links[group].send(request)
            sent[group] = Dispatch(calls[group], request, future, deadline, wakes)
            self.zones.register(request.id, operation.id, group)
            self._progress[group] = GroupProgress(self.links[group].state, operation.id, request.function)
        self._publish_status()
        return sent

    async def _run_operation(self, operation: Operation) -> None:
        calls = {g: c for g, c in operation.calls.items() if not self._sits_out(c)}
        for group in operation.calls.keys() - calls.keys():  # done before a resume, skipped: holds no zone
            self.zones.ended(operation.id, group)
        pending = self._dispatch(operation, calls, attempt=1)
        report = self.report
        assert report is not None
        while pending:
            futures = {d.future: g for g, d in pending.items()}
            horizon = min(d.deadline for d in pending.values()) - self.clock.now()
            done = [d.future for d in await self._results.first(pending.values(), horizon)]
            if not done:
                late = [g for g, d in pending.items() if d.deadline <= self.clock.now()]
                for group in late:
                    await self._abandon(pending, group, f"no result within {self.function_timeout:g} s")
                continue
            failed: list[tuple[str, asyncio.Future[SmResult]]] = []
            for future in done:
                group = futures[future]
                result = future.result()
                report.group_busy[group] += max(0.0, result.t_end - result.t_start)
                report.group_functions[group] += 1
                if await ended_with_outcome(self, operation, group, result, self._stop_reason is not None) or result.outcome == "succeeded":
                    del pending[group]
                    self.zones.ended(operation.id, group)
                else:
                    failed.append((group, future))
            for group, future in failed:
                # a sync partner's failure may already have been handled (and retried) with the first one
                if group in pending and pending[group].future is future:
                    await self._on_failure(operation, pending, group, future.result())
        await self._await_ready(tuple(calls))

    async def _await_ready(self, groups: tuple[str, ...]) -> None:
        for group in groups:
            if not await self.links[group].wait_state((READY,), self.service_timeout):
                raise ApplicationAborted(f"{group} did not return to Ready after its result (it is in {self.links[group].state})")

    async def _abandon(self, pending: dict[str, Dispatch], group: str, why: str) -> None:
        dispatch = pending.pop(group)
        self.links[group].forget(dispatch.request.id)
        await self.links[group].command("stop")
        assert self.report is not None
        self.report.errors.append(GroupError(group, dispatch.request.operation, dispatch.request.function, why, dispatch.request.attempt, self.clock.now()))
        raise ApplicationAborted(f"{group}: {dispatch.request.function}: {why}")

    # ------------------------------------------------------------------- error policy
    async def _on_failure(self, operation: Operation, pending: dict[str, Dispatch], group: str, result: SmResult) -> None:
        """Apply the application's error policy to a failed function (and its sync partners)."""
        assert self.app is not None and self.report is not None
        dispatch = pending[group]
        error = result.error or result.outcome
        fault = result.fault.value if result.fault is not None else None
        self.report.errors.append(GroupError(group, operation.id, dispatch.request.function, error, dispatch.request.attempt, self.clock.now(), fault))
        if result.outcome == "preempted" or self._stop_reason is not None:
            raise ApplicationAborted(self._stop_reason or f"{group} was stopped: {error}")
        failed = {group: dispatch}
        for partner in dispatch.request.partners:  # a synchronised function fails for all of its partners
            if partner != group and partner in pending:
                failed[partner] = pending[partner]
        others = [g for g in pending if g not in failed]
        what = f"{group}: {dispatch.request.function} failed: {error}"
        policy = self.app.error_policy
        attempt = dispatch.request.attempt
        _, plan = self._retry_plan([result], attempt)  # said at once; the partners' results may change it
        self._set_state("error", f"{what} - {plan}")
        await self._pause_groups(others)
        await self._collect(failed, group)
        partner_results = [d.future.result() for d in failed.values() if d.future.done() and not d.future.cancelled()]
        retry, plan = self._retry_plan(partner_results or [result], attempt)
        self._message = f"{what} - {plan}"
        unanswered = ""
        if policy.action == "alarm" and not retry:
            retry, unanswered = await self._alarm(group, error, plan, policy.alarm_timeout)  # notes how it was answered
        else:
            self._note_recovery(plan)
        if not retry:
            await self._stop_groups(others, pending)
            if policy.action == "safe_pose" and policy.safe_pose:
                await self._go_safe([g for g in pending if pending[g].call.function != "wait"])
            raise ApplicationAborted(what + unanswered)
        self.report.retries += 1
        await self._retry(operation, pending, failed, attempt + 1)
        for other in others:
            await self.links[other].command("resume")
        self._set_state("running")

    def _retry_plan(self, results: list[SmResult], attempt: int) -> tuple[bool, str]:
        """Whether the policy retries automatically, and the words for the report and the console."""
        assert self.app is not None
        retries = self.app.error_policy.retries
        retryable, why = verdict(r.fault for r in results)
        if not retryable:
            return False, f"not retried: {why}"
        if attempt > retries:
            return False, f"not retried: the error policy allows {retries} retr{'y' if retries == 1 else 'ies'}"
        return True, f"retrying (attempt {attempt + 1} of {retries + 1}): {why}"

    def _note_recovery(self, recovery: str) -> None:
        """Say on the latest error what the policy did about it."""
        assert self.report is not None and self.report.errors
        self.report.errors[-1] = replace(self.report.errors[-1], recovery=recovery)

    async def _pause_groups(self, groups: list[str]) -> None:
        """Pause running groups and wait (bounded) until the pause has landed."""
        for group in groups:
            await self.links[group].command("pause")
        for group in groups:
            await self.links[group].wait_state((PAUSE, READY, ERROR_HANDLING), self.service_timeout)

    async def _collect(self, failed: dict[str, Dispatch], first: str) -> None:
        """Wait for the failed partners' own results (they fail through the barrier)."""
        for group, dispatch in failed.items():
            if group == first or dispatch.future.done():
                continue
            try:
                await self.clock.wait_for(asyncio.shield(dispatch.future), self.service_timeout * 2)
            except asyncio.TimeoutError:
                await self.links[group].command("stop")

    async def _retry(self, operation: Operation, pending: dict[str, Dispatch], failed: dict[str, Dispatch], attempt: int) -> None:
        for group in failed:
            link = self.links[group]
            if link.state == ERROR_HANDLING:
                await link.command("reset")
            if not await link.wait_state((READY,), self.service_timeout):
                raise ApplicationAborted(f"{group} could not be reset for a retry (it is in {link.state})")
        resent = self._dispatch(operation, {g: d.call for g, d in failed.items()}, attempt)
        pending.update(resent)

    def note_branch(self, event: str, operation: str, group: str, function: str | None, outcome: str, message: str) -> None:
        """An outcome a tested function ended with, or an operation its branch left out: an event for the
        trace, the timeline, the run report and the checkpoint (a resume takes the same branches)."""
        self._publish_event(EngineEvent(event, self.clock.now(), self.state, operation, message=message, command=function, source=group, answer=outcome))  # type: ignore[arg-type]

    def announce(self, message: str) -> None:
        """Say something about the run in the engine's status and events (and so in the trace).

        Already running, there is no change of state to carry it, so the announcement is an event
        of its own (``running`` to ``running``): it belongs to this moment, not to the next change.
        """
        previous = self.state
        self._set_state("running", message)
        if previous == "running":
            operation = self._operation.id if self._operation else None
            self._publish_event(EngineEvent("state", self.clock.now(), "running", operation, from_state="running", message=message))

    async def _stop_groups(self, groups: list[str], pending: dict[str, Dispatch]) -> None:
        """Stop running groups and wait (bounded) for their preempted results."""
        for group in groups:
            await self.links[group].command("stop")
        for group in groups:
            dispatch = pending.get(group)
            if dispatch is None:
                continue
            try:
                await self.clock.wait_for(asyncio.shield(dispatch.future), self.service_timeout * 2)
            except asyncio.TimeoutError:
                self.links[group].forget(dispatch.request.id)

    # ------------------------------------------------------------------------- safe pose
    async def _go_safe(self, in_work: list[str]) -> None:
        """Retreat, slow down and move every group the pose covers to it (:mod:`.safe_pose`)."""
        assert self.app is not None and self.report is not None
        plan = SafePosePlan.build(self.app, self.catalog, in_work)
        self._set_state("error", f"moving to safe pose {plan.pose!r}")
        unlinked = [g for g, ok in zip(self.links, await asyncio.gather(*(link.link(self.startup_timeout) for link in self.links.values()))) if not ok]
        if unlinked:
            raise ApplicationAborted(
                f"the request and result topics of {', '.join(unlinked)} did not match within {self.startup_timeout:g} s"
            )
        self.report.safe_pose = plan.pose
        self.report.safe_pose_steps.extend(await go_safe(self, self.app, plan))
        missed = self.report.safe_pose_missed
        reached = "NOT reached by " + ", ".join(missed) if missed else "reached"
        self._set_state("error", f"safe pose {plan.pose!r} {reached}")

    async def run_stage(self, stage: str, calls: dict[str, Call]) -> dict[str, SmResult | None]:
        """One stage of the way to the safe pose, for every group at once (a :class:`StageRunner`)."""
        assert self.app is not None
        operation = Operation(id=f"safe_pose/{stage}", name=f"safe pose: {stage}", line=0, col=0, calls=calls)
        sent = self._dispatch(operation, calls, attempt=1)
        results: dict[str, SmResult | None] = {}
        for group, dispatch in sent.items():
            try:
                results[group] = await self.clock.wait_for(dispatch.future, self.function_timeout)
            except asyncio.TimeoutError:
                self.links[group].forget(dispatch.request.id)
                results[group] = None
        return results

    async def make_ready(self, groups: Iterable[str]) -> list[str]:
        """Reset machines left in ErrorHandling; the groups that are not in Ready afterwards."""
        stuck = []
        for group in groups:
            link = self.links[group]
            if link.state == ERROR_HANDLING:
                await link.command("reset")
            if not await link.wait_state((READY,), self.service_timeout):
                stuck.append(group)
        return stuck

    async def _end_all(self) -> bool:
        """Send every machine to Finish; True when all of them got there."""
        for group, link in self.links.items():
            if link.state in (*WORKING_STATES, PAUSE):
                await link.command("stop")
                await link.wait_state((ERROR_HANDLING, READY), self.service_timeout)
            link.send_end()
        reached = await asyncio.gather(*(link.wait_state((FINISH,), self.service_timeout) for link in self.links.values()))
        return all(reached)

    # ---------------------------------------------------------------------------- status
    def _set_state(self, state: str, message: str | None = None) -> None:
        """Change (or restate) the engine's state and publish it.

        A message is the reason of *this* change: a change without one has none, so a line such
        as STOPPING never carries the reason of an earlier change ("resumed by ...").  Restating
        the state without a message keeps the reason it was entered with.
        """
        previous = self.state
        self.state = state
        if message is not None:
            self._message = message
        elif state != previous:
            self._message = ""
        if state != previous:
            operation = self._operation.id if self._operation else None
            self._publish_event(EngineEvent("state", self.clock.now(), state, operation, from_state=previous, message=self._message))
        self._publish_status()

    def _publish_flag(self, group: str, flag: str, state: str, operation: str | None, kind: str = "flag") -> None:
        """A flag set, or a group's wait for a flag or zone starting or ending: an EngineEvent (trace, timeline) and the status."""
        words = {"set": "sets", "waiting": "waits for", "passed": "passes", "timeout": "gave up waiting for", "stopped": "stopped waiting for"}
        message = f"{group} {words.get(state, state)} {kind} {flag!r}" if kind == "flag" or state != "passed" else f"{group} enters zone {flag!r}"
        self._publish_event(EngineEvent("flag", self.clock.now(), state, operation, message=message, command=flag, source=group, answer=kind))
        self._publish_status()

    def _publish_event(self, event: EngineEvent) -> None:
        if self._events_pub.get_subscription_count() > 0:
            self._events_pub.publish(event)

    def _publish_status(self) -> None:
        if self._status_pub.get_subscription_count() == 0:
            return
        app = self.app
        groups = {
            g: GroupProgress(
                f"waiting for {self.flags.waiting_for(g)}" if self.flags.waiting_for(g) else link.state,
                *(self._progress[g].operation, self._progress[g].function) if g in self._progress else (None, None),
                position=self.remainder.groups.position(app, g) if app is not None and app.sync == "flags" else "",
            )
            for g, link in self.links.items()
        }
        status = EngineStatus(
            app=app.name if app else "",
            state=self.state,  # type: ignore[arg-type]
            operation_index=self._op_index + 1 if self._operation else 0,
            operation_count=len(app.operations) if app else 0,
            t=self.clock.now(),
            operation_id=self._operation.id if self._operation else None,
            groups=groups,
            message=self.speed.status_message(self._message), speed_override=self.speed.percent,
        )
        self._status_pub.publish(status)
