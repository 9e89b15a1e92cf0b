"""Watching a run from outside: the live console view and the JSON-lines trace.

Both are plain subscribers of the machines' ``status`` topics and the engine's status, like any
viewer on a ROS 2 network would be; they see exactly what an operator's tool would see.

Trace lines (one JSON object each) carry ``t`` (run seconds), ``event`` (transition,
function_start, function_end, primitive_start, primitive_end, error), ``group``,
``operation`` and, where they apply, ``function``, ``from``, ``to``, ``signal``, ``state``,
``primitive``, ``index``, ``count``, ``outcome``, ``error`` and, on ``primitive_end``, the
``result`` the robot reported (joint positions in rad, TCP pose in m and quaternion, a vision
measurement).
"""
from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from typing import IO, Any

from execution_engine.transport import codec
from execution_engine.transport.msgs import String
from execution_engine.transport.port import Node
from execution_engine.transport.qos import EVENTS
from execution_engine.transport.wire import ENGINE_STATUS, EngineStatus, SmStatus, sm_topic

TRACE_EVENTS = ("transition", "function_start", "function_end", "primitive_start", "primitive_end", "error")


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


class RunObserver:
    """Subscribes to every group's status and the engine's; fans events out to sinks."""

    def __init__(self, node: Node, groups: Iterable[str]) -> None:
        self.node = node
        self.sinks: list[Callable[[SmStatus], None]] = []
        self.engine_sinks: list[Callable[[EngineStatus], None]] = []
        self.rejected: list[str] = []
        for group in groups:
            node.create_subscription(String, sm_topic(group, "status"), self._on_status, EVENTS)
        node.create_subscription(String, ENGINE_STATUS, self._on_engine, EVENTS)

    def _on_status(self, msg: String) -> None:
        try:
            status = codec.decode(SmStatus, msg.data, source="status")
        except codec.WireError as error:
            self.rejected.append(str(error))
            return
        for sink in self.sinks:
            sink(status)

    def _on_engine(self, msg: String) -> None:
        try:
            status = codec.decode(EngineStatus, msg.data, source=self.node.resolve(ENGINE_STATUS))
        except codec.WireError as error:
            self.rejected.append(str(error))
            return
        for sink in self.engine_sinks:
            sink(status)


class TraceWriter:
    """Writes trace records as JSON lines; engine failures become ``error`` lines of group "engine"."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.lines = 0
        self._last_engine_message = ""

    def on_status(self, status: SmStatus) -> None:
        self._write(trace_record(status))

    def on_engine(self, status: EngineStatus) -> None:
        if status.state in ("failed", "alarm") and status.message and status.message != self._last_engine_message:
            self._last_engine_message = status.message
            self._write({"t": round(status.t, 6), "event": "error", "group": "engine", "operation": status.operation_id, "error": status.message})

    def _write(self, record: dict[str, Any]) -> None:
        self.stream.write(json.dumps(record, separators=(",", ":")) + "\n")
        self.lines += 1


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
            progress = f"operation {status.operation_index}/{status.operation_count}" if status.operation_count else ""
            message = f" - {status.message}" if status.message else ""
            self._print(status.t, "engine", f"{status.state.upper()} {progress}{message}")

    def _print(self, t: float, who: str, text: str) -> None:
        self.stream.write(f"[{t:9.3f} s] {who:<{self.width}}  {text}\n")
        self.stream.flush()
