"""What operators do to a run: commands, the safety stop, and alarms that wait for their answer.

A mixin of :class:`~execution_engine.engine.engine.ExecutionEngine`, kept apart from the
orchestration of operations: every command is decided first (:func:`.operator.decide`),
recorded (trace, events, report) with its source and answer, then acted on; a ``true`` on the
safety-stop topic is a pause like any other command; an alarm holds the run until an operator
answers it (reset, stop, or skip for a resumed run's interrupted function), bounded by the
operator's wall clock.
"""
from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING

from core_functions.limits import DURATION
from execution_engine.engine.operator import CONSOLE_KEYS, ENDED, Flags, decide
from execution_engine.engine.report import OperatorAction, RunReport
from execution_engine.machine.table import PAUSE, READY, WORKING_STATES
from node_transport.msgs import Bool, Trigger, TriggerRequest, TriggerResponse
from node_transport.wall_clock import WallClock, wake_loop
from node_transport.wire import SAFETY_STOP, EngineEvent, engine_service

if TYPE_CHECKING:
    from execution_engine.app_model.model import Operation
    from node_transport.clock import Clock
    from execution_engine.engine.group_link import GroupLink
    from node_transport.port import Node


class OperatorCommands:
    """The operator's side of the engine (commands, safety stop, alarms)."""

    #: Every stop asked for, taken or not: a run that is still being checked before it starts
    #: (cell_runner/dry_run/start.py) is not started when this changed meanwhile.
    stops_asked: int = 0

    if TYPE_CHECKING:  # the engine's own state, which these methods read and change
        node: Node
        clock: Clock
        state: str
        links: dict[str, GroupLink]
        report: RunReport | None
        operators: bool
        wall_clock: WallClock
        _operation: Operation | None
        _message: str
        _paused: bool
        _stepping: bool
        _stop_reason: str | None
        _safety_active: bool
        _start_requested: bool
        _alarm_reset: bool
        _alarm_skip: bool
        _skippable: bool
        _tasks: set[asyncio.Task[tuple[bool, str]]]

        def _poke(self) -> None: ...
        async def _wait_control(self) -> None: ...
        def _operator_wait(self) -> contextlib.AbstractContextManager[None]: ...
        def _note_recovery(self, recovery: str) -> None: ...
        def _set_state(self, state: str, message: str | None = None) -> None: ...
        def _publish_event(self, event: EngineEvent) -> None: ...
        def _publish_status(self) -> None: ...

    # -------------------------------------------------------------------------- commands
    async def _on_service(self, command: str, request: TriggerRequest) -> TriggerResponse:
        ok, message = await self.operator_command(command, f"service {self.node.resolve(engine_service(command))}")
        return Trigger.Response(ok, message)

    async def operator_command(self, command: str, source: str) -> tuple[bool, str]:
        """Take (or refuse) an operator command; it is recorded before it takes effect.

        ``source`` says where it came from: the services pass their resolved name, the terminal
        console of ``run --interactive`` (in this process) the key that was pressed.
        """
        if command == "stop":
            self.stops_asked += 1
        ok, answer = decide(command, self.state, Flags(self._start_requested, self._safety_active, self._skippable))
        self._record(OperatorAction(self.clock.now(), command, source, self.state, ok, answer))
        if not ok:
            return False, answer
        notes = await getattr(self, f"_cmd_{command}")(source)
        self._poke()
        return True, answer + "".join(f"; {note}" for note in notes)

    def _record(self, action: OperatorAction) -> None:
        if self.report is not None and self.state not in ENDED:
            self.report.operator_actions.append(action)
        self._publish_event(EngineEvent(
            "operator", action.t, action.state, self._operation.id if self._operation else None,
            command=action.command, source=action.source, accepted=action.accepted, answer=action.answer,
        ))

    async def _cmd_start(self, source: str) -> list[str]:
        self._start_requested = True
        return []

    async def _cmd_pause(self, source: str) -> list[str]:
        self._paused = True
        self._stepping = False
        answers = [await link.command("pause") for link in self.links.values() if link.state in (READY, *WORKING_STATES)]
        self._set_state("paused", f"paused by {source}")
        return [m for ok, m in answers if not ok]

    async def _resume_groups(self) -> None:
        self._paused = False
        for link in self.links.values():
            if link.state in (PAUSE, READY):
                await link.command("resume")

    async def _cmd_resume(self, source: str) -> list[str]:
        self._stepping = False
        await self._resume_groups()
        self._set_state("running", f"resumed by {source}")
        return []

    async def _cmd_step(self, source: str) -> list[str]:
        self._stepping = True
        self._start_requested = True
        if self._paused:
            await self._resume_groups()
            if self.state == "paused":  # paused within an operation: it goes on, to its end
                self._set_state("stepping", f"one step by {source}")
        return []

    async def _cmd_stop(self, source: str) -> list[str]:
        self._stop_reason = f"stopped by {source}"
        for link in self.links.values():
            if link.state in (READY, PAUSE, *WORKING_STATES):
                await link.command("stop")
        return []

    async def _cmd_reset(self, source: str) -> list[str]:
        self._alarm_reset = True
        return []

    async def _cmd_skip(self, source: str) -> list[str]:
        self._alarm_skip = True
        return []

    def _on_safety(self, msg: Bool) -> None:
        if msg.data and not self._safety_active:
            self._safety_active = True
            task = asyncio.get_running_loop().create_task(self.operator_command("pause", f"safety stop on {self.node.resolve(SAFETY_STOP)}"))
            self._tasks.add(task)
            task.add_done_callback(self._task_done)
        elif not msg.data and self._safety_active:
            self._safety_active = False
            self._message = "safety stop cleared: resume to continue"
            self._publish_status()

    def _task_done(self, task: asyncio.Task[tuple[bool, str]]) -> None:
        """A background command must not fail unseen."""
        self._tasks.discard(task)
        error = None if task.cancelled() else task.exception()
        if error is not None:
            self.node.report_fault("safety stop pause", error)

    # ----------------------------------------------------------------------------- alarms
    def alarm_message(self, group: str, error: str, plan: str, timeout: float) -> str:
        """The alarm as the operator reads it: what failed, and exactly how to answer it."""
        reset, stop = (self.node.resolve(engine_service(c)) for c in ("reset", "stop"))
        limit = f"; gives up after {timeout:g} s (wall clock)" if timeout > 0 else ""
        return (
            f"ALARM {group}: {error} ({plan}) - to retry: key {CONSOLE_KEYS['reset']!r} (run --interactive) or call {reset}; "
            f"to abort: key {CONSOLE_KEYS['stop']!r} or call {stop}{limit}"
        )

    async def _alarm(self, group: str, error: str, plan: str, timeout: float) -> tuple[bool, str]:
        """Hold for an operator reset: (True, "") to retry; (False, why) to give up -- a stop, or
        ``timeout`` seconds of the operator's wall clock without an answer (0: the longest
        duration there is, a day -- no wait is without a bound)."""
        self._alarm_reset = False
        timeout = timeout if timeout > 0 else DURATION.upper
        self._set_state("alarm", self.alarm_message(group, error, plan, timeout))
        if not self.operators:  # nobody can answer: say so now rather than wait for no one
            self._note_recovery(f"{plan}; alarm cannot be answered: no operator console and no service client can reach this engine")
            return False, (
                "; the alarm asks an operator: retry (reset) or abort (stop)? - and no operator can answer it here: "
                "run with --interactive at a terminal, or on ROS, where the engine's services answer"
            )
        expired = False

        def expire() -> None:
            nonlocal expired
            expired = True
            self._poke()

        timer = self.wall_clock.call_later(timeout, wake_loop(asyncio.get_running_loop(), expire))
        try:
            with self._operator_wait():  # the robot waits for a person: simulated time must not race on
                while not self._alarm_reset and self._stop_reason is None and not expired:
                    await self._wait_control()
        finally:
            timer.cancel()
        if self._alarm_reset and self._stop_reason is None:
            self._note_recovery(f"{plan}; alarm reset by an operator: retried")
            return True, ""
        unanswered = "" if self._stop_reason is not None else f"; alarm not answered within {timeout:g} s (wall clock)"
        self._note_recovery(f"{plan}{unanswered or '; alarm answered with stop'}")
        return False, unanswered

    async def hold_for_answer(self, message: str) -> str:
        """An alarm that only an operator ends: "reset", "skip" or "stop"; "unanswerable" at once
        when nobody can answer (a resumed run's interrupted functions)."""
        self._alarm_reset = self._alarm_skip = False
        self._skippable = True
        self._set_state("alarm", message)
        try:
            if not self.operators:
                return "unanswerable"
            with self._operator_wait():
                while not self._alarm_reset and not self._alarm_skip and self._stop_reason is None:
                    await self._wait_control()
        finally:
            self._skippable = False
        return "stop" if self._stop_reason is not None else "skip" if self._alarm_skip else "reset"
