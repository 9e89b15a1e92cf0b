"""``sync="flags"``: every group through its own functions at once, waiting only where the application says so.

A mixin of :class:`~execution_engine.engine.engine.ExecutionEngine` (as :mod:`.commands` is), kept
apart from the operation-by-operation run: each group runs its calls in document order in a task of
its own, with no barrier per operation; a group waits only at a ``wait_flag`` (engine/flags.py), a
synchronised function (its machine meets the partners at the barrier, as in lock-step: same barrier
key, same partner list) or, before a motion, a zone (engine/zones.py).  The first failure the error
policy does not recover from ends every group.  Each group takes its next call afresh from the run's
application (engine/remainder_groups.py keeps where it stands), so a paused run's edit goes on from there.
"""
from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any, Protocol

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.engine.branches import OutcomeBoard, branch_taken, ended_with_outcome
from execution_engine.engine.dispatch import ApplicationAborted
from execution_engine.engine.flags import ENGINE_FUNCTIONS, SET_FLAG, FlagBoard
from execution_engine.engine.remainder_groups import group_steps
from execution_engine.engine.report import GroupError
from execution_engine.machine.table import ERROR_HANDLING, READY
from node_transport.wire import SmRequest, SmResult

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from node_transport.clock import Clock
    from execution_engine.engine.dispatch import Dispatch
    from execution_engine.engine.group_link import GroupLink
    from execution_engine.engine.remainder_swap import Remainder
    from execution_engine.engine.report import RunReport
    from execution_engine.engine.zones import ZoneBoard


def meeting(operation: Operation, call: Call, catalog: Catalog) -> dict[str, Call]:
    """The group's call and, for a synchronised function, its partners' (one barrier key, one partner list)."""
    spec = catalog.get(call.function)
    if spec is None or not spec.sync:
        return {call.group: call}
    return {g: c for g, c in operation.calls.items() if (s := catalog.get(c.function)) is not None and s.sync == spec.sync}


class GroupsResume(Protocol):
    """A crash resume's side of flags mode (:class:`~execution_engine.checkpoint.resume.ResumePlan`)."""

    async def position_groups(self, engine: Any, steps: Mapping[str, Sequence[tuple[Operation, Call]]]) -> dict[str, int]: ...


class FlagsMode:
    """The engine's run of an application with ``sync="flags"``."""

    if TYPE_CHECKING:  # the engine's own state and steps, which these methods use
        app: Application | None
        report: RunReport | None
        catalog: Catalog
        clock: Clock
        links: dict[str, GroupLink]
        zones: ZoneBoard
        flags: FlagBoard
        function_timeout: float
        service_timeout: float
        tested: frozenset[tuple[str, str]]
        outcome_board: OutcomeBoard
        _operation: Operation | None
        _op_index: int
        _stop_reason: str | None
        remainder: Remainder

        def _sits_out(self, call: Call) -> bool: ...
        def note_branch(self, event: str, operation: str, group: str, function: str | None, outcome: str, message: str) -> None: ...
        async def _gate(self) -> bool: ...
        async def _group_gate(self, group: str, operation: Operation, partners: tuple[str, ...]) -> bool: ...
        def _dispatch(self, operation: Operation, calls: dict[str, Call], attempt: int, only: str | None = None) -> dict[str, Dispatch]: ...
        async def _abandon(self, pending: dict[str, Dispatch], group: str, why: str) -> None: ...
        async def _await_ready(self, groups: tuple[str, ...]) -> None: ...
        def _retry_plan(self, results: list[SmResult], attempt: int) -> tuple[bool, str]: ...
        def _set_state(self, state: str, message: str | None = None) -> None: ...
        async def _pause_groups(self, groups: list[str]) -> None: ...
        async def _alarm(self, group: str, error: str, plan: str, timeout: float) -> tuple[bool, str]: ...
        def _note_recovery(self, recovery: str) -> None: ...
        async def _go_safe(self, in_work: list[str]) -> None: ...

    async def _run_groups(self, app: Application, resume: GroupsResume | None = None) -> None:
        """Each group through its own calls at once; the first failure ends them all.  ``resume`` (after a crash):
        each group goes on after the calls it had done (checkpoint/resume.py), the flags they set set again."""
        groups = [g for g in app.robot.group_names if group_steps(app, g, self._sits_out)]
        walk = self.remainder.groups
        walk.start(app.robot.group_names, self._sits_out)  # each group's position: a paused run's edit, a resume
        for group in set(app.robot.group_names) - set(groups):
            walk.finish(group)
        if resume is not None:
            for group, done in (await resume.position_groups(self, {g: walk.steps(app, g) for g in groups})).items():
                for operation, call in walk.steps(app, group)[:done]:
                    if call.function == SET_FLAG:
                        self.flags.set(group, call.params[0], operation.id)
                    self.zones.ended(operation.id, group)
                    walk.passed(group, operation)
        tasks = {g: asyncio.ensure_future(self._run_group(g, group_steps(app, g, self._sits_out))) for g in groups}
        try:
            done, _ = await asyncio.wait(tasks.values(), return_when=asyncio.FIRST_EXCEPTION)
            failed = next((t for t in done if not t.cancelled() and t.exception() is not None), None)
            if failed is not None:
                for task in tasks.values():
                    task.cancel()
                await asyncio.gather(*tasks.values(), return_exceptions=True)
                error = failed.exception()
                assert error is not None
                raise error
        finally:
            for task in tasks.values():
                task.cancel()

    async def _run_group(self, group: str, steps: list[tuple[Operation, Call]]) -> None:
        """One group's calls in order, each when the one before succeeded (retried as the policy says)."""
        report, walk = self.report, self.remainder.groups
        assert report is not None
        while self.app is not None and (step := walk.step(self.app, group)) is not None:  # ``steps`` afresh: an edit while paused
            if not await self._gate():
                raise ApplicationAborted(self._stop_reason or "stopped")
            if (step := walk.step(self.app, group)) is None:
                break
            operation, call = step
            if not await self._branch_runs(group, operation):
                continue
            if not await self._group_gate(group, operation, tuple(meeting(operation, call, self.catalog))):  # a breakpoint there
                raise ApplicationAborted(self._stop_reason or "stopped")
            if (fresh := walk.step(self.app, group)) is None:
                break
            if fresh != step:  # swapped while held there: what is there now (its breakpoint was this hold)
                operation, call = fresh
                if not await self._branch_runs(group, operation):
                    continue
            walk.enter(group, operation)
            self._operation = operation
            index = self.app.operations.index(operation) if self.app is not None else 0
            self._op_index = index
            attempt = 1
            while True:
                dispatch = self._dispatch(operation, meeting(operation, call, self.catalog), attempt, only=group)[group]
                remaining = dispatch.deadline - self.clock.now()
                try:
                    result = await self.clock.wait_for(asyncio.shield(dispatch.future), max(0.0, remaining))
                except asyncio.TimeoutError:
                    await self._abandon({group: dispatch}, group, f"no result within {self.function_timeout:g} s")
                    raise  # unreachable: _abandon raises ApplicationAborted
                report.group_busy[group] += max(0.0, result.t_end - result.t_start)
                report.group_functions[group] += 1
                if await ended_with_outcome(self, operation, group, result, self._stop_reason is not None) or result.outcome == "succeeded":
                    if call.function not in ENGINE_FUNCTIONS:
                        await self._await_ready((group,))
                    self.zones.ended(operation.id, group)
                    walk.passed(group, operation)
                    break
                await self._on_group_failure(group, operation, dispatch.request, result)
                attempt += 1
        walk.finish(group)

    async def _branch_runs(self, group: str, operation: Operation) -> bool:
        """Under an <if>: once the outcome it tests is decided, whichever group decides it, whether it runs (left out:
        passed, holding no zone)."""
        report = self.report
        assert report is not None
        if not operation.when:
            return True
        await self.outcome_board.wait(operation, report)
        if branch_taken(self, operation, report):
            return True
        self.zones.ended(operation.id, group)
        self.remainder.groups.passed(group, operation)
        return False

    async def _on_group_failure(self, group: str, operation: Operation, request: SmRequest, result: SmResult) -> None:
        """The error policy for one group's failed function in flags mode; returns to retry, raises to end."""
        app, report = self.app, self.report
        assert app is not None and report is not None
        error = result.error or result.outcome
        fault = result.fault.value if result.fault is not None else None
        report.errors.append(GroupError(group, operation.id, request.function, error, request.attempt, self.clock.now(), fault))
        if result.outcome == "preempted" or self._stop_reason is not None:
            raise ApplicationAborted(self._stop_reason or f"{group} was stopped: {error}")
        what = f"{group}: {request.function} failed: {error}"
        others = [g for g in self.links if g != group]
        retry, plan = self._retry_plan([result], request.attempt)
        self._set_state("error", f"{what} - {plan}")
        await self._pause_groups(others)
        unanswered = ""
        if app.error_policy.action == "alarm" and not retry:
            retry, unanswered = await self._alarm(group, error, plan, app.error_policy.alarm_timeout)
        else:
            self._note_recovery(plan)
        if not retry:
            for other in others:
                await self.links[other].command("stop")
            if app.error_policy.action == "safe_pose" and app.error_policy.safe_pose:
                await self._go_safe(list(self.links))
            raise ApplicationAborted(what + unanswered)
        report.retries += 1
        link = self.links[group]
        if link.state == ERROR_HANDLING:
            await link.command("reset")
        if not await link.wait_state((READY,), self.service_timeout):
            raise ApplicationAborted(f"{group} could not be reset for a retry (it is in {link.state})")
        for other in others:
            await self.links[other].command("resume")
        self._set_state("running")
