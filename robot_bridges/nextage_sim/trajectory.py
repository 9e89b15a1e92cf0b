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
* Cartesian-linear moves sample the straight TCP line (position lerp, orientation slerp), solve IK
  at each sample from the previous solution, refuse joint-space jumps (a configuration change
  means no straight line exists), and time s(t) by the maximum TCP speed, stretched until no
  joint exceeds its velocity limit.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.model import describe_target

Vector = NDArray[np.float64]
Indices = NDArray[np.int64]

_EPS = 1e-12


# ---------------------------------------------------------------------------------- profile
@dataclass(frozen=True)
class Trapezoid:
    """s(t) from 0 to 1 with peak speed ``velocity`` (1/s) and acceleration ``acceleration`` (1/s^2)."""

    velocity: float
    acceleration: float
    duration: float
    ramp: float  # time spent accelerating (and, symmetrically, decelerating)

    @staticmethod
    def fit(max_velocity: float, max_acceleration: float) -> Trapezoid:
        """The fastest profile over a unit distance within both bounds (inf means unbounded)."""
        if not (max_velocity > 0 and max_acceleration > 0):
            raise ValueError(f"profile bounds must be > 0, got v={max_velocity}, a={max_acceleration}")
        if math.isinf(max_velocity) and math.isinf(max_acceleration):
            return Trapezoid(math.inf, math.inf, 0.0, 0.0)
        a = max_acceleration
        if max_velocity * max_velocity >= a:  # the cruise speed is never reached: triangle
            ramp = math.sqrt(1.0 / a)
            return Trapezoid(a * ramp, a, 2.0 * ramp, ramp)
        v = max_velocity
        ramp = v / a
        return Trapezoid(v, a, 1.0 / v + ramp, ramp)

    def position(self, t: float) -> float:
        if self.duration <= 0.0 or t >= self.duration:
            return 1.0
        if t <= 0.0:
            return 0.0
        a, ramp = self.acceleration, self.ramp
        if t < ramp:
            return 0.5 * a * t * t
        if t > self.duration - ramp:
            rest = self.duration - t
            return 1.0 - 0.5 * a * rest * rest
        return 0.5 * a * ramp * ramp + self.velocity * (t - ramp)


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


class Hold(Motion):
    """Stay at ``positions`` for ``duration`` (a dwell, a hand or camera action)."""

    def __init__(self, indices: Indices, positions: Vector, duration: float) -> None:
        self.indices = indices
        self.positions = positions.copy()
        self.duration = max(0.0, duration)

    def at(self, t: float) -> Vector:
        return self.positions.copy()


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


class TimedMove(Motion):
    """Joint points reached at given times, linearly interpolated (trajectory replay)."""

    def __init__(self, indices: Indices, times: Vector, points: NDArray[np.float64]) -> None:
        self.indices = indices
        self.times = times
        self.points = points
        self.duration = float(times[-1]) if len(times) else 0.0

    def at(self, t: float) -> Vector:
        return _interpolate(self.times, self.points, t)


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
    """Times and positions every ``period`` seconds, the exact end included."""
    count = max(1, math.ceil(motion.duration / period - 1e-9))
    times = np.minimum(np.arange(count + 1) * period, motion.duration)
    return times, np.array([motion.at(float(t)) for t in times])


# -------------------------------------------------------------------------- joint-space plans
def plan_joint_move(
    indices: Indices, start: Vector, goal: Vector, velocity: Vector, acceleration: Vector, speed: float
) -> JointMove:
    """The synchronised trapezoid from ``start`` to ``goal`` at speed fraction ``speed``.

    ``velocity``/``acceleration`` are the limits of the joints ``indices``.  With s the shared
    path parameter, joint i moves d_i * s, so s may reach min(v_i/|d_i|) and min(a_i/|d_i|).
    """
    distance = np.abs(goal - start)
    moving = distance > _EPS
    if not moving.any():
        return JointMove(indices, start, goal, Trapezoid(math.inf, math.inf, 0.0, 0.0))
    v = float(np.min(velocity[moving] / distance[moving]))
    a = float(np.min(acceleration[moving] / distance[moving]))
    return JointMove(indices, start, goal, Trapezoid.fit(v * speed, a * speed * speed))


# --------------------------------------------------------------------------- Cartesian plans
@dataclass(frozen=True)
class CartesianLimits:
    """TCP speed and acceleration bounds of linear moves at speed fraction 1."""

    linear_velocity: float = 0.25  # m/s
    angular_velocity: float = 1.0  # rad/s
    linear_acceleration: float = 0.5  # m/s^2
    angular_acceleration: float = 2.0  # rad/s^2
    step: float = 0.005  # m between IK samples along the line
    angle_step: float = math.radians(2.0)  # rad between IK samples
    max_joint_jump: float = 0.25  # rad between neighbouring samples before refining
    refinements: int = 3  # times a jumping interval is split (x4 each) before giving up


def interpolate_pose(start: Pose, end: Pose, s: float) -> Pose:
    """Position lerp and orientation slerp (shortest way) at fraction ``s``."""
    q0 = np.array(start.quaternion)
    q1 = np.array(end.quaternion)
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + (q1 - q0) * s
    else:
        theta = math.acos(min(1.0, dot))
        q = (math.sin((1.0 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)
    q /= np.linalg.norm(q)
    p = np.array(start.position) + (np.array(end.position) - np.array(start.position)) * s
    return Pose(float(p[0]), float(p[1]), float(p[2]), float(q[0]), float(q[1]), float(q[2]), float(q[3]))


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
    if length <= _EPS and angle <= _EPS:
        return PathMove(indices, knot_array, samples, Trapezoid(math.inf, math.inf, 0.0, 0.0))
    v = min(_ratio(limits.linear_velocity, length), _ratio(limits.angular_velocity, angle))
    a = min(_ratio(limits.linear_acceleration, length), _ratio(limits.angular_acceleration, angle))
    slope = np.max(np.abs(np.diff(samples, axis=0)) / np.diff(knot_array)[:, None], axis=0)  # |dq/ds|
    moving = slope > _EPS
    if moving.any():
        v = min(v, float(np.min(velocity[moving] / slope[moving])))
        a = min(a, float(np.min(acceleration[moving] / slope[moving])))
    return PathMove(indices, knot_array, samples, Trapezoid.fit(v * speed, a * speed * speed))


def _ratio(limit: float, amount: float) -> float:
    return math.inf if amount <= _EPS else limit / amount


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
