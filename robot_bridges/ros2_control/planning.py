"""The engine's motions as joint paths, and joint paths as timed trajectories within the robot's limits.

A path is the sequence of joint positions the arm must pass through (the group's joints, in its
order): two points for a joint move, the inverse kinematics of closely spaced poses for a straight
line, the recorded points for a replay.  :func:`time_path` gives it times: a trapezoidal speed
profile along the path at the speed fraction, each joint's speed within its URDF limit times the
fraction and its acceleration within its limit; the result is checked sample by sample and slowed
down where a corner of the path would ask more, so no trajectory sent to a controller exceeds a
limit -- whatever the primitive asked.  :func:`remainder` is what is left of a path from where the
arm really stopped, for a resume that re-plans instead of sending the old trajectory again.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from robot_bridges.backend import BridgeError, FaultKind

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

#: s between the points of a timed trajectory (joint_trajectory_controller interpolates between them).
SAMPLE_PERIOD = 0.05
#: m and rad between the poses of a straight line whose inverse kinematics make its joint path.
LINE_STEP = 0.002
LINE_ANGLE_STEP = math.radians(0.5)
#: the most poses a straight line is cut into (a 4 m line at 2 mm).
MAX_LINE_POSES = 2000
#: rad: more than this between two neighbouring poses' joints is a jump of the IK (another branch, a
#: singularity), not a straight line.
MAX_JOINT_STEP = 0.05
_SLACK = 1e-9
#: rad: a corner sharper than this (between two segments' directions, each joint scaled by its speed) is passed at rest.
CORNER = math.radians(20.0)
#: s: accelerations are judged as the change of velocity over at least this long.
ACCELERATION_WINDOW = 0.01


@dataclass(frozen=True)
class Timed:
    """A trajectory: ``points[k]`` reached at ``times[k]`` s with ``velocities[k]``; the last at rest."""

    times: Vector
    points: Matrix
    velocities: Matrix

    @property
    def duration(self) -> float:
        return float(self.times[-1])


@dataclass(frozen=True)
class Limits:
    """The group's joints' ranges, speeds and accelerations (rad, rad/s, rad/s^2)."""

    names: tuple[str, ...]
    lower: Vector
    upper: Vector
    velocity: Vector
    acceleration: Vector

    def check_positions(self, group: str, points: Matrix, what: str) -> None:
        """JOINT_LIMIT naming the joint when a point of ``points`` lies outside a range."""
        low = points < self.lower - 1e-9
        high = points > self.upper + 1e-9
        if low.any() or high.any():
            k, j = np.argwhere(low | high)[0]
            raise BridgeError(FaultKind.JOINT_LIMIT, f"{group}: {what}: joint {self.names[j]} at {points[k, j]:.4f} rad is outside "
                              f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")


def time_path(path: Matrix, limits: Limits, fraction: float, period: float = SAMPLE_PERIOD) -> Timed:
    """``path`` (n x joints, n >= 1) timed at speed ``fraction`` of the limits, sampled every ``period``.

    The path is played through in one sweep where it bends gently; at a sharper corner (more than
    :data:`CORNER` between the directions of two segments) the arm comes to rest, as a controller does
    between two motions, and a piece that still asks too much at its corners is played point to point."""
    path = np.asarray(path, dtype=float)
    keep = np.concatenate(([True], np.max(np.abs(np.diff(path, axis=0)), axis=1) > 1e-12)) if len(path) > 1 else np.ones(1, bool)
    path = path[keep]
    if len(path) == 1:
        return Timed(np.zeros(1), path.copy(), np.zeros_like(path))
    pieces = []
    for piece in _pieces(path, limits):
        timed = _time_piece(piece, limits, fraction, period)
        pieces += [timed] if timed is not None else [_time_piece(piece[k:k + 2], limits, fraction, period) for k in range(len(piece) - 1)]
    times, points, velocities = [np.zeros(1)], [path[:1]], [np.zeros((1, path.shape[1]))]
    for timed in pieces:
        assert timed is not None  # a straight segment always fits its own trapezoid
        times.append(times[-1][-1] + timed.times[1:])
        points.append(timed.points[1:])
        velocities.append(timed.velocities[1:])
    return Timed(np.concatenate(times), np.vstack(points), np.vstack(velocities))


def _pieces(path: Matrix, limits: Limits) -> list[Matrix]:
    """``path`` cut at its sharp corners (each piece shares its end point with the next)."""
    directions = np.diff(path, axis=0) / limits.velocity
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    turns = np.einsum("ij,ij->i", directions[:-1], directions[1:])
    cuts = [0, *(k + 1 for k, c in enumerate(turns) if c < math.cos(CORNER)), len(path) - 1]
    return [path[a:b + 1] for a, b in zip(cuts, cuts[1:]) if b > a]


def _time_piece(path: Matrix, limits: Limits, fraction: float, period: float) -> Timed | None:
    """One piece in one sweep, from rest to rest; None when its corners ask too much even slowed down."""
    steps = np.max(np.abs(np.diff(path, axis=0)) / limits.velocity, axis=1)
    arc = np.concatenate(([0.0], np.cumsum(steps)))
    # s is "seconds at full speed": moving along s at rate 1 moves the path's leading joint at its limit
    top = fraction
    accel = fraction * float(np.min(limits.acceleration / limits.velocity))
    stretch = 1.0
    for _ in range(12):
        timed = _sample(path, arc, top / stretch, accel / stretch**2, period)
        over = _excess(timed, limits, fraction)
        if over <= 1.0 + 1e-6:
            return timed
        stretch *= over * 1.05
    return None


def _sample(path: Matrix, arc: Vector, top: float, accel: float, period: float) -> Timed:
    total = float(arc[-1])
    ramp = top / accel
    if accel * ramp * ramp >= total:  # never reaches the top speed: a triangle
        ramp = math.sqrt(total / accel)
        top = accel * ramp
        cruise = 0.0
    else:
        cruise = (total - accel * ramp * ramp) / top
    duration = 2 * ramp + cruise
    count = max(1, math.ceil(duration / period - 1e-9))
    times = np.union1d(np.linspace(0.0, duration, count + 1), _times_at(arc[1:-1], accel, top, ramp, cruise, total))
    times = times[np.concatenate(([True], np.diff(times) > 1e-6))]  # every point of the path is a point of the trajectory
    times[-1] = duration
    s = np.empty_like(times)
    sd = np.empty_like(times)
    for k, t in enumerate(times):
        if t < ramp:
            s[k], sd[k] = 0.5 * accel * t * t, accel * t
        elif t < ramp + cruise:
            s[k], sd[k] = 0.5 * accel * ramp * ramp + top * (t - ramp), top
        else:
            left = max(0.0, duration - t)
            s[k], sd[k] = total - 0.5 * accel * left * left, accel * left
    s[-1], sd[-1] = total, 0.0
    segment = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2)
    width = arc[segment + 1] - arc[segment]
    u = np.clip((s - arc[segment]) / width, 0.0, 1.0)[:, None]
    points = path[segment] + u * (path[segment + 1] - path[segment])
    slope = (path[segment + 1] - path[segment]) / width[:, None]
    return Timed(times, points, slope * sd[:, None])


def _times_at(s: Vector, accel: float, top: float, ramp: float, cruise: float, total: float) -> Vector:
    """When the profile passes the arc values ``s`` (the inverse of the trapezoid)."""
    first = 0.5 * accel * ramp * ramp
    return np.where(
        s < first, np.sqrt(2 * np.maximum(s, 0.0) / accel),
        np.where(s < first + top * cruise, ramp + (s - first) / top, 2 * ramp + cruise - np.sqrt(2 * np.maximum(total - s, 0.0) / accel)),
    )


def _excess(timed: Timed, limits: Limits, fraction: float) -> float:
    """How far the sampled trajectory asks more than the limits at ``fraction`` (1: exactly within): the speed of
    every segment between two points, the points' own velocities, and the change of those velocities over at
    least :data:`ACCELERATION_WINDOW` (the controller's interpolation smooths anything shorter)."""
    dt = np.diff(timed.times)
    speeds = np.abs(np.diff(timed.points, axis=0)) / dt[:, None]
    over = float(np.max(speeds / (limits.velocity * fraction))) if len(speeds) else 0.0
    over = max(over, float(np.max(np.abs(timed.velocities) / (limits.velocity * fraction))))
    if len(dt):
        window = np.maximum(dt, ACCELERATION_WINDOW)[:, None]
        accelerations = np.abs(np.diff(timed.velocities, axis=0)) / window
        over = max(over, math.sqrt(float(np.max(accelerations / (limits.acceleration * fraction)))))
    return over


def retime(times: Sequence[float], points: Matrix, limits: Limits, fraction: float) -> Timed:
    """A recorded trajectory at its own times divided by ``fraction``, slowed down uniformly where that
    would exceed a speed or an acceleration; positions only in, velocities by finite differences out."""
    times_v = np.asarray(times, dtype=float) - float(times[0])
    points = np.asarray(points, dtype=float)
    if len(points) == 1 or times_v[-1] <= 0:
        return time_path(points, limits, fraction)
    scaled = times_v / fraction
    for _ in range(8):
        velocities = _velocities(scaled, points)
        timed = Timed(scaled, points, velocities)
        over = _excess(timed, limits, 1.0)
        if over <= 1.0 + 1e-6:
            return timed
        scaled = scaled * over * 1.05
    return time_path(points, limits, fraction)


def _velocities(times: Vector, points: Matrix) -> Matrix:
    """Central differences inside, at rest at both ends."""
    velocities = np.zeros_like(points)
    if len(points) > 2:
        velocities[1:-1] = (points[2:] - points[:-2]) / (times[2:] - times[:-2])[:, None]
    return velocities


def remainder(path: Matrix, measured: Vector, after: int = 0) -> tuple[Matrix, int]:
    """What is left of ``path`` for an arm standing at ``measured``: measured, then every point after
    the one nearest to it (searched from index ``after`` on); and that point's index."""
    path = np.asarray(path, dtype=float)
    distance = np.max(np.abs(path[after:] - measured), axis=1)
    nearest = after + int(np.argmin(distance))
    rest = path[nearest + 1:] if nearest + 1 < len(path) else path[-1:]
    return np.vstack((measured[None, :], rest)), nearest


def line_poses(start: Pose, target: Pose) -> list[Pose]:
    """Poses along the straight line (slerped orientation) from ``start`` to ``target``, start and end included."""
    count = max(1, math.ceil(max(start.distance_to(target) / LINE_STEP, start.angle_to(target) / LINE_ANGLE_STEP)))
    if count > MAX_LINE_POSES:
        raise BridgeError(FaultKind.UNREACHABLE, f"a straight line of {start.distance_to(target):.3f} m is longer than this back end plans "
                          f"({MAX_LINE_POSES * LINE_STEP:.1f} m)")
    a, b = np.array(start.quaternion), np.array(target.quaternion)
    if float(a @ b) < 0:
        b = -b
    poses = []
    for k in range(count + 1):
        u = k / count
        q = _slerp(a, b, u)
        poses.append(Pose(start.x + u * (target.x - start.x), start.y + u * (target.y - start.y), start.z + u * (target.z - start.z), *q))
    return poses


def _slerp(a: Vector, b: Vector, u: float) -> tuple[float, float, float, float]:
    dot = min(1.0, float(a @ b))
    angle = math.acos(dot)
    if angle < 1e-9:
        q = a + u * (b - a)
    else:
        q = (math.sin((1 - u) * angle) * a + math.sin(u * angle) * b) / math.sin(angle)
    q = q / np.linalg.norm(q)
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def line_path(group: str, start: Vector, poses: Sequence[Pose], solve: Callable[[Pose, Vector], Vector], names: Sequence[str]) -> Matrix:
    """The joint path of a straight line: each pose's IK seeded with the previous; UNREACHABLE where the
    joints jump (a singularity or another branch of the arm on the way)."""
    points = [np.asarray(start, dtype=float)]
    for k, pose in enumerate(poses[1:], start=1):
        q = solve(pose, points[-1])
        step = np.abs(q - points[-1])
        if float(np.max(step)) > MAX_JOINT_STEP:
            j = int(np.argmax(step))
            raise BridgeError(FaultKind.UNREACHABLE, f"{group}: the straight line cannot be followed: joint {names[j]} would jump "
                              f"{math.degrees(float(step[j])):.1f} deg at {100.0 * k / (len(poses) - 1):.0f} % of the line "
                              f"(a singularity or the limits on the way); move ptp")
        points.append(q)
    return np.array(points)
