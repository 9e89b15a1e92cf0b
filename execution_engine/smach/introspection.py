"""What an observer of a machine sees: its structure once, then every transition with its time.

This is the paper's first requirement ("introspection ... provide current execution state
continuously"); the group machine forwards it to ``/<group>/sm/structure`` and ``status``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class StructureInfo:
    """States, outcome-to-target rows and the container's own outcomes."""

    name: str
    initial: str
    states: tuple[str, ...]
    transitions: tuple[tuple[str, str, str], ...]  # (from state, outcome, target)
    outcomes: tuple[str, ...]


@dataclass(frozen=True)
class TransitionRecord:
    """``source --outcome--> target`` at run time ``t`` (target may be a container outcome)."""

    machine: str
    source: str
    outcome: str
    target: str
    t: float


class MachineObserver(Protocol):
    def on_structure(self, structure: StructureInfo) -> None: ...

    def on_enter(self, machine: str, state: str, t: float) -> None: ...

    def on_transition(self, record: TransitionRecord) -> None: ...
