"""Injected faults: make the simulator fail the way a real cell does, on purpose, for tests and demos.

Error handling (retry, safe pose, operator alarm) can only be tested if primitives fail at will
and realistically: a joint-limit stop half-way through a move leaves the arm half-way, an IK
failure happens before anything moves.  A :class:`FaultSpec` says which group fails, with which
:class:`FaultKind`, and at which fraction of the primitive's duration; the simulator consumes it
on the next primitive of that group it applies to:

* ``unreachable`` -- the next Cartesian primitive (MoveCartesian, MoveRelative, MasterSlaveMove,
  a planned RecordTrajectory) fails as an IK failure; at ``@0`` (its default) before moving.
* ``vision`` -- the next Vision primitive finds nothing.
* any other kind -- the next motion (MoveJoints, MoveCartesian, MoveRelative, ExecuteTrajectory,
  FullBodyMove, MasterSlaveMove) stops part-way with that fault (default ``@0.5``).

The text form ``<group>:<kind>[@<fraction>]`` (e.g. ``right_arm:joint_limit@0.5``) is what a CLI
option or a launch parameter carries.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from core_functions.primitives import (
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    RecordTrajectory,
    Vision,
)
from robot_bridges.backend import FaultKind

CARTESIAN_PRIMITIVES: tuple[type, ...] = (MoveCartesian, MoveRelative, MasterSlaveMove, RecordTrajectory)
MOTION_PRIMITIVES: tuple[type, ...] = (MoveJoints, MoveCartesian, MoveRelative, ExecuteTrajectory, FullBodyMove, MasterSlaveMove)
MAX_FAULT_TEXT = 200
_FAULT_TEXT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*:\s*([A-Za-z_]+)\s*(?:@\s*([^\s]+))?\s*$")


@dataclass(frozen=True)
class FaultSpec:
    """Fail the next applicable primitive of ``group`` with ``kind`` at ``after`` x its duration."""

    group: str
    kind: FaultKind
    after: float = 0.5

    def __post_init__(self) -> None:
        if not (0.0 <= self.after <= 1.0):
            raise ValueError(f"fault fraction must be within [0, 1], got {self.after}")

    def applies_to(self, primitive: Primitive) -> bool:
        if self.kind is FaultKind.UNREACHABLE:
            if isinstance(primitive, RecordTrajectory):
                return primitive.mode == "plan"
            return isinstance(primitive, CARTESIAN_PRIMITIVES)
        if self.kind is FaultKind.VISION:
            return isinstance(primitive, Vision)
        return isinstance(primitive, MOTION_PRIMITIVES)

    def __str__(self) -> str:
        return f"{self.group}:{self.kind.value}@{self.after:g}"


def parse_fault(text: str) -> FaultSpec:
    """``"right_arm:joint_limit@0.5"`` -> FaultSpec; a ValueError quoting the text otherwise."""
    if len(text) > MAX_FAULT_TEXT:
        raise ValueError(f"fault spec is longer than {MAX_FAULT_TEXT} characters")
    match = _FAULT_TEXT.match(text)
    if not match:
        raise ValueError(f"fault spec {text!r} is not <group>:<kind>[@<fraction>] (e.g. right_arm:joint_limit@0.5)")
    group, kind_text, after_text = match.groups()
    try:
        kind = FaultKind(kind_text.lower())
    except ValueError:
        known = ", ".join(k.value for k in FaultKind)
        raise ValueError(f"fault spec {text!r}: unknown fault kind {kind_text!r} (known: {known})") from None
    if after_text is None:
        after = 0.0 if kind is FaultKind.UNREACHABLE else 0.5
    else:
        try:
            after = float(after_text)
        except ValueError:
            raise ValueError(f"fault spec {text!r}: {after_text!r} is not a number") from None
        if not (0.0 <= after <= 1.0):
            raise ValueError(f"fault spec {text!r}: the fraction must be within [0, 1], got {after_text}")
    return FaultSpec(group, kind, after)


class FaultPlan:
    """Faults waiting for their primitive, in the order they were injected."""

    def __init__(self, specs: Iterable[FaultSpec] = ()) -> None:
        self._pending: list[FaultSpec] = list(specs)

    def add(self, spec: FaultSpec) -> None:
        self._pending.append(spec)

    @property
    def pending(self) -> tuple[FaultSpec, ...]:
        return tuple(self._pending)

    def take(self, groups: Iterable[str], primitive: Primitive) -> FaultSpec | None:
        """Remove and return the first fault of one of ``groups`` that applies to ``primitive``."""
        wanted = set(groups)
        for i, spec in enumerate(self._pending):
            if spec.group in wanted and spec.applies_to(primitive):
                return self._pending.pop(i)
        return None
