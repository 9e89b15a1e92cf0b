"""Outcome branches at run time: which operations an ``<if>``/``<else>`` lets run, and the named
outcome a tested function ends with.

A function an ``<if>`` tests keeps its named outcome in the run report (``outcomes``); a fault of
the kind one of its outcomes names (vision: ``not_found``) ends it with that outcome instead of
an error -- its machine is reset to Ready and no error policy applies, since the application
says what to do.  An operation whose conditions are not met is left out and said so in the
events, so the trace, the timeline and the run report show the branch taken.
"""
from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Protocol

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Operation
from execution_engine.engine.dispatch import ApplicationAborted
from execution_engine.engine.group_link import GroupLink
from execution_engine.engine.report import RunReport
from execution_engine.machine.table import ERROR_HANDLING, READY
from node_transport.wire import SmResult


class BranchEngine(Protocol):
    """What of the engine the branches use."""

    catalog: Catalog
    links: dict[str, GroupLink]
    report: RunReport | None
    tested: frozenset[tuple[str, str]]
    service_timeout: float
    outcome_board: OutcomeBoard

    def note_branch(self, event: str, operation: str, group: str, function: str | None, outcome: str, message: str) -> None: ...


class OutcomeBoard:
    """Which tested functions' outcomes are decided (sync="flags": a group whose next operation is
    under an <if> on another group's function waits until that function has ended -- or was itself
    left out by a branch, which decides it too: no outcome)."""

    def __init__(self) -> None:
        self._decided: dict[tuple[str, str], asyncio.Event] = {}
        self.left_out: set[str] = set()  # operations a branch left out and said so (once, whichever group saw it first)

    def start(self) -> None:
        self._decided.clear()
        self.left_out.clear()

    def _event(self, key: tuple[str, str]) -> asyncio.Event:
        return self._decided.setdefault(key, asyncio.Event())

    def decided(self, operation: Operation, groups: Iterable[str]) -> None:
        for group in groups:
            self._event((operation.id, group)).set()

    async def wait(self, operation: Operation, report: RunReport) -> None:
        """Until every outcome ``operation``'s conditions test is decided."""
        for condition in operation.when:
            if f"{condition.operation}/{condition.group}" not in report.outcomes:
                await self._event((condition.operation, condition.group)).wait()


def branch_taken(engine: BranchEngine, operation: Operation, report: RunReport) -> bool:
    """Whether the <if>/<else> around ``operation`` let it run."""
    unmet = [c for c in operation.when if not c.met(report.outcomes.get(f"{c.operation}/{c.group}"))]
    if not unmet:
        return True
    board = engine.outcome_board
    board.decided(operation, operation.calls)  # what it would have decided is decided: nothing
    if operation.id in board.left_out:
        return False
    board.left_out.add(operation.id)
    why = unmet[0]
    outcome = report.outcomes.get(f"{why.operation}/{why.group}", "none")
    report.skipped.append((operation.id, f"{why.group} {why.operation} ended {outcome}"))
    engine.note_branch("branch", operation.id, why.group, None, outcome,
                       f"{operation.id} left out: {why.group} {why.operation} ended {outcome}; it runs when {why.describe()}")
    return False


async def ended_with_outcome(engine: BranchEngine, operation: Operation, group: str, result: SmResult, stopping: bool) -> bool:
    """Record the named outcome of a tested function; True when a failure is one of its outcomes
    (the function counts as done)."""
    report = engine.report
    assert report is not None
    if (operation.id, group) not in engine.tested:
        return False
    function = operation.calls[group].function
    spec = engine.catalog.get(function)
    succeeded = result.outcome == "succeeded"
    named = spec.outcome_of(succeeded, result.fault.value if result.fault is not None else None) if spec is not None else None
    if named is None or result.outcome == "preempted" or stopping:
        return False
    report.outcomes[f"{operation.id}/{group}"] = named
    if not succeeded and result.error:
        report.outcome_details[f"{operation.id}/{group}"] = result.error
    engine.outcome_board.decided(operation, (group,))
    engine.note_branch("outcome", operation.id, group, function, named,
                       f"{group} {function} ended {named}" + ("" if succeeded else f": {result.error}"))
    if not succeeded:
        link = engine.links[group]
        if link.state == ERROR_HANDLING:
            await link.command("reset")
        if not await link.wait_state((READY,), engine.service_timeout):
            raise ApplicationAborted(f"{group} did not return to Ready after ending {operation.id} with {named} (it is in {link.state})")
    return True
