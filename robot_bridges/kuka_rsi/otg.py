"""Online second-order trajectory generation, stepped once per RSI cycle.

ITRA's RSI-based approach (seed 003, after Haschke et al.) reaches a target that may change at any
cycle, keeping velocity continuous and within given maximum speed and acceleration.  Here the
generator runs in the external system and its set point goes to the robot as a correction every
cycle.  It is a discrete *braking-curve* law, the same each cycle whatever happened before, so a
new target mid-motion needs no replanning:

* the wanted velocity points at the target; its size is the largest from which the remaining
  distance can still be braked to rest exactly, in whole cycles, at the maximum deceleration --
  and never above the maximum speed;
* the velocity moves toward the wanted one by at most ``a_max * dt`` per cycle.

Because the new velocity is a convex combination of the old one and the wanted one, speed never
exceeds the limit and acceleration never exceeds its limit, whatever the targets do.  Starting
from rest, the velocity stays parallel to the remaining distance, so all axes arrive together (a
synchronised PTP move in joint space, a straight line with a matching slerp in Cartesian space);
from rest the profile is the time-optimal trapezoid, landing exactly on the target.

Vectors are measured per *group* of coordinates: a group's length is its Euclidean norm divided by
its limit, and the vector's size is the largest group's.  Joints are six groups of one (each axis
its own limit); a Cartesian pose is two groups of three (translation in m, rotation in rad).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.kinematics import rotation_angle

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

#: Below these, a generator at its target is at rest (m or rad, m/s or rad/s).
POSITION_EPS = 1e-9
VELOCITY_EPS = 1e-9
#: Beyond this many braking steps (units of ``accel dt^2``) the braking speed is the continuous
#: curve's: far above any speed limit, so the limit decides.
FAR_CYCLES = 1e15


class GroupNorm:
    """``max_g |x[g]|_2 / limit_g``: how many limits long a vector is, group by group."""

    def __init__(self, sizes: Sequence[int]) -> None:
        self.dim = sum(sizes)
        self._starts = np.cumsum([0, *sizes[:-1]])
        self._single = all(s == 1 for s in sizes)

    def __call__(self, x: Vector, limits: Vector) -> float:
        if self._single:
            return float(np.max(np.abs(x) / limits))
        return float(np.max(np.sqrt(np.add.reduceat(x * x, self._starts)) / limits))


def braking_speed(distance: float, accel: float, dt: float) -> float:
    """Largest speed for the next cycle from which ``distance`` is braked to rest exactly.

    With ``p += v dt`` and ``v`` falling by ``accel dt`` per cycle, a speed of ``n accel dt``
    (``m < n <= m + 1``) takes the cycles ``n, n-1, ..., n-m`` to stop and covers
    ``accel dt^2 ((m + 1) n - m (m + 1) / 2)``; that is solved for ``n`` exactly, so the last
    cycle lands on the target instead of dithering around it.
    """
    if distance <= 0.0:
        return 0.0
    step = accel * dt
    cycles = distance / (step * dt)  # the distance in units of accel dt^2
    if not cycles <= FAR_CYCLES:
        # The whole-cycle correction is below rounding there, and ceil() of an overflowed count raises.
        return math.sqrt(2.0 * distance) * math.sqrt(accel)
    m = max(0, math.ceil((math.sqrt(1.0 + 8.0 * cycles) - 3.0) / 2.0))
    if m * (m + 1) / 2 >= cycles:  # guard the ceil against rounding
        m = max(0, m - 1)
    n = (cycles + m * (m + 1) / 2) / (m + 1)
    return n * step


class VectorOTG:
    """Second-order generator for a vector that lives in a flat space (joints, a position)."""

    def __init__(self, sizes: Sequence[int], dt: float) -> None:
        if not dt > 0:
            raise ValueError(f"cycle time must be > 0, got {dt}")
        self.norm = GroupNorm(sizes)
        self.dt = dt
        n_groups = len(sizes)
        self.position = np.zeros(self.norm.dim)
        self.velocity = np.zeros(self.norm.dim)
        self.target: Vector | None = None
        self.vmax = np.ones(n_groups)
        self.amax = np.ones(n_groups)
        self.scale = 1.0  # the speed override: the share of vmax the move may reach (0: brakes to rest on its line)
        self.done = True

    def reset(self, position: Sequence[float] | Vector, velocity: Sequence[float] | Vector | None = None) -> None:
        """Put the generator at ``position`` (at rest unless ``velocity``), with no target."""
        self.position = np.array(position, dtype=float)
        self.velocity = np.zeros(self.norm.dim) if velocity is None else np.array(velocity, dtype=float)
        self.target = None
        self.done = not np.any(self.velocity)

    def set_limits(self, vmax: Sequence[float] | Vector | float, amax: Sequence[float] | Vector | float) -> None:
        vmax_a = np.broadcast_to(np.asarray(vmax, dtype=float), self.vmax.shape).copy()
        amax_a = np.broadcast_to(np.asarray(amax, dtype=float), self.amax.shape).copy()
        if not (np.all(vmax_a > 0) and np.all(amax_a > 0) and np.all(np.isfinite(vmax_a)) and np.all(np.isfinite(amax_a))):
            raise ValueError(f"speed and acceleration limits must be finite and > 0, got {vmax_a}, {amax_a}")
        self.vmax, self.amax = vmax_a, amax_a

    def set_target(self, target: Sequence[float] | Vector, vmax: Sequence[float] | Vector | float, amax: Sequence[float] | Vector | float) -> None:
        """Aim at ``target`` from wherever the generator is, at whatever velocity it has."""
        self.set_limits(vmax, amax)
        self.target = np.array(target, dtype=float)
        self.done = False

    def halt(self) -> None:
        """Brake to rest at the maximum deceleration, wherever that ends."""
        self.target = None
        self.done = not np.any(self.velocity)

    def resync(self, position: Sequence[float] | Vector, velocity: Sequence[float] | Vector | None = None) -> None:
        """Go on from ``position`` at ``velocity`` (rest unless given) toward the same target:
        where the robot really is, when it did not follow (or a limiter held it back)."""
        self.position = np.array(position, dtype=float)
        self.velocity = np.zeros(self.norm.dim) if velocity is None else np.array(velocity, dtype=float)
        self.done = self.target is None and not np.any(self.velocity)

    def error(self) -> Vector:
        if self.target is None:
            return np.zeros(self.norm.dim)
        return self.target - self.position

    def step(self) -> bool:
        """Advance one cycle; True when at rest on the target (or at rest after a halt)."""
        if self.done:
            return True
        error = self.error()
        self.velocity = next_velocity(error, self.velocity, self.vmax, self.amax, self.dt, self.norm, self.scale)
        self.position = self.position + self.velocity * self.dt
        if self._settled():
            if self.target is not None:
                self.position = self.target.copy()
            self.velocity[:] = 0.0
            self.done = True
        return self.done

    def _settled(self) -> bool:
        at_target = self.target is None or float(np.max(np.abs(self.target - self.position))) <= POSITION_EPS
        return at_target and float(np.max(np.abs(self.velocity))) <= VELOCITY_EPS


def next_velocity(error: Vector, velocity: Vector, vmax: Vector, amax: Vector, dt: float, norm: GroupNorm, cap: float = 1.0) -> Vector:
    """One cycle of the braking-curve law (see the module docstring).

    The error is measured in units of its largest component: its sizes against the limits then
    lie between the limits' reciprocals, whatever the error's magnitude.  Measured as it is, a
    subnormal remainder (a target like 1e-300 rad on one axis, the others landed exactly) had a
    size whose reciprocal overflowed to inf; ``0 * inf`` made the set point NaN, the controller
    refused every reply, and RSI stopped after 100 late packets.
    ``cap`` (the speed override, 0..1) caps the speed at that share of ``vmax``, reached within ``amax`` like any
    change and along the same direction, so a move keeps its line; 0 brakes it to rest there, its target kept.
    """
    scale = float(np.max(np.abs(error)))
    if scale > 0.0:
        # Move along ``unit``: lam = scale is the whole remaining distance.  lam' may not exceed
        # 1 / size_v (speed limit) and the braking speed at deceleration 1 / size_a.
        unit = error / scale
        size_v, size_a = norm(unit, vmax), norm(unit, amax)
        wanted = unit * min(cap / size_v, braking_speed(scale, 1.0 / size_a, dt))
    else:
        wanted = np.zeros_like(velocity)
    change = wanted - velocity
    needed = norm(change, amax) / dt  # in multiples of the allowed change per cycle
    if needed > 1.0:
        change = change / needed
    return velocity + change


# ------------------------------------------------------------------------------- rotations
def rotvec_to_matrix(v: Vector) -> Matrix:
    """Rodrigues: the rotation by ``|v|`` about ``v``."""
    angle = math.sqrt(float(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
    if angle < 1e-12:
        return np.eye(3)
    x, y, z = (float(c) / angle for c in v)
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array(
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    )


def matrix_to_rotvec(r: Matrix) -> Vector:
    """The rotation vector (axis * angle, angle in [0, pi]) of a rotation matrix."""
    angle = rotation_angle(r)
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]], dtype=float)
    if angle < 1e-7:
        return skew / 2.0
    if angle > math.pi - 1e-4:
        # Near a half turn the skew part vanishes; the symmetric part is cos(a) I + (1 - cos(a)) k k^T,
        # so k is the dominant column of (sym - cos(a) I) / (1 - cos(a)).  (R + I) / 2 alone keeps
        # sin(a)/2 of the skew part: an axis error of (pi - a)/2.
        c = math.cos(angle)
        outer = ((np.asarray(r, dtype=float) + np.asarray(r, dtype=float).T) / 2.0 - c * np.eye(3)) / (1.0 - c)
        k = int(np.argmax(np.diag(outer)))
        axis = outer[:, k] / math.sqrt(max(float(outer[k, k]), 1e-12))
        if float(np.dot(axis, skew)) < 0:
            axis = -axis
        return axis / np.linalg.norm(axis) * angle
    return skew * (angle / (2.0 * math.sin(angle)))


class CartesianOTG:
    """Second-order generator for a pose: translation (m) and orientation, one synchronised law.

    The orientation error is the rotation vector from the current orientation to the target,
    in the base frame; the angular velocity integrates on the rotation group, so orientations
    stay orthonormal and a move from rest follows the geodesic (slerp) exactly.
    """

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.norm = GroupNorm((3, 3))
        self.position = np.zeros(3)
        self.rotation = np.eye(3)
        self.velocity = np.zeros(6)  # linear (m/s), angular (rad/s), base frame
        self.target_position: Vector | None = None
        self.target_rotation: Matrix | None = None
        self.vmax = np.ones(2)
        self.amax = np.ones(2)
        self.scale = 1.0  # the speed override (VectorOTG.scale)
        self.done = True

    def reset(self, position: Sequence[float] | Vector, rotation: Matrix, velocity: Sequence[float] | Vector | None = None) -> None:
        self.position = np.array(position, dtype=float)
        self.rotation = np.array(rotation, dtype=float)
        self.velocity = np.zeros(6) if velocity is None else np.array(velocity, dtype=float)
        self.target_position = self.target_rotation = None
        self.done = not np.any(self.velocity)

    def set_target(self, position: Sequence[float] | Vector, rotation: Matrix, limits: tuple[float, float, float, float]) -> None:
        """``limits``: linear speed (m/s), linear acceleration (m/s^2), angular speed, angular acceleration."""
        speed, accel, ang_speed, ang_accel = limits
        values = np.array([speed, ang_speed, accel, ang_accel], dtype=float)
        if not (np.all(values > 0) and np.all(np.isfinite(values))):
            raise ValueError(f"speed and acceleration limits must be finite and > 0, got {limits}")
        self.vmax = np.array([speed, ang_speed])
        self.amax = np.array([accel, ang_accel])
        self.target_position = np.array(position, dtype=float)
        self.target_rotation = np.array(rotation, dtype=float)
        self.done = False

    def halt(self) -> None:
        self.target_position = self.target_rotation = None
        self.done = not np.any(self.velocity)

    def resync(self, position: Sequence[float] | Vector, rotation: Matrix, velocity: Sequence[float] | Vector | None = None) -> None:
        """Go on from this pose at ``velocity`` (linear, angular; rest unless given) toward the same target."""
        self.position = np.array(position, dtype=float)
        self.rotation = np.array(rotation, dtype=float)
        self.velocity = np.zeros(6) if velocity is None else np.array(velocity, dtype=float)
        self.done = self.target_position is None and not np.any(self.velocity)

    def error(self) -> Vector:
        if self.target_position is None or self.target_rotation is None:
            return np.zeros(6)
        return np.concatenate(
            (self.target_position - self.position, matrix_to_rotvec(self.target_rotation @ self.rotation.T))
        )

    def step(self) -> bool:
        if self.done:
            return True
        error = self.error()
        self.velocity = next_velocity(error, self.velocity, self.vmax, self.amax, self.dt, self.norm, self.scale)
        self.position = self.position + self.velocity[:3] * self.dt
        self.rotation = rotvec_to_matrix(self.velocity[3:] * self.dt) @ self.rotation
        if float(np.max(np.abs(self.velocity))) <= VELOCITY_EPS and float(np.max(np.abs(self.error()))) <= POSITION_EPS:
            if self.target_position is not None and self.target_rotation is not None:
                self.position = self.target_position.copy()
                self.rotation = self.target_rotation.copy()
            self.velocity[:] = 0.0
            self.done = True
        return self.done
