"""Trapezoidal timing of a path parameter, shared by every back end that plans its own motions.

A planned motion is a path in joint space traversed by a parameter s in [0, 1]; how fast s may
run is set by the robot's limits.  Keeping that one profile here lets the Nextage simulator and
the V+ back end time a recorded straight line the same way, so a trajectory recorded on one
means the same speed as on the other, and the recording can name the instant each sample of the
line is reached (:meth:`Trapezoid.time_at`): a replay that interpolates between stored samples
only follows the planned path if the samples sit where the path bends.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Vector = NDArray[np.float64]

_EPS = 1e-12
#: s: a sample this close to a kept one adds nothing but a division by a tiny span.
MERGE_TIME = 1e-6


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

    @staticmethod
    def instant() -> Trapezoid:
        """The profile of a motion of zero length."""
        return Trapezoid(math.inf, math.inf, 0.0, 0.0)

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

    def time_at(self, s: float) -> float:
        """The instant the profile reaches ``s`` (the inverse of :meth:`position`)."""
        if self.duration <= 0.0 or s <= 0.0:
            return 0.0
        if s >= 1.0:
            return self.duration
        a, ramp = self.acceleration, self.ramp
        edge = 0.5 * a * ramp * ramp  # s covered by one ramp
        if s <= edge:
            return math.sqrt(2.0 * s / a)
        if s >= 1.0 - edge:
            return self.duration - math.sqrt(2.0 * (1.0 - s) / a)
        return ramp + (s - edge) / self.velocity


@dataclass(frozen=True)
class TcpLimits:
    """TCP speed and acceleration bounds of a straight-line motion at speed fraction 1."""

    linear_velocity: float = 0.25  # m/s
    angular_velocity: float = 1.0  # rad/s
    linear_acceleration: float = 0.5  # m/s^2
    angular_acceleration: float = 2.0  # rad/s^2


def path_profile(
    fractions: Vector,
    joints: NDArray[np.float64],
    length: float,
    angle: float,
    tcp: TcpLimits,
    velocity: Vector,
    acceleration: Vector,
    speed: float,
) -> Trapezoid:
    """The fastest trapezoid on s for joint samples ``joints`` at ``fractions`` of a TCP path.

    The TCP bounds act on the path's ``length`` (m) and ``angle`` (rad).  Between samples the
    joints are interpolated linearly in s, so |dq/ds| is constant there and ``max |dq/ds| * ds/dt
    <= velocity`` is exact: no joint exceeds its velocity limit, whatever instants a replay
    later samples.  Accelerations are bounded the same way, which is approximate (dq/ds jumps
    at the samples).  ``speed`` is the speed fraction: it scales time.
    """
    if length <= _EPS and angle <= _EPS:
        return Trapezoid.instant()
    v = min(_ratio(tcp.linear_velocity, length), _ratio(tcp.angular_velocity, angle))
    a = min(_ratio(tcp.linear_acceleration, length), _ratio(tcp.angular_acceleration, angle))
    spans = np.diff(fractions)
    steps = np.abs(np.diff(joints, axis=0))
    slope = np.max(steps[spans > _EPS] / spans[spans > _EPS, None], axis=0, initial=0.0)  # |dq/ds|
    moving = slope > _EPS
    if moving.any():
        v = min(v, float(np.min(velocity[moving] / slope[moving])))
        a = min(a, float(np.min(acceleration[moving] / slope[moving])))
    return Trapezoid.fit(v * speed, a * speed * speed)


def joint_profile(start: Vector, goal: Vector, velocity: Vector, acceleration: Vector, speed: float) -> Trapezoid:
    """The synchronised trapezoid of a joint-space line from ``start`` to ``goal``.

    Joint i moves d_i * s, so s may reach min(v_i / |d_i|) and min(a_i / |d_i|): every joint
    starts and stops together and none exceeds its limits.  ``speed`` scales time.
    """
    distance = np.abs(np.asarray(goal, dtype=float) - np.asarray(start, dtype=float))
    moving = distance > _EPS
    if not moving.any():
        return Trapezoid.instant()
    v = float(np.min(velocity[moving] / distance[moving]))
    a = float(np.min(acceleration[moving] / distance[moving]))
    return Trapezoid.fit(v * speed, a * speed * speed)


def _ratio(limit: float, amount: float) -> float:
    return math.inf if amount <= _EPS else limit / amount


def sample_times(duration: float, period: float, corners: Iterable[float] = ()) -> Vector:
    """Every ``period`` seconds over ``[0, duration]`` (the exact end included), plus ``corners``.

    ``corners`` are the instants where the sampled motion's joint path bends (where a straight
    line was sampled, where one segment meets the next).  A replay interpolating between the
    returned instants then follows the same joint path, not a chord across a bend; the regular
    ones keep the speed profile.  Grid instants closer than :data:`MERGE_TIME` to a corner give
    way to it, so no span is too short to divide by.
    """
    if not (period > 0 and math.isfinite(period)):
        raise ValueError(f"sample period must be a positive number of seconds, got {period!r}")
    count = max(1, math.ceil(duration / period - 1e-9))
    grid = np.minimum(np.arange(count + 1) * period, duration)
    inner = np.unique(np.array([c for c in corners if MERGE_TIME < c < duration - MERGE_TIME], dtype=float))
    if inner.size == 0:
        return grid
    keep = np.concatenate([[True], np.diff(inner) > MERGE_TIME])
    inner = inner[keep]
    nearest = np.min(np.abs(grid[1:-1, None] - inner[None, :]), axis=1) if count > 1 else np.zeros(0)
    middle = grid[1:-1][nearest > MERGE_TIME]
    return np.sort(np.concatenate([grid[:1], middle, inner, grid[-1:]]))
