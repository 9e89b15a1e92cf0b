"""Operator commands: whether the engine takes one in its current state, and how to give one.

The decision is made at once, before the engine acts on it, so the command is recorded (trace
and report) ahead of the state changes it causes, with the answer the operator gets.  The keys
of the terminal console live here too, because the alarm message must name them, and the
console and the message must not drift apart.
"""
from __future__ import annotations

from dataclasses import dataclass

from node_transport.wire import ENGINE_SERVICES

#: Engine states a run has ended in.
ENDED = ("finished", "failed", "stopped")

#: The terminal console's key for each command (``run --interactive``); a whole word works too.
CONSOLE_KEYS: dict[str, str] = {"pause": "p", "resume": "r", "stop": "s", "step": "t", "reset": "x", "skip": "k"}


@dataclass(frozen=True)
class Flags:
    """What the decisions depend on besides the engine state."""

    start_requested: bool
    safety_active: bool
    skippable: bool = False  # the alarm is a resumed run's interrupted function: skip answers it


def decide(command: str, state: str, flags: Flags) -> tuple[bool, str]:
    """Accept or refuse ``command`` in ``state``; the answer the operator reads either way."""
    if command not in ENGINE_SERVICES:
        return False, f"unknown command {command!r} (commands: {', '.join(ENGINE_SERVICES)})"
    if command == "start":
        if flags.start_requested or state != "idle":
            return False, f"already {state}"
        return True, "started"
    if command == "stop":
        return (False, f"already {state}") if state in ENDED else (True, "stopping")
    if command == "skip":
        if state == "alarm" and flags.skippable:
            return True, "alarm acknowledged: the interrupted function is skipped (taken as done)"
        return False, "nothing to skip: skip answers the alarm of a function a crash interrupted" + (" (use reset or stop)" if state == "alarm" else f" ({state})")
    if command == "reset":
        return (True, "alarm acknowledged: retrying") if state == "alarm" else (False, f"no alarm to reset ({state})")
    if state in (*ENDED, "stopping", "alarm"):  # an alarm holds every group already; it wants an answer
        hint = " (use reset to acknowledge the alarm, or stop)" if state == "alarm" else ""
        return False, f"cannot {command}: {state}{hint}"
    if command == "resume" and flags.safety_active:
        return False, "the safety stop is still active"
    return True, {"pause": "paused", "resume": "resumed", "step": "stepping: the next operation runs, then the application pauses"}[command]


def console_source(key: str) -> str:
    """How a command typed at the terminal console is named in the trace and the report."""
    return f"terminal console (key {key!r})"
