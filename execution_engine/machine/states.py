"""The states of the group machine (paper Table 1, plus Pause, Stop and ErrorHandling).

Each state returns exactly the signals of its row of Table 2 (:mod:`.table`).  What a state
does with an event it cannot use is written down here, case by case: a request arriving while
the arm moves is refused (the engine must wait for Ready), feedback for an old command is
dropped, an ``end`` request is kept for a state that can honour it.

Userdata keys (SMACH blackboard): ``primitive`` (Ready -> working state), ``resume_command``
(the bridge command a paused working state resumes), ``early_done`` (its completion, if it
arrived during the pause), ``error``, ``fault`` (its :class:`FaultKind`, which the result carries
to the engine) and ``stop_reason`` (for ErrorHandling).
"""
from __future__ import annotations

import asyncio
from collections.abc import MutableMapping
from typing import Any

from core_functions.primitives import MasterSlaveMove, MotionResult, describe
from execution_engine.machine.bridge_watch import WATCH_PERIOD
from execution_engine.machine.context import MachineContext
from execution_engine.machine.events import (
    Event,
    FaultEvent,
    FeedbackEvent,
    OperatorSignal,
    RequestEvent,
)
from execution_engine.machine.function_run import SkillError
from execution_engine.machine.rebase import Step, absolute
from execution_engine.machine.table import (
    END,
    ERROR,
    ERROR_HANDLING,
    OK,
    PAUSE,
    PAUSE_SIGNAL,
    READY,
    RESUME,
    STOP,
    STOP_SIGNAL,
    signals_of,
)
from execution_engine.smach import State
from node_transport.wire import BridgeFeedback, FaultKind

UD_KEYS = ("primitive", "resume_command", "early_done", "error", "fault", "stop_reason")
_EPSILON = 1e-9  # run seconds: a deadline this close is reached (float sums never land on it exactly)
#: What a problem of the bridge link is, when a control command gets no acknowledgement or fails.
Problem = tuple[FaultKind, str]


def fail(userdata: MutableMapping[str, Any], kind: FaultKind, error: str) -> str:
    """Leave by Table 2's error, with the error's text and kind for ErrorHandling (and the engine)."""
    userdata["error"] = error
    userdata["fault"] = kind
    return ERROR


def feedback_fault(feedback: BridgeFeedback) -> FaultKind:
    """The kind of an error feedback; a bridge that does not say is not trusted with a retry."""
    return feedback.fault if feedback.fault is not None else FaultKind.PROTOCOL


class MachineState(State):
    """A state of the group machine; its outcomes are its row of Table 2."""

    def __init__(self, name: str, ctx: MachineContext) -> None:
        super().__init__(signals_of(name), input_keys=UD_KEYS, output_keys=UD_KEYS)
        self.name = name
        self.ctx = ctx

    def refuse(self, event: RequestEvent) -> None:
        """Answer a request this state cannot take; ``end`` is kept for a state that can."""
        request = event.request
        if request.kind == "end":
            self.ctx.events.put_back(event)
            return
        self.ctx.send_result(request, "aborted", f"{self.ctx.group} is in {self.name}, not Ready: request refused", FaultKind.BUSY)

    @staticmethod
    def stopping(userdata: MutableMapping[str, Any], signal: OperatorSignal) -> str:
        """Leave by Table 2's stop, remembering who asked (ErrorHandling reports it)."""
        userdata["stop_reason"] = f"stopped by {signal.source}"
        return STOP_SIGNAL

    def refuse_or_fail(self, userdata: MutableMapping[str, Any], event: Event) -> str | None:
        """While working: a request is refused, a fault is this state's error; anything else is no signal."""
        if isinstance(event, RequestEvent):
            self.refuse(event)
        elif isinstance(event, FaultEvent):
            return fail(userdata, event.kind, f"{event.where}: {event.error}")
        return None

    async def _control(
        self, op: str, *, keep_done_of: str | None = None, userdata: MutableMapping[str, Any] | None = None
    ) -> Problem | None:
        """Send pause/resume/stop to the bridge and wait for its acknowledgement.

        Returns None when acknowledged, else the problem and its kind.  Events that arrive meanwhile are
        handed back in order, except the final feedback of ``keep_done_of`` (the primitive
        finished while we paused it), which is kept in userdata for the resume.
        """
        problem, _ = await self._ask(op, keep_done_of=keep_done_of, userdata=userdata)
        return problem

    async def _ask(
        self, op: str, *, keep_done_of: str | None = None, userdata: MutableMapping[str, Any] | None = None
    ) -> tuple[Problem | None, BridgeFeedback | None]:
        """:meth:`_control` for any command without a primitive (``measure`` too): the problem, or the answer."""
        ctx = self.ctx
        link_problem = await ctx.link_bridge()
        if link_problem is not None:
            return (FaultKind.CONNECTION, link_problem), None
        control_id = ctx.send_bridge(op)
        expected = {"pause": "paused", "resume": "resumed", "stop": "stopped", "measure": "measured"}[op]
        answer: BridgeFeedback | None = None
        deadline = ctx.clock.now() + ctx.config.bridge_timeout
        resend_at = ctx.clock.now() + ctx.config.resend_interval
        held: list[Event] = []
        problem: Problem | None = None
        while True:
            now = ctx.clock.now()
            if now >= deadline - _EPSILON:
                problem = FaultKind.TIMEOUT, f"timeout: the bridge did not acknowledge {op} within {ctx.config.bridge_timeout:g} s"
                break
            if now >= resend_at - _EPSILON:
                ctx.resend_bridge(control_id)
                resend_at = now + ctx.config.resend_interval
            lost = ctx.bridge_watch.lost()
            if lost is not None:
                problem = FaultKind.CONNECTION, lost
                break
            event = await ctx.events.get(max(0.0, min(deadline, resend_at, now + WATCH_PERIOD) - ctx.clock.now()))
            if event is None:
                continue
            if isinstance(event, FeedbackEvent) and event.feedback.id == control_id:
                if event.feedback.status == expected:
                    answer = event.feedback
                    break
                if event.feedback.status == "error":
                    problem = feedback_fault(event.feedback), f"{op} failed: {event.feedback.error}"
                    break
            elif (
                isinstance(event, FeedbackEvent)
                and event.feedback.id == keep_done_of
                and event.feedback.status in ("done", "error")
                and userdata is not None
            ):
                userdata["early_done"] = event.feedback
            else:
                held.append(event)
        ctx.acknowledged(control_id)
        for event in reversed(held):
            ctx.events.put_back(event)
        return problem, answer


# -------------------------------------------------------------------------------- Ready
class ReadyState(MachineState):
    """Waits for the engine; hands the next primitive of the running function to its state."""

    def __init__(self, ctx: MachineContext) -> None:
        super().__init__(READY, ctx)

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        ctx = self.ctx
        yielded = False
        while True:
            run = ctx.run
            if run is not None and run.finished:
                ctx.finish_function("succeeded")
                continue
            gated = False  # the next motion waits for a zone (machine/zone_gate.py)
            if run is not None and run.next_primitive is not None and not ctx.hold:
                if run.started and not yielded:
                    # a turn of the loop before each further primitive: a bridge may answer inside our own
                    # publish (node_transport/local.py), and the other nodes and the operators get their turn
                    yielded = True
                    await asyncio.sleep(0)
                step = ctx.goals.step(run.started, run.next_primitive)  # a retried relative move: its recorded goal
                if ctx.zones.admits(step.send):
                    run.take()
                    ctx.goals.take(step)
                    userdata["primitive"] = step.send
                    return step.send.STATE.request_signal
                gated = True
                lost = ctx.bridge_watch.lost()  # waiting for a zone with no bridge to move: nothing ever will
                if lost is not None:
                    ctx.status("error", error=lost)
                    ctx.finish_function("aborted", lost, FaultKind.CONNECTION)
                    continue
            event = await ctx.events.get(min(ctx.zones.wake_in(), WATCH_PERIOD) if gated else None)
            if event is None:
                continue
            if isinstance(event, RequestEvent):
                if event.request.kind == "end":
                    if run is not None:
                        ctx.finish_function("preempted", "application ended", FaultKind.STOPPED)
                    ctx.hold = False
                    return END
                if run is not None:
                    ctx.send_result(event.request, "aborted", f"{ctx.group} is busy with {run.label}: request refused", FaultKind.BUSY)
                    continue
                problem = await ctx.wait_for_cell(event.request.cell) if event.request.cell else None
                kind = FaultKind.TIMEOUT  # the cell model did not arrive in time
                if problem is None:
                    problem, kind = ctx.start_function(event.request), FaultKind.UNSUPPORTED  # unknown function, bad params
                if problem is not None:
                    ctx.status("error", error=problem, operation=event.request.operation, function=event.request.function)
                    ctx.send_result(event.request, "aborted", problem, kind)
            elif isinstance(event, OperatorSignal):
                if event.command == "pause":
                    ctx.hold = True
                elif event.command == "resume":
                    ctx.hold = False
                elif event.command == "stop":
                    ctx.hold = False
                    if run is not None:
                        ctx.finish_function("preempted", f"stopped by {event.source}", FaultKind.STOPPED)
            elif isinstance(event, FaultEvent) and run is not None:
                ctx.status("error", error=f"{event.where}: {event.error}")
                ctx.finish_function("aborted", f"{event.where}: {event.error}", event.kind)
            # FeedbackEvent here is stale (an old command); SyncEvent is already on the board.


# ---------------------------------------------------------------------- working states
class WorkingState(MachineState):
    """Runs one primitive on the bridge: execute, then done / error; pause and stop on request."""

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        resume_id = userdata.get("resume_command")
        userdata["resume_command"] = None
        if resume_id is not None:
            return await self._resume(userdata, resume_id)
        return await self._run(userdata)

    async def _run(self, userdata: MutableMapping[str, Any]) -> str:
        ctx = self.ctx
        primitive = userdata["primitive"]
        assert ctx.run is not None
        if ctx.watched:
            ctx.status("primitive_start", primitive=describe(primitive), index=ctx.run.started)
        step = ctx.goals.current
        if step is not None and step.refusal is not None:
            return fail(userdata, FaultKind.UNSUPPORTED, step.refusal)
        if step is not None and step.needs_goal:
            problem = await self._fix_goal(step)
            if problem is not None:
                return fail(userdata, problem[0], f"{describe(primitive)}: {problem[1]}")
            stop = ctx.events.take_signal("stop")  # asked while the arm was measured: the move is not sent
            if stop is not None:
                return self.stopping(userdata, stop)
        return await self._execute(userdata, primitive)

    async def _fix_goal(self, step: Step) -> Problem | None:
        """Before a relative move may be sent: measure where the arm is and record the goal it resolves to."""
        ctx = self.ctx
        problem, answer = await self._ask("measure")
        if problem is not None:
            return problem
        measured = answer.result if answer is not None else None
        if not isinstance(measured, MotionResult):
            return FaultKind.PROTOCOL, f"the bridge's measurement is a {type(measured).__name__}, not a MotionResult"
        joints = ctx.robot.group(ctx.group).joint_names
        ctx.goals.record(step.index, absolute(step.asked, measured, joints, ctx.goals.label(step.index, step.asked)))
        return None

    async def _execute(self, userdata: MutableMapping[str, Any], primitive: Any) -> str:
        """Send ``primitive`` once the bridge is linked, then wait for its end."""
        problem = await self.ctx.link_bridge()
        if problem is not None:
            return fail(userdata, FaultKind.CONNECTION, f"{describe(primitive)}: {problem}")
        command_id = self.ctx.send_bridge("execute", primitive)
        return await self._await_done(userdata, command_id, accepted=False)

    async def _resume(self, userdata: MutableMapping[str, Any], command_id: str) -> str:
        early: BridgeFeedback | None = userdata.get("early_done")
        userdata["early_done"] = None
        if early is not None:
            return self._finish(userdata, early)
        problem = await self._control("resume")
        if problem is not None:
            return fail(userdata, *problem)
        return await self._await_done(userdata, command_id, accepted=True)

    async def _await_done(self, userdata: MutableMapping[str, Any], command_id: str, *, accepted: bool) -> str:
        ctx = self.ctx
        ctx.active_command = command_id
        primitive = userdata["primitive"]
        now = ctx.clock.now()
        accept_deadline = now + ctx.config.bridge_timeout
        done_deadline = now + ctx.config.primitive_timeout
        resend_at = now + ctx.config.resend_interval
        while True:
            now = ctx.clock.now()
            deadline = done_deadline if accepted else accept_deadline
            if now >= deadline - _EPSILON:
                what = "finish" if accepted else "accept"
                limit = ctx.config.primitive_timeout if accepted else ctx.config.bridge_timeout
                return fail(userdata, FaultKind.TIMEOUT, f"timeout: the bridge did not {what} {describe(primitive)} within {limit:g} s")
            if not accepted and now >= resend_at - _EPSILON:  # lost before the bridge matched: same id again
                ctx.resend_bridge(command_id)
                resend_at = now + ctx.config.resend_interval
            lost = ctx.bridge_watch.lost()
            if lost is not None:
                ctx.active_command = None
                return fail(userdata, FaultKind.CONNECTION, f"{describe(primitive)}: {lost}")
            event = ctx.events.pop()  # the answer is often here already: the bridge answered inside our publish
            if event is None:
                wake = min(deadline if accepted else min(deadline, resend_at), now + WATCH_PERIOD)
                event = await ctx.events.get(max(0.0, wake - ctx.clock.now()))
            if event is None:
                continue
            if isinstance(event, FeedbackEvent) and event.feedback.id == command_id:
                status = event.feedback.status
                if status == "accepted":
                    accepted = True
                    ctx.acknowledged(command_id)
                elif status in ("done", "error"):
                    ctx.acknowledged(command_id)
                    return self._finish(userdata, event.feedback)
            elif isinstance(event, OperatorSignal):
                outcome = await self._operator(userdata, event, command_id)
                if outcome is not None:
                    return outcome
            else:
                outcome = self.refuse_or_fail(userdata, event)
                if outcome is not None:
                    return outcome

    async def _operator(self, userdata: MutableMapping[str, Any], signal: OperatorSignal, command_id: str) -> str | None:
        if signal.command == "pause":
            problem = await self._control("pause", keep_done_of=command_id, userdata=userdata)
            if problem is not None:
                return fail(userdata, *problem)
            userdata["resume_command"] = command_id
            return PAUSE_SIGNAL
        if signal.command == "stop":
            return self.stopping(userdata, signal)
        return None  # resume / reset do not apply while working

    def _finish(self, userdata: MutableMapping[str, Any], feedback: BridgeFeedback) -> str:
        """Turn a final feedback into ok (skill advanced) or error."""
        ctx = self.ctx
        primitive = userdata["primitive"]
        ctx.active_command = None
        assert ctx.run is not None
        index = ctx.run.started
        if feedback.status == "error":
            error = feedback.error or "bridge reported an error without a message"
            ctx.status("primitive_end", primitive=describe(primitive), index=index, outcome="error", error=error)
            return fail(userdata, feedback_fault(feedback), f"{describe(primitive)}: {error}")
        result = feedback.result if feedback.result is not None else primitive.RESULT()
        if type(result) is not primitive.RESULT:
            answered = f"the bridge answered a {type(result).__name__}, not a {primitive.RESULT.__name__}"
            return fail(userdata, FaultKind.PROTOCOL, f"{describe(primitive)}: {answered}")
        if ctx.watched:
            ctx.status("primitive_end", primitive=describe(primitive), index=index, outcome="done", result=result)
        ctx.zones.moved(primitive, result)
        try:
            ctx.run.advance(result)
        except SkillError as error:
            return fail(userdata, error.fault, str(error))
        return OK


class SyncState(WorkingState):
    """FullBodyMotion / MasterSlave: meet the partner groups, then the leader moves the robot.

    Every partner announces its arrival on the sync topic; when all have arrived, the leader
    (the master, or the first partner of a full-body move) sends the one command that moves
    them all, and tells the others when it is done or failed.  A partner that never arrives
    is an error after ``sync_timeout``.
    """

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        ctx = self.ctx
        assert ctx.run is not None
        request = ctx.run.request
        primitive = userdata["primitive"]
        key = request.sync or f"{request.operation}:{request.function}"
        partners = request.partners or (ctx.group,)
        leader = primitive.master if isinstance(primitive, MasterSlaveMove) else partners[0]
        if userdata.get("resume_command") is not None and leader == ctx.group:
            return self._report(userdata, key, await super().execute(userdata))
        if ctx.sync_key != key:
            ctx.sync_key = key
            ctx.status("primitive_start", primitive=describe(primitive), index=ctx.run.started)
            ctx.send_sync(key, "arrived")
        outcome = await self._barrier(userdata, key, partners)
        if outcome is not None:
            return outcome
        if leader == ctx.group:
            if ctx.sync_sent != key:
                ctx.sync_sent = key
                outcome = await self._execute(userdata, primitive)
            else:
                outcome = fail(userdata, FaultKind.INTERNAL, "synchronised command lost after a pause")
            return self._report(userdata, key, outcome)
        return await self._follow(userdata, key, leader, partners)

    def _report(self, userdata: MutableMapping[str, Any], key: str, outcome: str) -> str:
        ctx = self.ctx
        if outcome == OK:
            ctx.send_sync(key, "done")
            ctx.sync_key = ctx.sync_sent = None
        elif outcome == ERROR:
            ctx.send_sync(key, "failed", userdata.get("error"), userdata.get("fault"))
            ctx.sync_key = ctx.sync_sent = None
        return outcome

    async def _barrier(self, userdata: MutableMapping[str, Any], key: str, partners: tuple[str, ...]) -> str | None:
        ctx = self.ctx
        deadline = ctx.clock.now() + ctx.config.sync_timeout
        while True:
            board = ctx.sync_board.get(key, {})
            failed = [m for m in board.values() if m.event == "failed"]
            if failed:
                ctx.sync_key = None
                return fail(userdata, failed[0].fault or FaultKind.PROTOCOL, f"partner {failed[0].group} failed: {failed[0].error}")
            missing = [g for g in partners if g not in board]
            if not missing:
                return None
            now = ctx.clock.now()
            if now >= deadline - _EPSILON:
                late = f"timeout: {', '.join(missing)} did not reach the {self.name} barrier within {ctx.config.sync_timeout:g} s"
                return self._report(userdata, key, fail(userdata, FaultKind.TIMEOUT, late))
            event = await ctx.events.get(max(0.0, min(deadline, now + ctx.config.resend_interval) - now))
            if event is None:  # a partner that matched after our announcement has not heard it
                ctx.send_sync(key, "arrived")
                continue
            outcome = await self._interrupt(userdata, event)
            if outcome is not None:
                return outcome

    async def _follow(self, userdata: MutableMapping[str, Any], key: str, leader: str, partners: tuple[str, ...]) -> str:
        ctx = self.ctx
        deadline = ctx.clock.now() + ctx.config.primitive_timeout
        while True:
            board = ctx.sync_board.get(key, {})
            failed = [m for g, m in board.items() if m.event == "failed" and g != ctx.group]
            if failed:
                ctx.sync_key = None
                return fail(userdata, failed[0].fault or FaultKind.PROTOCOL, f"{failed[0].group} failed the {self.name}: {failed[0].error}")
            if board.get(leader) is not None and board[leader].event == "done":
                ctx.sync_key = ctx.sync_sent = None
                assert ctx.run is not None
                ctx.status("primitive_end", primitive=describe(userdata["primitive"]), index=ctx.run.started, outcome="done")
                try:
                    ctx.run.advance(userdata["primitive"].RESULT())
                except SkillError as error:
                    return fail(userdata, error.fault, str(error))
                return OK
            event = await ctx.events.get(max(0.0, deadline - ctx.clock.now()))
            if event is None:
                late = f"timeout: {leader} did not finish the {self.name} within {ctx.config.primitive_timeout:g} s"
                return self._report(userdata, key, fail(userdata, FaultKind.TIMEOUT, late))
            outcome = await self._interrupt(userdata, event)
            if outcome is not None:
                return outcome

    async def _interrupt(self, userdata: MutableMapping[str, Any], event: Event) -> str | None:
        """Operator signals and faults while waiting on partners (nothing of ours is moving)."""
        if isinstance(event, OperatorSignal):
            if event.command == "pause":
                return PAUSE_SIGNAL
            if event.command == "stop":
                return self.stopping(userdata, event)
            return None
        return self.refuse_or_fail(userdata, event)  # a SyncEvent: the board changed, look again


# ------------------------------------------------------------------ Pause, Stop, Error
class PauseState(MachineState):
    """Holds until resume or stop; an error reported meanwhile (the bridge failed) wins."""

    def __init__(self, ctx: MachineContext) -> None:
        super().__init__(PAUSE, ctx)

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        ctx = self.ctx
        paused = userdata.get("resume_command")
        early: BridgeFeedback | None = userdata.get("early_done")
        if early is not None and early.status == "error":  # it failed as the pause landed
            userdata["early_done"] = None
            return fail(userdata, feedback_fault(early), f"while pausing: {early.error}")
        while True:
            event = await ctx.events.get()
            if isinstance(event, OperatorSignal):
                if event.command == "resume":
                    return RESUME
                if event.command == "stop":
                    return self.stopping(userdata, event)
            elif isinstance(event, FeedbackEvent) and event.feedback.id == paused:
                if event.feedback.status == "error":
                    return fail(userdata, feedback_fault(event.feedback), f"while paused: {event.feedback.error}")
                if event.feedback.status == "done":
                    userdata["early_done"] = event.feedback
            elif isinstance(event, FaultEvent):
                return fail(userdata, event.kind, f"while paused: {event.where}: {event.error}")
            elif isinstance(event, RequestEvent):
                self.refuse(event)


class StopState(MachineState):
    """Halts the robot and abandons the function; Table 2 then leads to ErrorHandling."""

    def __init__(self, ctx: MachineContext) -> None:
        super().__init__(STOP, ctx)

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        reason = userdata.get("stop_reason") or "stopped"
        problem = await self._control("stop")
        self.ctx.active_command = None
        userdata["resume_command"] = None
        userdata["early_done"] = None
        return fail(userdata, FaultKind.STOPPED, reason if problem is None else f"{reason}; {problem[1]}")


class ErrorHandlingState(MachineState):
    """Reports the error, holds the robot, and waits for a reset (-> Ready) or the end (-> Finish).

    What to do about the error -- retry, go to a safe pose, raise an alarm for the operator --
    is the application's error policy, applied by the engine, which sees the function's result.
    """

    def __init__(self, ctx: MachineContext) -> None:
        super().__init__(ERROR_HANDLING, ctx)

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        ctx = self.ctx
        error = userdata.get("error") or "unknown error"
        stopped = userdata.get("stop_reason") is not None
        fault: FaultKind = userdata.get("fault") or (FaultKind.STOPPED if stopped else FaultKind.INTERNAL)
        if ctx.active_command is not None:
            ctx.send_bridge("stop")  # whatever failed, the arm must not keep moving
            ctx.active_command = None
        if ctx.sync_key is not None:
            ctx.send_sync(ctx.sync_key, "failed", error, fault)
            ctx.sync_key = ctx.sync_sent = None
        ctx.status("error", error=error)
        ctx.finish_function("preempted" if stopped else "aborted", error, fault)
        for key in ("error", "fault", "stop_reason", "resume_command", "early_done"):
            userdata[key] = None
        ctx.hold = False
        while True:
            event = await ctx.events.get()
            if isinstance(event, OperatorSignal) and event.command == "reset":
                return OK
            if isinstance(event, RequestEvent):
                if event.request.kind == "end":
                    return END
                ctx.send_result(event.request, "aborted", f"{ctx.group} is in ErrorHandling: reset it before new requests", FaultKind.BUSY)
