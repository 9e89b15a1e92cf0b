"""The operator's speed override applied on the path: a running motion's own time runs slower.

A planned motion ``q(tau)`` is a path with its timing.  The override does not re-plan it: the
back end plays it at a *rate* ``r = dtau/dt`` in [0, 1] (1: as planned, 0: held on the path), so
every position the robot passes through is one of the planned path's, and the robot is never
faster than the application asked (``r`` never exceeds 1).  The joints then move with

    velocity      q'(tau) * r
    acceleration  q''(tau) * r**2 + q'(tau) * dr/dt

The first term is within the limits whenever the plan is and ``r <= 1``; the second is what
changing the rate costs.  :class:`PathRate` moves ``r`` towards the override no faster than
every joint's acceleration limit allows at the present point of the path (``dr/dt`` is kept in
the interval where ``|q'' r^2 + q' dr/dt| <= A`` holds for every joint, which always contains
0), and no faster than :data:`MAX_RATE_CHANGE`, so a change of the override -- 0 % included, a
controlled stop on the path -- never asks a joint for more than its limits, and raising it
again continues from where the robot stopped.  With no change under way it costs nothing.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Vector = NDArray[np.float64]

#: 1/s: the fastest the rate changes when no joint's limit binds (100 % to 0 % in 0.5 s at best),
#: so the acceleration changes in steps an operator can follow, not at once.
MAX_RATE_CHANGE = 2.0
#: s of path time: the step of the central differences that estimate the path's derivatives.
_PROBE = 1e-3

#: The path's first and second derivatives (per joint) at a path time tau: q'(tau), q''(tau).
Shape = Callable[[float], tuple[Vector, Vector]]


def fraction(percent: float) -> float:
    """An override in percent as the rate it asks for, in [0, 1]; ValueError outside [0, 100]."""
    if not (isinstance(percent, (int, float)) and math.isfinite(percent) and 0.0 <= percent <= 100.0):
        raise ValueError(f"speed override must be a percentage in [0, 100], got {percent!r}")
    return float(percent) / 100.0


def sampled_shape(at: Callable[[float], Vector], duration: float) -> Shape:
    """The derivatives of a path known only by its positions ``at(tau)`` on ``[0, duration]``,
    by central differences (one-sided at the ends)."""

    def shape(tau: float) -> tuple[Vector, Vector]:
        lo = max(0.0, tau - _PROBE)
        hi = min(duration, tau + _PROBE)
        mid = min(max(tau, lo), hi)
        if hi - lo <= 0.0:
            zero = np.zeros_like(np.asarray(at(mid), dtype=float))
            return zero, zero
        q_lo, q_mid, q_hi = (np.asarray(at(x), dtype=float) for x in (lo, mid, hi))
        velocity = (q_hi - q_lo) / (hi - lo)
        if mid - lo > 0.0 and hi - mid > 0.0:
            acceleration = 2.0 * ((q_hi - q_mid) / (hi - mid) - (q_mid - q_lo) / (mid - lo)) / (hi - lo)
        else:
            acceleration = np.zeros_like(velocity)
        return velocity, acceleration

    return shape


def rate_change_bounds(velocity: Vector, acceleration: Vector, limits: Vector, rate: float) -> tuple[float, float]:
    """The interval of ``dr/dt`` that keeps every joint within ``limits`` (rad/s^2) at this point of the path."""
    low, high = -math.inf, math.inf
    base = acceleration * rate * rate
    for v, a, limit in zip(velocity, base, limits):
        if abs(v) < 1e-12:
            continue
        one, two = (-limit - a) / v, (limit - a) / v
        low, high = max(low, min(one, two)), min(high, max(one, two))
    # the plan itself keeps |q''| <= A, so 0 is always allowed; rounding must not take that away
    return min(low, 0.0), max(high, 0.0)


@dataclass
class PathRate:
    """How fast one running motion's own time goes against the clock, and where it is heading."""

    target: float = 1.0
    rate: float = 1.0
    max_change: float = MAX_RATE_CHANGE

    @property
    def settled(self) -> bool:
        return self.rate == self.target

    @property
    def holding(self) -> bool:
        """Held on the path: the override is 0 % and the motion has come to rest."""
        return self.target == 0.0 and self.rate == 0.0

    def aim(self, target: float) -> None:
        if not 0.0 <= target <= 1.0:
            raise ValueError(f"a path rate lies in [0, 1], got {target!r}")
        self.target = target

    def advance(self, dt: float, tau: float = 0.0, shape: Shape | None = None, limits: Vector | None = None) -> float:
        """Path time covered over ``dt`` clock seconds from path time ``tau``, the rate moving towards
        its target as fast as the joints' acceleration ``limits`` allow (at the path's ``shape`` there)."""
        if dt <= 0.0:
            return 0.0
        start = self.rate
        if start == self.target:
            return start * dt
        wanted = (self.target - start) / dt
        low, high = -self.max_change, self.max_change
        if shape is not None and limits is not None:
            # at both ends of the step (a little beyond: the path's acceleration may change within it, at a ramp's
            # end, and the derivatives are differences over _PROBE), at the highest rate the step may reach
            highest = start if self.target <= start else min(self.target, start + self.max_change * dt)
            for at in (tau, tau + max(start, highest) * dt + 2.0 * _PROBE):
                velocity, acceleration = shape(at)
                lo, hi = rate_change_bounds(velocity, acceleration, limits, highest)
                low, high = max(low, lo), min(high, hi)
        change = min(max(wanted, low), high)
        end = start + change * dt
        end = self.target if (change > 0 and end >= self.target) or (change < 0 and end <= self.target) else end
        self.rate = min(max(end, 0.0), 1.0)
        return 0.5 * (start + self.rate) * dt
