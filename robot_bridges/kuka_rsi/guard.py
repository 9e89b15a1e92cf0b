"""The last word before a correction leaves: the per-cycle limiter and the controller cross-check.

Two rules the external system keeps whatever its generators, streams or catch-ups computed, and
whatever the controller says:

* **limiter** -- no correction step may move an axis faster than its speed limit, nor change its
  step faster than its acceleration limit allows (joint corrections, per axis); a Cartesian
  correction step is held to the linear and angular speed and acceleration limits.  The step is
  measured from the set point the controller holds (:mod:`.setpoint`), so a cycle the controller
  held still counts as a step of zero.  A step beyond is clamped, counted and reported, never sent.
* **cross-check** -- what the controller reports (``ASPos``; ``RSol`` while Cartesian corrections
  run) must match the set point our own replies put there, within a tolerance; the report may be
  one cycle behind (``lag``), as a controller applying a correction a cycle later shows it.  A
  disagreement is a fault: the report is never taken as an input.

KUKA does not publish the KR 6's axis accelerations; :data:`ACCEL_TIME` sets the default -- every
axis from rest to its full speed in 0.1 s -- and a link configures its own.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.kinematics import rotation_angle

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

#: Seconds from rest to an axis's full speed: the default acceleration limit is speed / ACCEL_TIME.
ACCEL_TIME = 0.1
#: A step this much beyond its limit (relative) is rounding, not a violation.
_SLACK = 1e-9
#: Axis names for messages.
AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


def limit_joint_step(step: Vector, previous: Vector, max_step: Vector, max_change: Vector) -> tuple[Vector, list[int]]:
    """``step`` clamped to ``previous +- max_change`` and then to ``+- max_step``, and the axes clamped.

    The speed limit wins where the two disagree (a controller that jumped on its own leaves a
    previous step no acceleration could follow): never faster than the axis.
    """
    slack = 1.0 + _SLACK
    if (np.abs(step) <= max_step * slack).all() and (np.abs(step - previous) <= max_change * slack).all():
        return step, []  # the common case, in a few microseconds
    out = np.minimum(np.maximum(step, previous - max_change), previous + max_change)
    out = np.minimum(np.maximum(out, -max_step), max_step)
    over = np.abs(out - step) > _SLACK * (1.0 + np.abs(step))
    return out, [int(i) for i in np.nonzero(over)[0]]


def limit_vector_step(step: Vector, previous: Vector, max_step: float, max_change: float) -> tuple[Vector, bool]:
    """A 3-vector step (translation or rotation vector) held to a speed and acceleration by norm."""
    out, clamped = step, False
    change = out - previous
    size = float(np.linalg.norm(change))
    if size > max_change * (1 + _SLACK):
        out, clamped = previous + change * (max_change / size), True
    size = float(np.linalg.norm(out))
    if size > max_step * (1 + _SLACK):
        out, clamped = out * (max_step / size), True
    return out, clamped


def joint_disagreement(reported: Vector, candidates: Sequence[Vector], tolerance: Vector) -> tuple[int, Vector] | None:
    """None when ``reported`` (rad) lies within ``tolerance`` of one candidate set point (newest
    last), every axis; else the axis furthest beyond its tolerance and the candidate that came closest."""
    if (np.abs(reported - candidates[-1]) <= tolerance).all():
        return None  # the common case: the newest set point, in a few microseconds
    best: tuple[float, int, Vector] | None = None
    for candidate in candidates:
        excess = np.abs(reported - candidate) / tolerance
        worst = int(np.argmax(excess))
        if excess[worst] <= 1.0:
            return None
        if best is None or excess[worst] < best[0]:
            best = (float(excess[worst]), worst, candidate)
    assert best is not None
    return best[1], best[2]


def pose_disagreement(reported: Matrix, candidates: Sequence[Matrix], tolerance_m: float, tolerance_rad: float) -> tuple[float, float] | None:
    """None when ``reported`` (4x4) lies within the tolerances of one candidate pose; else the
    smallest ``(shift m, turn rad)`` found."""
    best: tuple[float, float, float] | None = None
    for candidate in candidates:
        shift = float(np.linalg.norm(reported[:3, 3] - candidate[:3, 3]))
        turn = rotation_angle(reported[:3, :3] @ candidate[:3, :3].T)
        if shift <= tolerance_m and turn <= tolerance_rad:
            return None
        score = max(shift / tolerance_m, turn / tolerance_rad)
        if best is None or score < best[0]:
            best = (score, shift, turn)
    assert best is not None
    return best[1], best[2]


def describe_joint_fault(axis: int, commanded: Vector, reported: Vector, tolerance: Vector) -> str:
    """The words of a cross-check fault on an axis (degrees)."""
    return (
        f"{AXES[axis]}: commanded {math.degrees(float(commanded[axis])):.3f} deg, the controller reports "
        f"{math.degrees(float(reported[axis])):.3f} deg (tolerance {math.degrees(float(tolerance[axis])):.3f} deg); "
        "the controller does not hold the set point it was sent"
    )


def joint_outside_tube(actual: Vector, window: Sequence[Vector], tolerance: Vector) -> tuple[int, float, float] | None:
    """None when every actual axis (rad) lies between the lowest and the highest set point of ``window``
    (the last cycles' commanded set points), widened by ``tolerance``; else the axis furthest out and
    the span (low, high) it should lie in.

    A servo's actual position trails its set point: whatever the lag, a following axis lies among the
    set points it was given lately (a first-order lag is a weighted mean of them), never outside.
    """
    first, last = window[0], window[-1]
    if (np.abs(actual - (first + last) * 0.5) <= np.abs(last - first) * 0.5 + tolerance).all():
        return None  # between the window's ends (the common case, a monotonic move or rest): inside the whole span
    span = np.array(window)
    low, high = span.min(axis=0), span.max(axis=0)
    if ((actual >= low - tolerance) & (actual <= high + tolerance)).all():
        return None
    excess = np.maximum(low - actual, actual - high) / tolerance
    axis = int(np.argmax(excess))
    return axis, float(low[axis]), float(high[axis])


def pose_outside_tube(actual: Matrix, window: Sequence[Matrix], tolerance_m: float, tolerance_rad: float) -> tuple[float, float] | None:
    """The same for a TCP pose: its position within the box of the window's positions (widened by
    ``tolerance_m``), its orientation within ``tolerance_rad`` plus the window's largest turn between two
    cycles of the nearest orientation of the window; else ``(shift m, turn rad)`` beyond."""
    positions = np.array([pose[:3, 3] for pose in window])
    low, high = positions.min(axis=0) - tolerance_m, positions.max(axis=0) + tolerance_m
    p = actual[:3, 3]
    shift = float(np.linalg.norm(np.maximum(low - p, 0.0) + np.maximum(p - high, 0.0)))
    spread = max((rotation_angle(b[:3, :3] @ a[:3, :3].T) for a, b in zip(window, list(window)[1:])), default=0.0)
    turn = min(rotation_angle(actual[:3, :3] @ pose[:3, :3].T) for pose in window)
    if shift <= 0.0 and turn <= tolerance_rad + spread:
        return None
    return shift, max(0.0, turn - spread)
