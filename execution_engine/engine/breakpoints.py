"""Breakpoints and "run to here": the run pauses before an operation, says why, and goes on as the operator says.

A mixin of :class:`~execution_engine.engine.engine.ExecutionEngine` (as :mod:`.commands` is, whose
resume and step it extends).  A breakpoint comes from the file (``break="true"`` on an
``<operation>``) or is set and cleared while the run goes on (the page, the terminal's keys, the
``execution_engine/breakpoint`` service); the file is never changed.  "Run to here"
(``execution_engine/run_to``) is a breakpoint for once: the run goes on and pauses before that
operation (breakpoints on the way still pause it).

In lock-step every group is at its barrier before the operation: the run pauses there, as a step
does.  With ``sync="flags"`` the group that reaches it holds there and the others go on until they
need it: a group whose synchronised function has a held partner waits before it (so the barrier
cannot time out), and a ``wait_flag`` does not count the time a group was held against its
timeout.  Continue (resume) lets the held groups go on, Step runs one operation and pauses again,
stop ends the run as ever.  Without anyone who could continue the run (no terminal console, no
service client) a breakpoint is passed and said so, as an alarm ends such a run at once rather than
wait for nobody.

Every pause is a ``breakpoint`` EngineEvent (trace, recording, timeline) and a line of the run
report; every command is an operator action with its source and the operation it names.
"""
from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING

from execution_engine.app_model.model import Operation
from execution_engine.engine.breakpoint_set import ACTIONS, BreakpointSet, describe, pause_message
from execution_engine.engine.commands import OperatorCommands
from execution_engine.engine.flags_mode import meeting
from execution_engine.engine.operator import ENDED
from execution_engine.engine.report import BreakpointHit, OperatorAction
from execution_engine.machine.table import WORKING_STATES
from node_transport import mirrors
from node_transport.wire import EngineEvent

if TYPE_CHECKING:
    from core_functions.catalog import Catalog
    from execution_engine.app_model.model import Application, Call
    from node_transport.wire import GroupProgress
    from execution_engine.engine.flags import FlagBoard

BREAKPOINT_SERVICE = "execution_engine/breakpoint"
RUN_TO_SERVICE = "execution_engine/run_to"
BreakpointService = mirrors.service("dual_arm_executive_interfaces/srv/Breakpoint")
RunToService = mirrors.service("dual_arm_executive_interfaces/srv/RunTo")
#: How the operator commands on breakpoints are named in the trace and the report.
COMMANDS = {"set": "break", "clear": "unbreak", "clear_all": "unbreak_all", "run_to": "run_to"}
#: Run seconds between two looks, by a held group, at whether the whole run waits for the operator now.
HOLD_POLL = 0.5


class BreakpointControl(OperatorCommands):
    """The engine's breakpoints: the services, the commands, and the holds before operations."""

    breakpoints: BreakpointSet

    if TYPE_CHECKING:  # the engine's own state, which these methods read and change
        app: Application | None
        catalog: Catalog
        flags: FlagBoard
        _op_index: int
        _progress: dict[str, GroupProgress]

        def _sits_out(self, call: Call) -> bool: ...
        async def _gate(self) -> bool: ...

    def _serve_breakpoints(self) -> BreakpointSet:
        """The breakpoint and run-to services of the engine node; the (empty) set they change."""
        self.node.create_service(BreakpointService, BREAKPOINT_SERVICE, self._on_breakpoint_service)
        self.node.create_service(RunToService, RUN_TO_SERVICE, self._on_run_to_service)
        return BreakpointSet()

    async def _on_breakpoint_service(self, request: object) -> object:
        action = str(getattr(request, "action", "") or "set")
        source = f"service {self.node.resolve(BREAKPOINT_SERVICE)}"
        ok, message = await self.breakpoint_command(action, str(getattr(request, "operation", "")), source)
        return BreakpointService.Response(success=ok, message=message, breakpoints=tuple(self.breakpoints.ids()))

    async def _on_run_to_service(self, request: object) -> object:
        ok, message = await self.breakpoint_command("run_to", str(getattr(request, "operation", "")), f"service {self.node.resolve(RUN_TO_SERVICE)}")
        return RunToService.Response(success=ok, message=message)

    # -------------------------------------------------------------------------- commands
    def _current(self, first: int = 0) -> BreakpointSet:
        """The breakpoints of the run under way (the file's, the first time they are asked for)."""
        bp = self.breakpoints
        if self.app is not None and self.report is not None and bp.run is not self.report:
            bp.ensure(self.app, self.report, first)
            self.flags.held = lambda: bp.held_seconds(self.clock.now())  # a held group's time is no flag wait's
        elif self.app is not None:
            bp.adopt(self.app)  # a paused run's remainder was edited
        return bp

    async def breakpoint_command(self, action: str, operation: str, source: str) -> tuple[bool, str]:
        """Set, clear or toggle a breakpoint (``clear_all``: every one), or ``run_to`` an operation; recorded
        with ``source`` and the operation it names before it takes effect, as every operator command is.

        ``operation``: an id, ``#N`` (the N-th operation), or "" for the next operation to start."""
        bp = self._current()
        ok, answer, index = self._decide_breakpoint(action, operation, bp)
        command = COMMANDS.get(action, action)
        if ok and action == "toggle":
            command = "unbreak" if bp.operations[index].id in bp.active else "break"
        target = bp.operations[index].id if index is not None else operation.strip()  # refused: as it was asked for
        if ok and command in ("break", "unbreak"):
            answer = f"breakpoint {'set' if command == 'break' else 'cleared'} before {describe(index, bp.operations[index])}"  # type: ignore[index]
        self._record_target(OperatorAction(self.clock.now(), command, source, self.state, ok, answer, target))
        if not ok:
            return False, answer
        if command == "break":
            bp.active.add(target)
        elif command == "unbreak":
            bp.active.discard(target)
        elif command == "unbreak_all":
            bp.active.clear()
            bp.target = None
        else:
            bp.target = target
            await self._run_on(source)
        self._poke()
        return True, answer

    def _decide_breakpoint(self, action: str, operation: str, bp: BreakpointSet) -> tuple[bool, str, int | None]:
        """Whether the command applies now, the answer, and the operation it names."""
        if action not in (*ACTIONS, "run_to"):
            return False, f"unknown breakpoint action {action!r} (actions: {', '.join(ACTIONS)}, run_to)", None
        if self.app is None or self.state in (*ENDED, "stopping"):
            return False, f"no run to set breakpoints in ({self.state})", None
        if action == "clear_all":
            return True, f"every breakpoint cleared ({len(bp.active)} were set)" + ("" if bp.target is None else ", and the run-to target"), None
        found = bp.find(operation)
        if isinstance(found, str):
            return False, found, None
        where = describe(found, bp.operations[found])
        if action != "run_to":
            return True, "", found
        if self.state == "alarm":
            return False, "cannot run_to: alarm (use reset to acknowledge the alarm, or stop)", None
        nxt = bp.next_index()
        if bp.holding_at(found):
            return False, f"the run is paused before {where} already: Step runs it, Resume goes on", None
        if nxt is None or found < nxt:
            return False, f"{where} has already run (the run is at operation {(nxt or len(bp.operations)) + 1})", None
        if self.state == "paused" and self._safety_active:
            return False, "the safety stop is still active", None
        return True, f"running to {where}: the run pauses before it", found

    async def _run_on(self, source: str) -> None:
        """After ``run_to``: go on (paused), start (waiting for start), or only keep the target (running)."""
        self._stepping = False
        if self.state == "idle" and not self._start_requested:
            await self._cmd_start(source)
        elif self.state == "paused":
            await self._cmd_resume(source)

    def _record_target(self, action: OperatorAction) -> None:
        """An operator action naming an operation: the report's line, and the trace's with its ``target``."""
        if self.report is not None and self.state not in ENDED:
            self.report.operator_actions.append(action)
        self._publish_event(EngineEvent(
            "operator", action.t, action.state, self._operation.id if self._operation else None, message=action.target,
            command=action.command, source=action.source, accepted=action.accepted, answer=action.answer,
        ))

    async def _cmd_resume(self, source: str) -> list[str]:
        notes = await super()._cmd_resume(source)  # every paused machine resumes, those paused at a barrier too
        self.breakpoints.release(self.clock)
        self.breakpoints.paused.clear()
        return notes

    async def _cmd_step(self, source: str) -> list[str]:
        flags = self.app is not None and self.app.sync == "flags" and bool(self.breakpoints.held)
        notes = await super()._cmd_step(source)
        if flags:  # the held groups each run one operation, then hold again
            self.breakpoints.release(self.clock, step=True)
            await self._resume_partners()
            self._set_state("stepping", f"one step by {source}")
        return notes

    # ----------------------------------------------------------------------------- holds
    async def _gate_at(self, index: int, operation: Operation) -> bool:
        """Lock-step: hold between operations before ``operation`` when a breakpoint (or the run-to target)
        is there and its branch lets it run, as after a step; False when the application must stop."""
        assert self.app is not None and self.report is not None
        bp = self._current(index)
        for group in self.links:
            bp.at[group] = index
        report = self.report
        runs = all(c.met(report.outcomes.get(f"{c.operation}/{c.group}")) for c in operation.when)
        kind = bp.due(None, index) if runs else None
        if kind is not None and self._hit(kind, index, operation, tuple(self.links)):
            self._paused, self._stepping = True, False
        going = await self._gate()
        bp.release(self.clock)
        if kind is not None:
            bp.passed(index)
        for group in self.links:
            bp.at[group] = index + 1
        return going

    async def _group_gate(self, group: str, operation: Operation, partners: tuple[str, ...]) -> bool:
        """``sync="flags"``: hold ``group`` before ``operation`` when a breakpoint, the run-to target or a step's
        end is there; then wait while a partner of its synchronised function is held.  False: stop."""
        assert self.app is not None and self.report is not None
        bp = self._current()
        index = bp.index[operation.id]
        bp.at[group] = index
        kind = bp.due(group, index)
        if kind is not None and self._hit(kind, index, operation, (group,)):
            bp.hold((group,), index, kind, self.clock)
            await self._pause_partners(group)
            while group in bp.held and self._stop_reason is None:
                await self._await_operator()
        others = [p for p in partners if p != group]
        while self._stop_reason is None and any(p in bp.held for p in others):
            bp.waiting.add(group)  # its barrier would time out while the partner is held
            try:
                await self._await_operator()
            finally:
                bp.waiting.discard(group)
        bp.at[group] = index + 1
        return self._stop_reason is None

    async def _pause_partners(self, group: str) -> None:
        """Pause the groups already at a barrier with ``group`` (their synchronised function names it): a paused
        machine's barrier wait starts its timeout again when it resumes, so the hold cannot time it out."""
        bp = self.breakpoints
        for other, progress in list(self._progress.items()):
            index = bp.index.get(progress.operation or "")
            if other == group or other in bp.held or other in bp.paused or index is None or bp.at.get(other) != index + 1:
                continue
            call = bp.operations[index].calls.get(other)
            if call is not None and group in meeting(bp.operations[index], call, self.catalog) and self.links[other].state in WORKING_STATES:
                ok, _ = await self.links[other].command("pause")
                if ok:
                    bp.paused.add(other)

    async def _resume_partners(self) -> None:
        for other in sorted(self.breakpoints.paused):
            await self.links[other].command("resume")
        self.breakpoints.paused.clear()

    async def _run_group(self, group: str, steps: list[tuple[Operation, Call]]) -> None:
        """Flags mode's run of one group, which the breakpoints see end (the run may then wait for the operator alone)."""
        try:
            await super()._run_group(group, steps)  # type: ignore[misc]
        finally:
            self.breakpoints.finished.add(group)
            self._poke()

    async def _await_operator(self) -> None:
        """One wait of a held group: while every group still running waits for the operator (held, waiting for a
        held partner, a flag or a zone), simulated time stands still as for any operator; else look again soon."""
        bp = self.breakpoints
        waits = set(self.flags.waiting) | set(self.flags.zones.waiting if self.flags.zones is not None else {})
        going = [g for g in bp.at if g not in bp.finished and g not in bp.held and g not in bp.waiting and g not in bp.paused and g not in waits]
        if not going:
            with self._operator_wait():
                await self._wait_control()
            return
        with contextlib.suppress(asyncio.TimeoutError):
            await self.clock.wait_for(self._wait_control(), HOLD_POLL)

    def _hit(self, kind: str, index: int, operation: Operation, groups: tuple[str, ...]) -> bool:
        """Say that the run pauses before ``operation`` (True), or that it passes because nobody could continue it."""
        assert self.app is not None and self.report is not None
        flags = self.app.sync == "flags"
        where = describe(index, operation)
        held = self.operators
        message = pause_message(kind, where, groups, flags) if held else (
            f"{'breakpoint' if kind == 'break' else 'run-to target'} before {where} passed: nobody can continue a paused run here "
            "(run --interactive at a terminal, or on ROS, where the engine's services answer)")
        t = self.clock.now()
        self.report.breakpoints.append(BreakpointHit(t, operation.id, kind, groups, message, held))
        if held:
            if not flags:
                self._op_index, self._operation = index, operation
                self.breakpoints.hold(groups, index, kind, self.clock)
            self._set_state("paused", message)
        self._publish_event(EngineEvent(
            "breakpoint", t, self.state, operation.id, message=message, command=kind,
            source=" ".join(groups) if flags else None, answer="held" if held else "passed",
        ))
        if not held:
            self.announce(message)
        self._poke()
        return held
