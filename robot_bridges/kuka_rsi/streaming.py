"""Tool paths streamed one point per RSI cycle: ITRA's computer-based approach (``setToolPathFromFile``).

The trajectory is planned beforehand and every interpolation cycle takes the next point, so the
path is followed exactly -- but nothing smooths it any more: a point too far from the previous
one is a jump the robot must not make.  So a file is checked completely before a single point
is sent: every value finite, joints inside their limits, no step between two consecutive points
(or from the robot to the first point) faster than the speed limits allow, no change of step
faster than the acceleration limits allow, and the last point reached at rest.  Problems are
reported with the file and line.

A controller that held still for a cycle (a late reply) leaves the stream behind the path; going
on at the path's speed at once would be a jump in speed.  :class:`StreamCursor` plays the path at
a fractional point index: one point per cycle as planned, but after a hold -- or from a start
away from rest -- its rate ramps up from the held speed as fast as the acceleration left over by
the path allows, so the robot re-enters the path without a jump and then follows it exactly.

File format (text, one point per line, ``#`` starts a comment, values separated by blanks or
commas), in the controller's units because such files come from KUKA tooling:

* ``joint``: ``A1 A2 A3 A4 A5 A6`` in degrees;
* ``cartesian``: ``X Y Z`` in mm and ``A B C`` in degrees (KUKA's Z-Y'-X'' angles).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, rotation_angle
from robot_bridges.kuka_rsi.otg import matrix_to_rotvec

Space = Literal["joint", "cartesian"]
MAX_FILE_BYTES = 256 * 1024 * 1024
MAX_POINTS = 2_000_000
_SPLIT = re.compile(r"[\s,]+")


class ToolPathError(ValueError):
    """The tool-path file cannot be streamed; the message names the file and line."""


@dataclass(frozen=True)
class ToolPath:
    """Points in SI: joints in rad, or x y z (m) and A B C (rad)."""

    space: Space
    points: NDArray[np.float64]  # shape (n, 6)
    source: str = "<memory>"
    lines: tuple[int, ...] = ()  # the file line of each point, for messages

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def where(self, i: int) -> str:
        return f"{self.source}:{self.lines[i]}" if self.lines else f"{self.source} point {i + 1}"


def parse_tool_path(text: str, space: Space, source: str = "<string>") -> ToolPath:
    """Read the points of a tool-path text (see the module docstring)."""
    if space not in ("joint", "cartesian"):
        raise ToolPathError(f"{source}: space must be 'joint' or 'cartesian', not {space!r}")
    rows: list[list[float]] = []
    lines: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = [p for p in _SPLIT.split(body) if p]
        if len(parts) != 6:
            raise ToolPathError(f"{source}:{number}: expected 6 values, found {len(parts)}")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise ToolPathError(f"{source}:{number}: not a number in {body!r}") from None
        if not all(math.isfinite(v) for v in values) or any("_" in p for p in parts):
            raise ToolPathError(f"{source}:{number}: values must be finite decimal numbers")
        rows.append(values)
        lines.append(number)
        if len(rows) > MAX_POINTS:
            raise ToolPathError(f"{source}:{number}: more than {MAX_POINTS} points")
    if not rows:
        raise ToolPathError(f"{source}: no points")
    raw = np.array(rows, dtype=float)
    if space == "joint":
        points = np.radians(raw)
    else:
        points = np.column_stack((raw[:, :3] / 1000.0, np.radians(raw[:, 3:])))
    return ToolPath(space, points, source, tuple(lines))


def load_tool_path(path: str | Path, space: Space) -> ToolPath:
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ToolPathError(f"{path}: {size} bytes, more than the {MAX_FILE_BYTES} allowed")
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ToolPathError(f"{path}: cannot read tool path: {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise ToolPathError(f"{path}: not UTF-8 text ({error.reason} at byte {error.start})") from None
    return parse_tool_path(text, space, str(path))


def check_tool_path(
    path: ToolPath,
    dt: float,
    *,
    lower: NDArray[np.float64] | None = None,
    upper: NDArray[np.float64] | None = None,
    max_joint_speed: NDArray[np.float64] | None = None,
    max_speed: float = 2.0,
    max_angular_speed: float = math.pi,
    start: NDArray[np.float64] | None = None,
    max_joint_accel: NDArray[np.float64] | None = None,
    max_accel: float | None = None,
    max_angular_accel: float | None = None,
) -> None:
    """Refuse a path the robot cannot follow one point per cycle ``dt`` (raises ToolPathError).

    ``start`` is where the robot is (same units as the points): the first point must be
    reachable from it within one cycle too.  With acceleration limits the change of step between
    consecutive points is checked as well, and the last step, into which the robot stops.
    """
    _check_speed(path, dt, lower, upper, max_joint_speed, max_speed, max_angular_speed, start)
    if path.space == "joint":
        if max_joint_accel is not None:
            _check_change(path, np.diff(path.points, axis=0), max_joint_accel * dt * dt, None, "deg")
        return
    if max_accel is not None:
        _check_change(path, np.diff(path.points[:, :3], axis=0), np.array(max_accel * dt * dt), "the TCP", "mm")
    if max_angular_accel is not None and len(path) > 1:
        rotations = [abc_to_matrix(*p[3:]) for p in path.points]
        turns = np.array([matrix_to_rotvec(rotations[i + 1] @ rotations[i].T) for i in range(len(rotations) - 1)])
        _check_change(path, turns, np.array(max_angular_accel * dt * dt), "the tool orientation", "deg")


def _check_change(path: ToolPath, steps: NDArray[np.float64], budget: NDArray[np.float64], group: str | None, unit: str) -> None:
    """Refuse a change of step (row ``i`` of ``steps`` is the step into point ``i + 1``) beyond
    ``budget`` per cycle, and a last step the robot could not stop from in one cycle.

    ``group`` None: every coordinate against its own budget (axes, rad); else the steps are
    3-vectors measured by their length (m or rad) against one budget.
    """
    def size(rows: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.abs(rows) if group is None else np.linalg.norm(rows, axis=-1, keepdims=True)

    def words(value: float) -> str:
        return f"{value * 1000.0:.4f} mm" if unit == "mm" else f"{math.degrees(value):.4f} deg"

    limit = budget * (1 + 1e-9) + 1e-15
    where = group or "an axis"
    if len(steps) > 1:
        change = size(np.diff(steps, axis=0))
        over = np.nonzero(np.any(change > limit, axis=1))[0]
        if over.size:
            j = int(over[0])
            raise ToolPathError(
                f"{path.where(j + 1)}: the step out of this point changes by {words(float(np.max(change[j])))} on {where}, "
                f"more than the acceleration allows in one cycle ({words(float(np.min(budget)))})"
            )
    if len(steps):
        last = size(steps[-1:])[0]
        if np.any(last > limit):
            raise ToolPathError(
                f"{path.where(len(path) - 1)}: the robot must come to rest at the last point, but the step into it is "
                f"{words(float(np.max(last)))} on {where}, more than it can stop from in one cycle "
                f"({words(float(np.min(budget)))}); slow the path down to its end"
            )


def _check_speed(
    path: ToolPath,
    dt: float,
    lower: NDArray[np.float64] | None,
    upper: NDArray[np.float64] | None,
    max_joint_speed: NDArray[np.float64] | None,
    max_speed: float,
    max_angular_speed: float,
    start: NDArray[np.float64] | None,
) -> None:
    """Limits and the speed of every step (see :func:`check_tool_path`)."""
    pts = path.points if start is None else np.vstack((np.asarray(start, dtype=float), path.points))
    offset = 0 if start is None else 1
    if path.space == "joint":
        if lower is not None and upper is not None:
            outside = np.nonzero(np.any((path.points < lower - 1e-9) | (path.points > upper + 1e-9), axis=1))[0]
            if outside.size:
                i = int(outside[0])
                raise ToolPathError(f"{path.where(i)}: point {np.degrees(path.points[i]).round(3).tolist()} deg is outside the joint limits")
        if max_joint_speed is not None and len(pts) > 1:
            speed = np.abs(np.diff(pts, axis=0)) / dt
            over = np.nonzero(np.any(speed > max_joint_speed * (1 + 1e-9), axis=1))[0]
            if over.size:
                j = int(over[0])
                _too_fast(path, j + 1 - offset, f"{math.degrees(float(np.max(speed[j]))):.1f} deg/s on an axis")
        return
    if len(pts) > 1:
        linear = np.linalg.norm(np.diff(pts[:, :3], axis=0), axis=1) / dt
        over = np.nonzero(linear > max_speed * (1 + 1e-9))[0]
        if over.size:
            j = int(over[0])
            _too_fast(path, j + 1 - offset, f"{linear[j]:.3f} m/s (limit {max_speed:g})")
        rotations = [abc_to_matrix(*p[3:]) for p in pts]
        for i in range(1, len(rotations)):
            turn = rotation_angle(rotations[i] @ rotations[i - 1].T) / dt
            if turn > max_angular_speed * (1 + 1e-9):
                _too_fast(path, i - offset, f"{turn:.3f} rad/s (limit {max_angular_speed:g})")


def _too_fast(path: ToolPath, i: int, what: str) -> None:
    """The step into path point ``i`` is too fast (``i`` = 0: from where the robot is to the first point)."""
    if i == 0:
        raise ToolPathError(f"{path.where(0)}: the first point is too far from where the robot is ({what} in one cycle)")
    raise ToolPathError(f"{path.where(i)}: the step to this point needs {what}; the path must move at most that far per cycle")


#: The slowest re-entry: from rest to the path's speed in at most this many cycles.
MAX_RAMP_CYCLES = 1000


STILL = 1e-12  # rad or m per cycle: a smaller step is rounding, not motion


def ramp_rate(points: NDArray[np.float64], budget: NDArray[np.float64]) -> float:
    """How much a stream's rate (points per cycle) may grow per cycle within ``budget``.

    Playing at rate ``r`` that grows by ``dr``, a step changes by at most ``dr * D + r * A`` per
    cycle, ``D`` and ``A`` being the path's largest step and change of step on each coordinate;
    so ``dr = min((budget - A) / D)`` keeps every change within the budget.
    """
    if len(points) < 2:
        return 1.0
    steps = np.abs(np.diff(points, axis=0))
    largest = steps.max(axis=0)
    change = np.abs(np.diff(points, n=2, axis=0)).max(axis=0) if len(points) > 2 else np.zeros(points.shape[1])
    moving = largest > STILL  # a step below it is no motion, and dividing by it would overflow
    if not np.any(moving):
        return 1.0
    rate = float(np.min((budget[moving] - change[moving]) / largest[moving]))
    return min(1.0, max(1.0 / MAX_RAMP_CYCLES, rate))


class StreamCursor:
    """Where a stream is: a fractional index into its points and a rate in points per cycle.

    Row 0 of ``points`` is where the robot stood when the stream began.  At rate 1 every cycle
    takes the next point, exactly as planned; below 1 (a start away from rest, a re-entry after
    the controller held) the cursor interpolates between points and the rate grows by ``ramp``
    per cycle (see :func:`ramp_rate`).
    """

    def __init__(self, points: NDArray[np.float64], ramp: float, rate: float = 1.0) -> None:
        self.points = points
        self.last = len(points) - 1
        self.ramp = ramp
        self.position = 0.0
        self.rate = rate
        self.cap = 1.0  # the speed override: the rate moves towards it by ``ramp`` per cycle, up or down

    @property
    def done(self) -> bool:
        return self.position >= self.last

    @property
    def point(self) -> int:
        """The number (from 1) of the path point the cursor is on or just past."""
        return max(1, math.ceil(self.position - 1e-9))

    def at(self, position: float) -> NDArray[np.float64]:
        i = min(int(position), self.last)
        fraction = position - i
        if fraction <= 0.0 or i >= self.last:
            return self.points[i].copy()
        return self.points[i] + fraction * (self.points[i + 1] - self.points[i])

    def advance(self) -> NDArray[np.float64]:
        """The set point of the next cycle."""
        if self.rate < self.cap:
            self.rate = min(self.cap, self.rate + self.ramp)
        elif self.rate > self.cap:  # slowing down costs what speeding up does: within the budget (ramp_rate)
            self.rate = max(self.cap, self.rate - self.ramp)
        self.position = min(float(self.last), self.position + self.rate)
        return self.at(self.position)

    def hold(self, position: float, rate: float) -> None:
        """Go on from ``position`` at ``rate`` (what the controller is known to hold)."""
        self.position = min(float(self.last), max(0.0, position))
        self.rate = min(1.0, max(0.0, rate))

    def velocity(self, dt: float) -> NDArray[np.float64]:
        """The velocity of the last step, so a generator taking over brakes instead of stopping dead."""
        return (self.at(self.position) - self.at(max(0.0, self.position - self.rate))) / dt

