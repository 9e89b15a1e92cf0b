"""A recorded joint trajectory as one set point per RSI cycle: on the chords between its samples.

Two things a replay must keep, and what each rules out:

* **the path** -- a recording promises that joint interpolation between its samples stays within
  its tolerance of the line it recorded (:mod:`.recording`), so every set point must lie on a
  chord between two consecutive samples.  A cubic per axis leaves the chords: where a recording
  stops between two straight legs, such a cubic keeps its speed and cuts the corner (5.7 times the
  0.1 mm tolerance, measured on three-leg sweeps);
* **the axes' limits per cycle** -- no step faster than an axis, no change of step beyond its
  acceleration (the loop's limiter would stop the stream, and the path check refuses it before a
  point is sent).  Straight lines between the samples at their own mean speeds change the speed
  in one cycle at every sample.

So the geometry and the timing are separate.  The path is the polygon of the samples, walked by
its arc length (Euclidean, in joint space).  The recorded timing is a monotone cubic of the arc
length through ``(t_k, arc_k)`` -- every sample at its recorded time, at rest at both ends, never a
step back -- evaluated once per cycle.  Where the polygon bends, walking it at the recorded speed
turns the joint velocity within a cycle; where that turn (or the speed) is more than an axis can
do, the replay plays the recorded timing at a *rate* below one cycle per cycle, which it ramps
down before the bend and up after it within what the acceleration leaves over.  Along a finely
sampled line the chords barely bend and the replay keeps the recorded times exactly; at a corner
it slows, as the recording itself did (its legs end at rest).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Vector = NDArray[np.float64]
Points = NDArray[np.float64]

#: The share of an axis's acceleration budget per cycle that the bends may take; the rest is for
#: ramping the rate.  Halved on each retry when a plan still comes out over the budget.
BEND_SHARE = 0.5
#: The slowest rate: a point of the recorded timing in at most this many cycles.
MAX_SLOWDOWN = 1000
_RETRIES = 4
_TINY = 1e-15


def resample(times: Vector, points: Points, dt: float, max_speed: Vector, max_accel: Vector) -> Points:
    """The set points of a timed trajectory at every cycle ``dt``: on its chords, from rest to rest.

    ``times`` must increase strictly, one per row of ``points``; ``max_speed`` and ``max_accel`` are
    per axis (the points' unit per s and per s^2).  The first row is ``points[0]``, the last
    ``points[-1]``; each sample is passed at its recorded time unless a bend or a speed needs more.
    """
    return resample_along(times, points, dt, max_speed, max_accel)[0]


def resample_along(times: Vector, points: Points, dt: float, max_speed: Vector, max_accel: Vector) -> tuple[Points, Vector]:
    """:func:`resample`, and how far along the samples' polygon (its arc length) each set point lies:
    what tells, after a pause, which samples the stream had passed (:func:`samples_passed`)."""
    t = np.asarray(times, dtype=float)
    p = np.asarray(points, dtype=float)
    if len(t) != len(p) or len(t) < 2 or not np.all(np.diff(t) > 0):
        raise ValueError("trajectory times must increase strictly, one per point")
    polygon = _Polygon(p)
    arc = _recorded_arc(t, polygon.arc, _grid(t[0], t[-1], dt))
    budget = np.asarray(max_accel, dtype=float) * dt * dt
    reach = np.asarray(max_speed, dtype=float) * dt
    along = arc
    planned = polygon.at(along)
    share = BEND_SHARE
    for _ in range(_RETRIES):
        if _within(planned, reach, budget):
            return planned, along
        along = _slowed(arc, polygon, reach, budget, share)
        planned = polygon.at(along)
        share /= 2.0
    return planned, along  # still over: the path check refuses it, naming the point


def samples_passed(points: Points, along: Vector, reached: float) -> int:
    """The last sample of ``points`` a replay planned by :func:`resample_along` (``along``: its set points'
    arc lengths) had passed when its set point ``reached`` (an index, fractional) was commanded."""
    arc = _Polygon(np.asarray(points, dtype=float)).arc
    at = float(np.interp(reached, np.arange(len(along), dtype=float), along))
    return int(np.clip(np.searchsorted(arc, at * (1 + 1e-12) + _TINY, side="right") - 1, 0, len(arc) - 1))


def remainder(times: Vector, points: Points, here: Vector, after: int) -> tuple[Vector, Points]:
    """What is left of a timed trajectory for an arm standing at ``here`` (after a pause): ``here`` in
    place of the sample nearest to it, searched from sample ``after`` on (what was passed is never
    played again, even where the trajectory comes back over it), then every later sample at its
    recorded time.  Only the last sample when nothing follows the nearest."""
    times, points = np.asarray(times, dtype=float), np.asarray(points, dtype=float)
    after = min(max(0, after), len(points) - 1)
    nearest = after + int(np.argmin(np.max(np.abs(points[after:] - here), axis=1)))
    if nearest + 1 >= len(points):
        return times[-1:], points[-1:]
    return times[nearest:], np.vstack((np.asarray(here, dtype=float)[None, :], points[nearest + 1:]))


class _Polygon:
    """The samples joined by straight chords, addressed by arc length."""

    def __init__(self, points: Points) -> None:
        self.points = points
        self.length = np.linalg.norm(np.diff(points, axis=0), axis=1)
        self.arc = np.concatenate(([0.0], np.cumsum(self.length)))

    def at(self, arc: Vector) -> Points:
        k = np.clip(np.searchsorted(self.arc, arc, side="right") - 1, 0, len(self.length) - 1)
        span = self.length[k]
        w = np.where(span > _TINY, (arc - self.arc[k]) / np.where(span > _TINY, span, 1.0), 0.0)
        out: Points = self.points[k] + (self.points[k + 1] - self.points[k]) * np.clip(w, 0.0, 1.0)[:, None]
        return out


def _grid(start: float, end: float, dt: float) -> Vector:
    """Every cycle from ``start``; the last one on ``end`` (a shorter last cycle, never a missed end)."""
    count = max(1, int(np.ceil((end - start) / dt - 1e-9)))
    grid = start + np.arange(count + 1) * dt
    grid[-1] = end
    return grid


def _recorded_arc(t: Vector, arc: Vector, grid: Vector) -> Vector:
    """The arc length at ``grid`` by the recorded timing: a monotone cubic through ``(t, arc)``.

    Slopes: zero at both ends and beside a hold, else the weighted harmonic mean of the
    neighbouring secants (Fritsch-Butland: at most three times the smaller, so never a step back).
    """
    h = np.diff(t)
    secant = np.diff(arc) / h
    slope = np.zeros(len(t))
    if len(h) > 1:
        left, right = secant[:-1], secant[1:]
        w1, w2 = 2 * h[1:] + h[:-1], h[1:] + 2 * h[:-1]
        both = (left > 0) & (right > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope[1:-1] = np.where(both, (w1 + w2) / (w1 / left + w2 / right), 0.0)
    k = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2)
    span = h[k]
    u = (grid - t[k]) / span
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    value = h00 * arc[k] + h10 * span * slope[k] + h01 * arc[k + 1] + h11 * span * slope[k + 1]
    return np.maximum.accumulate(np.clip(value, arc[k], arc[k + 1]))


def _within(planned: Points, reach: Vector, budget: Vector) -> bool:
    """Every step within the speeds, every change of step (and the stop at the end) within the budget."""
    steps = np.diff(planned, axis=0)
    if np.any(np.abs(steps) > reach * (1 + 1e-9)):
        return False
    change = np.abs(np.diff(steps, axis=0, prepend=0.0, append=0.0))
    return not np.any(change > budget * (1 + 1e-9))


def _slowed(arc: Vector, polygon: _Polygon, reach: Vector, budget: Vector, share: float) -> Vector:
    """The recorded timing ``arc`` (one value per cycle) played at a rate that keeps every step within limits.

    At rate ``r`` (recorded cycles per cycle) a step is ``r`` times the recorded one, and a bend the
    recorded timing turns through in one cycle turns ``r`` times as fast; changing the rate by
    ``dr`` changes a step by ``dr`` times the recorded step.  So each recorded step gets the
    highest rate within the speeds and within ``share`` of the budget at its bends, and the rate
    moves from step to step by no more than the rest of the budget allows.
    """
    steps = np.diff(polygon.at(arc), axis=0)  # the recorded steps, one per cycle
    size = np.abs(steps)
    change = np.abs(np.diff(steps, axis=0, prepend=0.0, append=0.0))  # into step n, and out of the last
    bend = np.maximum(change[:-1] + change[1:], 0.0)  # a bend inside a step shows on both sides of it
    with np.errstate(divide="ignore", invalid="ignore"):
        by_speed = np.min(np.where(size > _TINY, reach / size, np.inf), axis=1)
        by_bend = np.min(np.where(bend > _TINY, share * budget / bend, np.inf), axis=1)
        ramp = np.min(np.where(size > _TINY, (1.0 - share) * budget / size, np.inf), axis=1)
    rate = np.clip(np.minimum(by_speed, by_bend), 1.0 / MAX_SLOWDOWN, 1.0)
    for n in range(len(rate) - 2, -1, -1):  # slow down in time for what comes
        rate[n] = min(rate[n], rate[n + 1] + ramp[n])
    for n in range(1, len(rate)):  # and speed up no faster than allowed
        rate[n] = min(rate[n], rate[n - 1] + ramp[n - 1])
    last = len(arc) - 1
    index = np.arange(len(arc), dtype=float)
    positions = [0.0]
    x = 0.0
    for _ in range(last * MAX_SLOWDOWN):
        if x >= last:
            break
        x = min(float(last), x + float(rate[min(int(x), last - 1)]))
        positions.append(x)
    return np.interp(np.array(positions), index, arc)
