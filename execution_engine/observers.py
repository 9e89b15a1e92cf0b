"""Watching a run from outside: the live console view and the JSON-lines trace.

Both are plain subscribers of the machines' ``status`` topics and the engine's status and
events, like any viewer on a ROS 2 network would be; they see exactly what an operator's tool
would see.

Trace lines (one JSON object each) carry ``t`` (run seconds), ``event`` (transition,
function_start, function_end, primitive_start, primitive_end, error, engine_state, operator),
``group``, ``operation`` and, where they apply, ``function``, ``from``, ``to``, ``signal``,
``state``, ``primitive``, ``index``, ``count``, ``outcome``, ``error`` and, on
``primitive_end``, the ``result`` the robot reported (joint positions in rad, TCP pose in m and
quaternion, a vision measurement).

The engine's lines have ``group`` "engine": ``engine_state`` (``from``, ``to``, ``message``) on
every change of the engine's state, ``operator`` (``command``, ``source``, ``state`` -- the
engine state it came in, "alarm" for an answer to an alarm --, ``accepted``, ``answer``; ``target``,
the operation a breakpoint or run-to command names) on every operator command, ``breakpoint``
(``kind`` break / run_to / step, ``groups`` held, ``held``, ``message``; on the held group's lane in
``sync="flags"``) when the run pauses before an operation, and ``error`` (the message of a failed run or an alarm).  The last line
of a complete trace is ``run_end`` (``outcome``, ``exit_code``, ``operations_done``,
``operations_total``, ``records``); see :class:`TraceWriter` for what survives a crash.  A record of an
operation a loop or a call made carries ``iteration`` (``for_each hole=drill_3``).  A run checked by its dry
run has ``plan`` records near its start (the plan it was checked against: ``app``, ``basis``, ``cycle_time``,
``operations`` as [id, s], ``functions`` as [group, id, s], ``part`` k of ``parts``; :mod:`execution_engine.run_plan`).
"""
from __future__ import annotations

import errno
import io
import json
import os
from collections.abc import Callable, Iterable, Mapping
from typing import IO, Any, TypeVar

from core_functions.printable import printable
from execution_engine.app_model.model import Application
from execution_engine.engine.remainder_swap import Swap, decode_answer, decode_groups
from execution_engine.run_plan import PLAN_TOPIC, PlanError, RunPlan, plan_from_fields, plan_records
from node_transport import codec, typed
from node_transport.port import Node
from node_transport.qos import EVENTS, LATCHED
from node_transport.typed import RunPlanMsg
from node_transport.wire import ENGINE_EVENTS, ENGINE_STATUS, EngineEvent, EngineStatus, SmStatus, sm_topic

M = TypeVar("M")

TRACE_EVENTS = (
    "transition", "function_start", "function_end", "primitive_start", "primitive_end", "error", "engine_state", "operator", "flag", "run_end",
    "outcome", "branch", "swap", "breakpoint", "plan",
)


def trace_record(status: SmStatus) -> dict[str, Any]:
    """The trace line of one machine status event: always t/event/group/operation, others if set."""
    record: dict[str, Any] = {
        "t": round(status.t, 6),
        "event": status.event,
        "group": status.group,
        "operation": status.operation,
    }
    optional = {
        "function": status.function,
        "from": status.from_state,
        "to": status.to_state,
        "signal": status.signal,
        "state": status.state,
        "primitive": status.primitive,
        "index": status.index,
        "count": status.count,
        "outcome": status.outcome,
        "error": status.error,
        "request_id": status.request_id,
        "result": status.result,
    }
    record.update({k: v for k, v in optional.items() if v is not None})
    return record


def engine_record(event: EngineEvent) -> dict[str, Any]:
    """The trace line of one engine event: a state change or an operator command."""
    record: dict[str, Any] = {"t": round(event.t, 6), "group": "engine", "operation": event.operation}
    if event.event == "state":
        record.update({"event": "engine_state", "from": event.from_state, "to": event.state, "message": event.message})
    elif event.event == "flag":  # a flag set, or a group's wait for one starting (waiting) or ending: on the group's lane
        record.update({"event": "flag", "group": event.source, "flag": event.command, "kind": event.answer or "flag", "state": event.state, "message": event.message})
    elif event.event == "outcome":  # a tested function's named outcome: on the group's lane
        record.update({"event": "outcome", "group": event.source, "function": event.command, "outcome": event.answer, "message": event.message})
    elif event.event == "branch":  # an operation its <if>/<else> left out
        record.update({"event": "branch", "tested": event.source, "outcome": event.answer, "message": event.message})
    elif event.event == "swap":  # a paused run's remainder edited: both applications' digests, from which operation on
        old, new, frontier = decode_answer(event.answer) or ("", "", -1)
        record.update({"event": "swap", "from_digest": old, "to_digest": new, "from_operation": frontier + 1,
                       "file": event.command, "source": event.source, "message": event.message})
        if groups := decode_groups(event.answer):  # sync="flags": where each group stood
            record["groups"] = groups
    elif event.event == "breakpoint":  # the run paused before an operation (sync="flags": on the held group's lane)
        groups = (event.source or "").split()
        record.update({"event": "breakpoint", "group": groups[0] if len(groups) == 1 else "engine", "kind": event.command,
                       "groups": groups, "held": event.answer != "passed", "message": event.message})
    else:
        record.update({
            "event": "operator", "command": event.command, "source": event.source,
            "state": event.state, "accepted": event.accepted, "answer": event.answer,
        })
        if event.message and event.command == "speed_override":  # the new override (percent), for whoever follows the run's pace
            record["percent"] = float(event.message)
        elif event.message:  # a breakpoint or run-to command: the operation it names
            record["target"] = event.message
    return record


class RunObserver:
    """Subscribes to every group's status and the engine's status and events; fans them out to sinks."""

    def __init__(self, node: Node, groups: Iterable[str]) -> None:
        self.node = node
        self.sinks: list[Callable[[SmStatus], None]] = []
        self.engine_sinks: list[Callable[[EngineStatus], None]] = []
        self.event_sinks: list[Callable[[EngineEvent], None]] = []
        self.plan_sinks: list[Callable[[RunPlan, float], None]] = []  # the plan the run was checked against, and when
        self.rejected: list[str] = []
        for group in groups:
            self._subscribe(SmStatus, sm_topic(group, "status"), self.sinks)
        self._subscribe(EngineStatus, ENGINE_STATUS, self.engine_sinks)
        self._subscribe(EngineEvent, ENGINE_EVENTS, self.event_sinks)
        self.node.create_subscription(RunPlanMsg, PLAN_TOPIC, self._plan, LATCHED)

    def _plan(self, msg: Any) -> None:
        """The run's plan (latched: also when it was published before this observer was made); garbage rejected."""
        try:
            plan, t = plan_from_fields(msg), typed.run_time(self.node.clock, msg.header.stamp)
        except (PlanError, AttributeError, TypeError, ValueError) as error:
            self.rejected.append(f"{PLAN_TOPIC}: {error}")
            return
        for sink in self.plan_sinks:
            sink(plan, t)

    def _subscribe(self, cls: type[M], topic: str, sinks: list[Callable[[M], None]]) -> None:
        """Decode each message of ``topic`` and hand it to every sink; garbage is kept in ``rejected``."""
        source = self.node.resolve(topic)

        def deliver(msg: Any) -> None:
            try:
                message = typed.from_msg(cls, msg, self.node.clock, source=source)
            except codec.WireError as error:
                self.rejected.append(str(error))
                return
            for sink in sinks:
                sink(message)

        self.node.create_subscription(typed.msg_type(cls), topic, deliver, EVENTS)


class TraceWriter:
    """Writes trace records as JSON lines, durably; engine failures become ``error`` lines of group "engine".

    A trace is the record an integrator reads after something went wrong, so it must survive what
    went wrong: every record is flushed to the operating system as it is written (a ``kill -9``
    of the run loses nothing already written, nor anything the console showed, since the trace
    is written first), the file is synced to disk at every operation boundary and at the end,
    and a complete trace ends with a ``run_end`` record (outcome, exit code, counts) -- a trace
    without one was cut.  A failing write (a full disk) never stops the run: the first error is
    kept, later records are counted as lost, and the caller reports it at the end.
    """

    def __init__(self, stream: IO[str], iterations: Mapping[str, str] | None = None) -> None:
        """``iterations``: the loop iteration or call each expanded operation was made for, by id
        (``Application.iterations``); a record of such an operation carries it as ``iteration``."""
        self.stream = stream
        self.iterations: Mapping[str, str] = iterations or {}
        self.lines = 0
        self.lost = 0
        self.error: OSError | None = None
        self.last_t = 0.0  # run time of the latest record: where a run that broke off ended
        self._last_engine_message = ""
        self._operation: str | None = None

    def swapped(self, app: Application, swap: Swap) -> None:
        """A paused run's remainder was edited (the engine's hook, engine/remainder_swap.py): the iterations its
        operations were made for, from now on."""
        self.iterations = app.iterations()

    def on_status(self, status: SmStatus) -> None:
        record = trace_record(status)
        iteration = self.iterations.get(status.operation or "") if self.iterations else None
        if iteration:
            record["iteration"] = iteration
        self._write(record)

    def on_engine(self, status: EngineStatus) -> None:
        if status.operation_id != self._operation:  # an operation boundary: make the record so far durable
            self._operation = status.operation_id
            self.sync()
        if status.state in ("failed", "alarm") and status.message and status.message != self._last_engine_message:
            self._last_engine_message = status.message
            self._write({"t": round(status.t, 6), "event": "error", "group": "engine", "operation": status.operation_id, "error": status.message})

    def on_event(self, event: EngineEvent) -> None:
        self._write(engine_record(event))

    def on_plan(self, plan: RunPlan, t: float) -> None:
        """The plan the run was checked against (:mod:`execution_engine.run_plan`): ``plan`` records."""
        for record in plan_records(plan, t):
            self._write(record)

    def finish(self, t: float, outcome: str, exit_code: int, operations_done: int, operations_total: int) -> None:
        """The last record: how the run ended; then everything to disk."""
        self._write({
            "t": round(t, 6), "event": "run_end", "group": "engine", "outcome": outcome, "exit_code": exit_code,
            "operations_done": operations_done, "operations_total": operations_total, "records": self.lines + 1,
        })
        self.sync()

    def sync(self) -> None:
        """Flush and fsync: what was written survives a crash of the whole machine, not only of the run."""
        if self.error is not None:
            return
        try:
            self.stream.flush()
            fileno = self.stream.fileno()
        except (AttributeError, io.UnsupportedOperation):  # an in-memory stream: nothing to sync
            return  # (UnsupportedOperation is an OSError: caught first)
        except (OSError, ValueError) as error:
            self.error = error if isinstance(error, OSError) else OSError(str(error))
            return
        try:
            os.fsync(fileno)
        except OSError as error:
            if error.errno not in (errno.EINVAL, errno.EROFS):  # a pipe or a device that cannot sync
                self.error = error

    def _write(self, record: dict[str, Any]) -> None:
        self.last_t = max(self.last_t, float(record["t"]))
        if self.error is not None:
            self.lost += 1
            return
        try:
            self.stream.write(json.dumps(record, separators=(",", ":")) + "\n")
            self.stream.flush()
        except OSError as error:
            self.error = error
            self.lost += 1
            return
        self.lines += 1


def engine_line(status: EngineStatus) -> str:
    """The console's words for the engine's state: ``PAUSED operation 2/8 - paused by ...``."""
    progress = f"operation {status.operation_index}/{status.operation_count}" if status.operation_count else ""
    message = f" - {status.message}" if status.message else ""
    return f"{status.state.upper()} {progress}{message}"


class LivePrinter:
    """One console line per state change of a group, and per change of the engine's state.

    A transition into a working state is printed together with the primitive it runs (the
    machine announces the primitive right after the transition), so each line says what the
    arm is doing and why.
    """

    def __init__(self, stream: IO[str], groups: Iterable[str]) -> None:
        self.stream = stream
        self.width = max((len(g) for g in groups), default=8)
        self._engine_state = ""
        self._held: dict[str, SmStatus] = {}

    def on_status(self, status: SmStatus) -> None:
        held = self._held.pop(status.group, None)
        if status.event == "primitive_start" and held is not None:
            self._transition(held, status.primitive or "")
            return
        if held is not None:
            self._transition(held, "")
        if status.event == "transition":
            if status.to_state in ("Ready", "Finish", "Pause", "Stop", "ErrorHandling"):
                self._transition(status, "")
            else:
                self._held[status.group] = status
        elif status.event == "error":
            self._print(status.t, status.group, f"ERROR: {status.error}")

    def _transition(self, status: SmStatus, doing: str) -> None:
        where = f"op {status.operation} {status.function}" if status.operation else ""
        line = f"{status.from_state} -> {status.to_state} ({status.signal})"
        self._print(status.t, status.group, f"{line:<44} {where} {doing}".rstrip())

    def on_engine(self, status: EngineStatus) -> None:
        if status.state != self._engine_state:
            self._engine_state = status.state
            self._print(status.t, "engine", engine_line(status))

    def on_event(self, event: EngineEvent) -> None:
        """Operator commands (state changes are printed from the status, with their progress)."""
        if event.event == "operator":
            answer = "accepted" if event.accepted else "refused"
            self._print(event.t, "engine", f"operator {event.command} from {event.source}: {answer} - {event.answer}")
        elif event.event == "flag" and event.source:
            self._print(event.t, event.source, event.message)
        elif event.event == "breakpoint" and (event.source or event.answer == "passed"):  # a group joining a pause; a pass
            self._print(event.t, event.source or "engine", event.message)

    def _print(self, t: float, who: str, text: str) -> None:
        """One line; names and texts from the application and the peers with control and bidi characters escaped."""
        self.stream.write(f"[{t:9.3f} s] {printable(who):<{self.width}}  {printable(text)}\n")
        self.stream.flush()


class QuestionPrinter:
    """With ``run -q``: the questions the run waits on, and nothing else.

    Quiet hides progress, never a question: an alarm that holds the robot until an operator
    answers is printed -- what failed, and which key or service answers it -- as the live view
    prints it, once per question.
    """

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self._asked = ""

    def on_engine(self, status: EngineStatus) -> None:
        if status.state != "alarm" and not (status.state == "paused" and " before operation " in status.message):  # a breakpoint waits too
            self._asked = ""
            return
        if status.message and status.message != self._asked:
            self._asked = status.message
            self.stream.write(f"[{status.t:9.3f} s] engine  {printable(engine_line(status))}\n")
            self.stream.flush()
