"""What a dry run remembers of every motion, for the collision sweep after it.

Each motion is kept with the time it ran on the report's time base and a function giving its
joints at any moment: the simulator's own planned motion where the back end shows it (the
Nextage simulator's ``motion_observer``: the exact path, profile and all), otherwise the straight
line in joint space from where the joints were to where they ended (exact in path for a
point-to-point move, the way V+ and RSI drive their joints).  Gripper actions are kept too: a
closing gripper takes the part under it, an opening one lets go.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cell_runner.dry_run.report import Span

Vector = NDArray[np.float64]
#: Positions of a motion's joints ``t`` seconds into it.
Sampler = Callable[[float], Vector]


@dataclass(frozen=True)
class MotionRecord:
    """One motion: its span on the timeline (who, which call, when: ending at the motion's own end),
    the joints it moves, by name, and their positions ``t`` seconds after its start (held at the end)."""

    span: Span
    joints: tuple[str, ...]
    at: Sampler

    @property
    def group(self) -> str:
        return self.span.group

    @property
    def start(self) -> float:
        return self.span.start

    @property
    def end(self) -> float:
        return self.span.end

    @property
    def duration(self) -> float:
        return self.span.duration


@dataclass(frozen=True)
class GripRecord:
    """A gripper of ``group`` closed (``closed``) or opened at ``t``, in call (``operation``, ``function``)."""

    group: str
    operation: str
    function: str
    t: float
    closed: bool


def straight(start: Sequence[float], end: Sequence[float], duration: float) -> Sampler:
    """Joint-space straight line from ``start`` to ``end`` over ``duration`` seconds."""
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)

    def at(t: float) -> Vector:
        if duration <= 0.0:
            return b
        s = min(max(t / duration, 0.0), 1.0)
        return a + (b - a) * s

    return at


def planned(motion: object, duration: float) -> Sampler:
    """A simulator's motion object (``at(t)`` over ``[0, duration]``) as a sampler."""
    at = getattr(motion, "at")

    def sample(t: float) -> Vector:
        return np.asarray(at(min(max(t, 0.0), duration)), dtype=float)

    return sample
