"""What a dry run remembers of every motion, for the collision sweep after it.

Each motion is kept with the time it ran on the report's time base, a function giving its
joints at any moment and a bound on each joint's speed over the whole motion (what the collision
sweep's conservative advancement steps by): the simulator's own planned motion where the back end
shows it (the Nextage simulator's ``motion_observer``: the exact path, profile and all, and its
exact peak speeds), otherwise the straight line in joint space from where the joints were to where
they ended (exact in path for a point-to-point move, the way V+ and RSI drive their joints; its
speed is the distance over the time).  Gripper actions are kept too: a closing gripper takes the
part under it, an opening one lets go.
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

    @property
    def speeds(self) -> Vector:
        """rad/s (or m/s) each of :attr:`joints` moves at most during the motion."""
        return self.speeds_between(0.0, self.duration)

    def speeds_between(self, start: float, end: float) -> Vector:
        """The same between ``start`` and ``end`` s into the motion (a ramp is slower than the cruise)."""
        return np.asarray(getattr(self.at, "bound")(start, end), dtype=float)


@dataclass(frozen=True)
class GripRecord:
    """A gripper of ``group`` closed (``closed``) or opened at ``t``, in call (``operation``, ``function``)."""

    group: str
    operation: str
    function: str
    t: float
    closed: bool


class Path:
    """A sampler with the speed bound of its joints between two instants (``bound(start, end)``):
    what :func:`straight` and :func:`planned` give."""

    def __init__(self, at: Sampler, bound: Callable[[float, float], Vector]) -> None:
        self._at = at
        self.bound = bound

    def __call__(self, t: float) -> Vector:
        return self._at(t)


def straight(start: Sequence[float], end: Sequence[float], duration: float) -> Path:
    """Joint-space straight line from ``start`` to ``end`` over ``duration`` seconds, at constant speed."""
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)

    def at(t: float) -> Vector:
        if duration <= 0.0:
            return b
        s = min(max(t / duration, 0.0), 1.0)
        return a + (b - a) * s

    speeds = np.abs(b - a) / duration if duration > 0.0 else np.zeros(len(a))
    return Path(at, lambda start, end: speeds)


def planned(motion: object, duration: float) -> Path:
    """A simulator's motion object (``at(t)`` over ``[0, duration]`` and ``speed_bound(start, end)``) as a sampler."""
    at = getattr(motion, "at")
    bound = getattr(motion, "speed_bound", None)
    if bound is None:
        raise TypeError(f"{type(motion).__name__} gives no speed_bound(): the collision sweep cannot step along it")

    def sample(t: float) -> Vector:
        return np.asarray(at(min(max(t, 0.0), duration)), dtype=float)

    return Path(sample, lambda start, end: np.asarray(bound(max(start, 0.0), end), dtype=float))
