"""Timed joint motions for the simulator: synchronised joint-space moves and Cartesian-linear paths.

Every motion the simulator executes is a :class:`Motion`: a pure function of time from its start
to joint positions, planned completely (IK included) before the robot moves.  That is what makes
pause/resume exact -- the executor holds the motion's clock and later continues the *same*
function to the *same* target -- and it makes a failing plan fail before anything moved.

Timing model (docs/nextage_sim.md):

* Profiles are trapezoidal in a path parameter s in [0, 1] (constant acceleration, cruise,
  constant deceleration; triangular when the cruise speed is never reached).
* Joint-space moves are synchronised: all joints follow the same s(t), whose peak speed and
  acceleration are set by the joint that needs them most relative to its limits, so every joint
  starts and stops together and none exceeds its velocity or acceleration limit.
* The speed fraction f scales *time*: a move at f takes exactly 1/f as long as at full speed
  (velocities scale by f, accelerations by f^2).
* Cartesian-linear moves and recordings sample the straight TCP line (position lerp, orientation
  slerp) where the line needs it (:mod:`core_functions.linear_path`: bisection until the joint
  interpolation between samples stays within the tolerance), refuse lines that leave the
  workspace or cross a singularity, and time s(t) by the maximum TCP speed, stretched until no
  joint exceeds its velocity limit (:func:`core_functions.motion_profile.path_profile`).
* A recording keeps every sample of such a line (:meth:`Motion.breakpoints`), so a replay that
  interpolates joints between stored samples follows the same path.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.linear_path import (
    LineSamplingError,
    LineTolerance,
    NoSolution,
    SamplingBounds,
    StraightLine,
    interpolate_pose,
    plan_line,
)
from core_functions.motion_profile import TcpLimits, Trapezoid, joint_profile, path_profile, sample_times
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.model import describe_target

Vector = NDArray[np.float64]
Indices = NDArray[np.int64]

_EPS = 1e-12


# ----------------------------------------------------------------------------------- motions
class Motion(ABC):
    """Positions of the joints ``indices`` (into the full joint vector) over ``[0, duration]``."""

    indices: Indices
    duration: float

    @abstractmethod
    def at(self, t: float) -> Vector:
        """Joint positions at ``t`` seconds after the start (clamped to the ends)."""

    @property
    def end(self) -> Vector:
        return self.at(self.duration)

    @abstractmethod
    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        """The most each joint's speed reaches between ``start`` and ``end`` s into the motion (rad/s):
        what the collision check's conservative advancement steps by (robot_bridges/collision/sweep.py).
        Slower stretches (a ramp, a short segment) give a smaller bound, so longer steps."""

    def breakpoints(self) -> Vector:
        """The instants where the joint path bends; between two of them it is a straight joint-space line.

        A recording must keep them: a replay interpolating between samples that skip one cuts
        the corner, and the TCP leaves the planned path.
        """
        return np.array([0.0, self.duration])


class Scaled(Motion):
    """``motion`` played at a constant ``rate`` (0, 1] of its own time: a motion started under a speed override, as the
    dry run's collision sweep must see it (its positions at the clock's times, its speeds scaled by the rate)."""

    def __init__(self, motion: Motion, rate: float) -> None:
        if not 0.0 < rate <= 1.0:
            raise ValueError(f"a motion plays at a rate in (0, 1], not {rate!r}")
        self.motion, self.rate = motion, rate
        self.indices = motion.indices
        self.duration = motion.duration / rate

    def at(self, t: float) -> Vector:
        return self.motion.at(t * self.rate)

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        return self.motion.speed_bound(start * self.rate, end * self.rate) * self.rate

    def breakpoints(self) -> Vector:
        return self.motion.breakpoints() / self.rate


def at_rate(motion: Motion, rate: float) -> tuple[Motion, float]:
    """``motion`` and its duration as played at ``rate`` (itself at 1)."""
    shown = motion if rate == 1.0 else Scaled(motion, rate)
    return shown, shown.duration


class Hold(Motion):
    """Stay at ``positions`` for ``duration`` (a dwell, a hand or camera action)."""

    def __init__(self, indices: Indices, positions: Vector, duration: float) -> None:
        self.indices = indices
        self.positions = positions.copy()
        self.duration = max(0.0, duration)

    def at(self, t: float) -> Vector:
        return self.positions.copy()

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        return np.zeros(len(self.positions))


class JointMove(Motion):
    """Straight line in joint space, every joint on the same trapezoid."""

    def __init__(self, indices: Indices, start: Vector, goal: Vector, profile: Trapezoid) -> None:
        self.indices = indices
        self.start = start.copy()
        self.goal = goal.copy()
        self.profile = profile
        self.duration = profile.duration

    def at(self, t: float) -> Vector:
        return self.start + (self.goal - self.start) * self.profile.position(t)

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        return _scaled(np.abs(self.goal - self.start), _peak_rate(self.profile, start, end))


class PathMove(Motion):
    """Joint samples along a path parameter, interpolated linearly, traversed by a trapezoid."""

    def __init__(self, indices: Indices, knots: Vector, samples: NDArray[np.float64], profile: Trapezoid) -> None:
        self.indices = indices
        self.knots = knots
        self.samples = samples
        self.profile = profile
        self.duration = profile.duration

    def at(self, t: float) -> Vector:
        return _interpolate(self.knots, self.samples, self.profile.position(t))

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        s0, s1 = self.profile.position(start), self.profile.position(min(end, self.duration))
        return _scaled(_window(self.knots, self._slopes, s0, s1), _peak_rate(self.profile, start, end))

    @cached_property
    def _slopes(self) -> NDArray[np.float64]:
        return _slopes(self.knots, self.samples)

    def breakpoints(self) -> Vector:
        return np.array([self.profile.time_at(float(s)) for s in self.knots])


class TimedMove(Motion):
    """Joint points reached at given times, linearly interpolated (trajectory replay)."""

    def __init__(self, indices: Indices, times: Vector, points: NDArray[np.float64]) -> None:
        self.indices = indices
        self.times = times
        self.points = points
        self.duration = float(times[-1]) if len(times) else 0.0

    def at(self, t: float) -> Vector:
        return _interpolate(self.times, self.points, t)

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        return _window(self.times, self._slopes, start, end)

    @cached_property
    def _slopes(self) -> NDArray[np.float64]:
        return _slopes(self.times, self.points)

    def breakpoints(self) -> Vector:
        return self.times.copy()


class Chain(Motion):
    """Motions of the same joints one after the other (a path through several waypoints)."""

    def __init__(self, segments: Sequence[Motion]) -> None:
        if not segments:
            raise ValueError("a chain needs at least one motion")
        self.segments = tuple(segments)
        self.indices = segments[0].indices
        self._starts = np.cumsum([0.0] + [m.duration for m in segments[:-1]])
        self.duration = float(self._starts[-1] + segments[-1].duration)

    def at(self, t: float) -> Vector:
        k = int(np.searchsorted(self._starts, t, side="right")) - 1
        k = min(max(k, 0), len(self.segments) - 1)
        return self.segments[k].at(t - float(self._starts[k]))

    def breakpoints(self) -> Vector:
        return np.concatenate([m.breakpoints() + start for m, start in zip(self.segments, self._starts)])

    def speed_bound(self, start: float = 0.0, end: float = math.inf) -> Vector:
        bounds = [m.speed_bound(max(start - t0, 0.0), end - t0) for m, t0 in zip(self.segments, self._starts.tolist())
                  if t0 <= end and t0 + m.duration >= start]
        return np.max(bounds, axis=0) if bounds else np.zeros(len(self.indices))


def _peak_rate(profile: Trapezoid, start: float, end: float) -> float:
    """The most ds/dt of a trapezoid between ``start`` and ``end``: rising on the first ramp, flat, falling on the last."""
    if profile.duration <= 0.0:
        return profile.velocity
    start, end = max(start, 0.0), min(end, profile.duration)
    if end <= profile.ramp:
        return profile.acceleration * max(end, 0.0)
    if start >= profile.duration - profile.ramp:
        return profile.acceleration * max(profile.duration - start, 0.0)
    return profile.velocity


def _scaled(path_slope: Vector, peak: float) -> Vector:
    """Joint speeds of a path whose parameter moves at most at ``peak`` (1/s): a joint that does not move has 0."""
    return np.where(path_slope > 0.0, path_slope * peak, 0.0) if np.isfinite(peak) else np.where(path_slope > 0.0, np.inf, 0.0)


def _window(knots: Vector, slopes: NDArray[np.float64], low: float, high: float) -> Vector:
    """Each joint's steepest slope (rows of :func:`_slopes`) over the knot intervals that reach into ``[low, high]``."""
    if len(slopes) == 0:
        return np.zeros(slopes.shape[1])
    first = max(int(np.searchsorted(knots, low, side="right")) - 1, 0)
    last = min(max(int(np.searchsorted(knots, high, side="left")), first + 1), len(slopes))
    return np.max(slopes[first:last], axis=0)


def _slopes(knots: Vector, samples: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each joint's change per unit of ``knots`` on each interval between neighbouring samples (rows).

    A jump (two samples at one knot) has no bound: inf, which the collision check refuses to step along;
    one below 1e-9 (a rounding step a replay accepts) is no motion.
    """
    width = samples.shape[1] if samples.ndim == 2 else 0
    if len(knots) < 2:
        return np.zeros((0, width))
    steps = np.abs(np.diff(samples, axis=0))
    spans = np.diff(knots)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        slopes = np.where(steps > 1e-9, np.where(spans > _EPS, steps / np.maximum(spans, _EPS), np.inf), 0.0)
    return slopes


def _interpolate(knots: Vector, samples: NDArray[np.float64], x: float) -> Vector:
    if x <= knots[0]:
        return samples[0].copy()
    if x >= knots[-1]:
        return samples[-1].copy()
    k = int(np.searchsorted(knots, x, side="right")) - 1
    span = knots[k + 1] - knots[k]
    w = 0.0 if span <= _EPS else (x - knots[k]) / span
    return samples[k] + (samples[k + 1] - samples[k]) * w


def sample(motion: Motion, period: float) -> tuple[Vector, NDArray[np.float64]]:
    """Times and positions every ``period`` seconds, the exact end and every breakpoint included.

    The breakpoints make a replay that interpolates joints between the samples follow
    ``motion``'s own joint path (a sampled straight line stays within its tolerance); the regular
    samples keep its speed profile.
    """
    times = sample_times(motion.duration, period, motion.breakpoints())
    return times, np.array([motion.at(float(t)) for t in times])


# -------------------------------------------------------------------------- joint-space plans
def plan_joint_move(
    indices: Indices, start: Vector, goal: Vector, velocity: Vector, acceleration: Vector, speed: float
) -> JointMove:
    """The synchronised trapezoid from ``start`` to ``goal`` at speed fraction ``speed``.

    ``velocity``/``acceleration`` are the limits of the joints ``indices``
    (:func:`core_functions.motion_profile.joint_profile`).
    """
    return JointMove(indices, start, goal, joint_profile(start, goal, velocity, acceleration, speed))


# --------------------------------------------------------------------------- Cartesian plans
@dataclass(frozen=True)
class CartesianLimits(TcpLimits):
    """TCP bounds of linear moves at speed fraction 1, and how their lines are sampled.

    ``tolerance`` is what a single-arm straight line (MoveCartesian / MoveRelative ``linear``)
    keeps to; a recording uses the tolerance its primitive names.  ``step`` ... ``refinements``
    are the fixed-step sampling of master/slave paths, whose slave path is not a straight line.
    """

    step: float = 0.005  # m between IK samples along the line
    angle_step: float = math.radians(2.0)  # rad between IK samples
    max_joint_jump: float = 0.25  # rad between neighbouring samples before refining
    refinements: int = 3  # times a jumping interval is split (x4 each) before giving up
    tolerance: LineTolerance = LineTolerance()
    sampling: SamplingBounds = SamplingBounds()


@dataclass(frozen=True)
class LinearLeg:
    """One arm's part of a Cartesian path: where its TCP is at s, and how to solve for it."""

    name: str  # the group, for error messages
    start_q: Vector  # the arm's joints at s = 0
    pose_at: Callable[[float], Pose]
    solve: Callable[[Pose, Vector], Vector]  # (target, seed arm joints) -> arm joints, or BridgeError
    joint_names: tuple[str, ...]
    length: float  # m the TCP travels
    angle: float  # rad the TCP turns


def straight_leg(
    name: str, start_q: Vector, start: Pose, end: Pose, solve: Callable[[Pose, Vector], Vector], joint_names: tuple[str, ...]
) -> LinearLeg:
    """The leg of a straight TCP line from ``start`` to ``end``."""
    return LinearLeg(
        name, start_q, lambda s: interpolate_pose(start, end, s), solve, joint_names, start.distance_to(end), start.angle_to(end)
    )


def plan_linear(
    indices: Indices,
    legs: Sequence[LinearLeg],
    velocity: Vector,
    acceleration: Vector,
    limits: CartesianLimits,
    speed: float,
) -> PathMove:
    """Sample the legs' TCP paths with IK, check continuity, and time them together.

    ``indices`` are the full-vector indices of the legs' joints concatenated in leg order, and
    ``velocity``/``acceleration`` their limits.  Raises ``BridgeError(UNREACHABLE)`` when a sample
    has no IK solution or the joints would have to jump (the straight line crosses a
    configuration change or a singularity).
    """
    length = max(leg.length for leg in legs)
    angle = max(leg.angle for leg in legs)
    count = max(1, math.ceil(max(length / limits.step, angle / limits.angle_step)))
    knots: list[float] = [0.0]
    rows: list[Vector] = [np.concatenate([leg.start_q for leg in legs])]
    for i in range(1, count + 1):
        _extend(legs, limits, knots, rows, i / count, limits.refinements)
    knot_array = np.array(knots)
    samples = np.array(rows)
    profile = path_profile(knot_array, samples, length, angle, limits, velocity, acceleration, speed)
    return PathMove(indices, knot_array, samples, profile)


def plan_straight(
    indices: Indices,
    leg: LinearLeg,
    forward: Callable[[Vector], Pose],
    velocity: Vector,
    acceleration: Vector,
    limits: CartesianLimits,
    tolerance: LineTolerance,
    speed: float,
) -> PathMove:
    """One arm's straight TCP line, sampled so that joint interpolation keeps within ``tolerance``.

    ``forward`` maps the arm's joints to its TCP pose.  The samples come from
    :func:`core_functions.linear_path.plan_line` (bisection where the chord strays) and are the
    path's knots, so the executed motion -- and any replay of samples taken at its breakpoints --
    is the sampled path itself.  Raises ``BridgeError(UNREACHABLE)`` naming the arm, the target
    and where on the line it fails (out of reach, a singularity, a tolerance it cannot keep).
    """
    line = StraightLine(leg.pose_at(0.0), leg.pose_at(1.0))

    def solve(target: Pose, seed: Vector) -> Vector:
        try:
            return leg.solve(target, seed)
        except BridgeError as error:
            raise NoSolution(error.detail) from None

    try:
        timed = plan_line(line, leg.start_q, solve, forward, limits, velocity, acceleration, speed, tolerance, limits.sampling, leg.joint_names)
    except LineSamplingError as error:
        raise BridgeError(FaultKind.UNREACHABLE, f"{leg.name}: the straight line to {describe_target(line.end)}: {error}") from None
    return PathMove(indices, timed.samples.fractions, timed.samples.joints, timed.profile)


def _extend(legs: Sequence[LinearLeg], limits: CartesianLimits, knots: list[float], rows: list[Vector], s: float, depth: int) -> None:
    """Append the sample at ``s``, splitting the interval while the joints jump."""
    previous = rows[-1]
    row = _solve_row(legs, previous, s)
    jump = np.abs(row - previous)
    if float(np.max(jump)) <= limits.max_joint_jump:
        knots.append(s)
        rows.append(row)
        return
    if depth > 0:
        s0 = knots[-1]
        for j in range(1, 5):
            _extend(legs, limits, knots, rows, s0 + (s - s0) * j / 4, depth - 1)
        return
    worst = int(np.argmax(jump))
    names = [n for leg in legs for n in leg.joint_names]
    leg = legs[_leg_of(legs, worst)]
    raise BridgeError(
        FaultKind.UNREACHABLE,
        f"{leg.name}: no continuous straight-line motion to {describe_target(leg.pose_at(1.0))}: "
        f"{names[worst]} would jump {math.degrees(float(jump[worst])):.1f} deg at {100 * s:.0f}% of the path "
        "(a configuration change or singularity on the line)",
    )


def _solve_row(legs: Sequence[LinearLeg], previous: Vector, s: float) -> Vector:
    parts = []
    offset = 0
    for leg in legs:
        n = len(leg.joint_names)
        target = leg.pose_at(s)
        try:
            parts.append(leg.solve(target, previous[offset : offset + n]))
        except BridgeError as error:
            raise BridgeError(
                FaultKind.UNREACHABLE,
                f"{leg.name}: the straight line to {describe_target(leg.pose_at(1.0))} leaves the reachable "
                f"workspace at {100 * s:.0f}% of the path ({error.detail})",
            ) from error
        offset += n
    return np.concatenate(parts)


def _leg_of(legs: Sequence[LinearLeg], column: int) -> int:
    offset = 0
    for k, leg in enumerate(legs):
        offset += len(leg.joint_names)
        if column < offset:
            return k
    return len(legs) - 1


# ------------------------------------------------------------------------ trajectory replay
def plan_replay(
    indices: Indices,
    names: Sequence[str],
    current: Vector,
    times: Vector,
    points: NDArray[np.float64],
    velocity: Vector,
    acceleration: Vector,
    speed: float,
) -> Motion:
    """Follow ``points`` at ``times / speed``, first moving to the first point if not there.

    Raises ``BridgeError(JOINT_LIMIT)`` naming the joint when a segment would need more than
    the joint's velocity limit (the trajectory was recorded faster than the robot can go).
    """
    scaled = (times - times[0]) / speed
    steps = np.diff(points, axis=0)
    spans = np.diff(scaled)
    for k in range(len(spans)):
        needed = np.abs(steps[k]) / spans[k] if spans[k] > _EPS else np.where(np.abs(steps[k]) > 1e-9, math.inf, 0.0)
        over = needed > velocity * (1.0 + 1e-6)
        if over.any():
            j = int(np.argmax(needed - velocity))
            raise BridgeError(
                FaultKind.JOINT_LIMIT,
                f"{names[j]} would move at {needed[j]:.3f} rad/s between points {k} and {k + 1} "
                f"(t = {scaled[k]:.3f}..{scaled[k + 1]:.3f} s at speed {speed:g}), above its limit "
                f"{velocity[j]:.3f} rad/s",
            )
    replay = TimedMove(indices, scaled, points)
    if float(np.max(np.abs(points[0] - current))) <= 1e-6:
        return replay
    approach = plan_joint_move(indices, current, points[0], velocity, acceleration, speed)
    return Chain([approach, replay])
