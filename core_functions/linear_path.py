"""Straight TCP lines as joint samples that a joint-interpolating replay keeps to, within a tolerance.

Why this exists: a recorded trajectory is a list of joint samples, and every replay -- the Nextage
simulator's, a V+ ``JMOVE`` from sample to sample, KUKA RSI's resampling -- moves the joints
*linearly* between two samples.  Between samples the TCP therefore follows forward kinematics of
a joint-space chord, which bows away from the straight line the samples lie on (up to 0.32 mm
for 0.1 s samples of a 0.25 m/s line on the Nextage, more at longer spans).  Samples taken at a
fixed period cannot promise anything; samples taken where the line needs them can -- provided
the recording stores every one of them (:func:`core_functions.motion_profile.sample_times`).

:func:`sample_line` places them by bisection in Cartesian space: an interval whose chord, checked
at its quarter points by forward kinematics, strays from the line by more than the tolerance is
split at its middle, whose joints come from inverse kinematics seeded by the chord's middle.  The
recursion depth and the sample count are bounded; where bisection cannot get within tolerance --
a singularity, a change of configuration, the edge of the workspace, a tolerance below what the
IK achieves -- the line fails with :class:`LineSamplingError` saying where, instead of being
recorded as something it is not.

Pure geometry on :class:`~core_functions.geometry.Pose` and numpy: the robot enters only through
the ``solve`` and ``forward`` callbacks, so every back end uses the same sampling.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.motion_profile import TcpLimits, Trapezoid, path_profile

Vector = NDArray[np.float64]
Solve = Callable[[Pose, Vector], Vector]  # (target, seed joints) -> joints, or raises NoSolution
Forward = Callable[[Vector], Pose]  # joints -> TCP pose, in the frame of the line

_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
_SEARCH_RESOLUTION = 1e-7  # fraction of the line: where the nearest admissible pose is looked for


@dataclass(frozen=True)
class LineTolerance:
    """How far an executed pose may be from the commanded line: position (m) and orientation (rad).

    A pose is within tolerance when one pose of the line is within ``position`` of its position
    *and* within ``orientation`` of its orientation -- position off the segment and orientation
    off the interpolated orientation at that same place of the line.
    """

    position: float = 1e-4  # m: 0.1 mm
    orientation: float = math.radians(0.1)  # rad: 0.1 deg

    def __post_init__(self) -> None:
        for name, value in (("position", self.position), ("orientation", self.orientation)):
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"line tolerance {name} must be a positive finite number, got {value!r}")


@dataclass(frozen=True)
class Deviation:
    """How far a pose is from a line: at the line's pose (``fraction``) that is nearest in tolerance units."""

    position: float  # m
    orientation: float  # rad
    fraction: float
    ratio: float  # max(position / tolerance.position, orientation / tolerance.orientation); <= 1 is within


def interpolate_pose(start: Pose, end: Pose, s: float) -> Pose:
    """Position lerp and orientation slerp (the shorter way) at fraction ``s``: the straight line."""
    return StraightLine(start, end).at(s)


def quaternion_angle(a: Vector, b: Vector) -> float:
    """Rotation angle (rad) between unit quaternions ``a`` and ``b``, accurate for tiny angles too.

    ``4 atan2(|a - b|, |a + b|)`` (with ``b``'s sign chosen nearest ``a``) keeps its digits where
    ``2 acos(a . b)`` loses them -- tolerances here are a fraction of a degree.
    """
    if float(a @ b) < 0.0:
        b = -b
    return 4.0 * math.atan2(float(np.linalg.norm(a - b)), float(np.linalg.norm(a + b)))


def _angle_between(a: Sequence[float], b: Sequence[float]) -> float:
    """:func:`quaternion_angle` on four floats each."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    if a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 < 0.0:
        b0, b1, b2, b3 = -b0, -b1, -b2, -b3
    d0, d1, d2, d3 = a0 - b0, a1 - b1, a2 - b2, a3 - b3
    s0, s1, s2, s3 = a0 + b0, a1 + b1, a2 + b2, a3 + b3
    return 4.0 * math.atan2(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3), math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3))


class StraightLine:
    """The straight TCP line from ``start`` to ``end``: where it is at s, and how far a pose is from it."""

    def __init__(self, start: Pose, end: Pose) -> None:
        self.start = start
        self.end = end
        self._p0 = np.array(start.position)
        self._dp = np.array(end.position) - self._p0
        q0 = np.array(start.quaternion)
        q1 = np.array(end.quaternion)
        if float(q0 @ q1) < 0.0:
            q1 = -q1
        self._q0, self._q1 = q0, q1
        self.length = float(np.linalg.norm(self._dp))
        self.angle = quaternion_angle(q0, q1)  # rotation from start to end
        self._half = self.angle / 2.0  # angle between the two 4-vectors
        if self._half > 1e-9:  # an orthonormal basis of the plane the slerp arc lies in
            self._e2 = q1 - float(q0 @ q1) * q0
            self._e2 /= np.linalg.norm(self._e2)
        self._p0_floats = tuple(map(float, self._p0))
        self._dp_floats = tuple(map(float, self._dp))
        self._q0_floats, self._q1_floats = tuple(map(float, q0)), tuple(map(float, q1))
        self._e2_floats = tuple(map(float, self._e2)) if self._half > 1e-9 else (0.0, 0.0, 0.0, 0.0)

    def position_at(self, s: float) -> Vector:
        return self._p0 + self._dp * s

    def quaternion_at(self, s: float) -> Vector:
        if self._half <= 1e-9:
            q = self._q0 + (self._q1 - self._q0) * s
            return q / np.linalg.norm(q)
        return math.cos(s * self._half) * self._q0 + math.sin(s * self._half) * self._e2

    def _quaternion_floats(self, s: float) -> tuple[float, float, float, float]:
        """:meth:`quaternion_at` on floats (the same operations, element by element)."""
        if self._half <= 1e-9:
            a, b = self._q0_floats, self._q1_floats
            w0, w1, w2, w3 = (a[k] + (b[k] - a[k]) * s for k in range(4))
            n = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2 + w3 * w3)
            return w0 / n, w1 / n, w2 / n, w3 / n
        c, n = math.cos(s * self._half), math.sin(s * self._half)
        a, e = self._q0_floats, self._e2_floats
        return c * a[0] + n * e[0], c * a[1] + n * e[1], c * a[2] + n * e[2], c * a[3] + n * e[3]

    def at(self, s: float) -> Pose:
        p, q = self.position_at(s), self.quaternion_at(s)
        return Pose(float(p[0]), float(p[1]), float(p[2]), float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    def deviation(self, pose: Pose, tolerance: LineTolerance, enough: float = 0.0) -> Deviation:
        """The pose of the line nearest ``pose`` in units of ``tolerance``, and how far that is.

        Minimises ``max(position error / tolerance, orientation error / tolerance)`` over the
        line.  Both errors are unimodal in s (a distance to a point moving on a segment, and on a
        geodesic), so their maximum is too, and its minimum lies between the fraction nearest in
        position and the one nearest in orientation: a golden-section search between the two.
        The search is skipped once a pose of the line within ``enough`` (tolerance units) is
        known, so a caller that only asks "within?" pays for two evaluations, not thirty.
        """
        p = np.array(pose.position)
        q = np.array(pose.quaternion)
        px, py, pz = pose.position
        q4 = pose.quaternion
        (x0, y0, z0), (dx, dy, dz) = self._p0_floats, self._dp_floats

        def measure(s: float) -> Deviation:  # the hot loop: floats, not 3-element arrays (a tenth of the time)
            ex, ey, ez = px - (x0 + dx * s), py - (y0 + dy * s), pz - (z0 + dz * s)
            dp = math.sqrt(ex * ex + ey * ey + ez * ez)
            da = _angle_between(q4, self._quaternion_floats(s))
            return Deviation(dp, da, s, max(dp / tolerance.position, da / tolerance.orientation))

        by_position, by_orientation = measure(self._nearest_in_position(p)), measure(self._nearest_in_orientation(q))
        lo, hi = sorted((by_position.fraction, by_orientation.fraction))
        best = min(by_position, by_orientation, key=lambda d: d.ratio)
        if hi - lo <= _SEARCH_RESOLUTION or best.ratio <= enough:
            return best
        a, b = hi - _GOLDEN * (hi - lo), lo + _GOLDEN * (hi - lo)
        da, db = measure(a), measure(b)
        while hi - lo > _SEARCH_RESOLUTION:
            if da.ratio <= db.ratio:
                hi, b, db = b, a, da
                a = hi - _GOLDEN * (hi - lo)
                da = measure(a)
            else:
                lo, a, da = a, b, db
                b = lo + _GOLDEN * (hi - lo)
                db = measure(b)
        return min(best, da, db, key=lambda d: d.ratio)

    def _nearest_in_position(self, p: Vector) -> float:
        if self.length <= 1e-12:
            return 0.0
        return min(1.0, max(0.0, float((p - self._p0) @ self._dp) / (self.length * self.length)))

    def _nearest_in_orientation(self, q: Vector) -> float:
        """The fraction of the slerp arc nearest ``q``: its projection on the arc's plane in R^4."""
        if self._half <= 1e-9:
            return 0.0
        best, best_cos = 0.0, -1.0
        for sign in (1.0, -1.0):  # q and -q are the same rotation
            phi = math.atan2(sign * float(q @ self._e2), sign * float(q @ self._q0))
            s = min(1.0, max(0.0, phi / self._half))
            cos = abs(float(q @ self.quaternion_at(s)))
            if cos > best_cos:
                best, best_cos = s, cos
        return best


# ------------------------------------------------------------------------------ sampling
@dataclass(frozen=True)
class SamplingBounds:
    """How a line is sampled, and how hard the sampling may try before it gives up.

    The first samples, ``step`` / ``angle_step`` apart, are solved each from the one before, so
    the arm keeps its configuration along the line; bisection then adds samples where the chord
    strays.  A chord is accepted when each check (fractions of the chord) is within ``margin``
    times the tolerance: the bow of a short chord is nearly a parabola, so the largest deviation
    between its quarter points exceeds the largest one measured by a few percent at most, and the
    margin covers that.  The check at 1.0 is the new sample itself, which a solver may place off
    the line by its own residual (or a controller's rounding of the joints).  A chord over which
    a joint turns more than ``max_joint_step`` is split whatever it looks like (it could hide a
    turn of the wrist).  ``max_depth`` bisections of one first interval (20 mm / 2^12 = 5 um)
    and ``max_samples`` per line bound the work; where the line leaves the workspace is located
    to ``2^-locate`` of a first interval.
    """

    step: float = 0.02  # m
    angle_step: float = math.radians(5.0)  # rad
    max_joint_step: float = 0.25  # rad
    max_depth: int = 12
    max_samples: int = 4000
    locate: int = 6
    checks: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0)
    margin: float = 0.9


class NoSolution(Exception):
    """What a ``solve`` callback raises when a pose has no joint solution (the message says why)."""


class LineSamplingError(ValueError):
    """The line cannot be sampled within tolerance; ``fraction`` says where along it."""

    def __init__(self, fraction: float, message: str) -> None:
        super().__init__(message)
        self.fraction = fraction


@dataclass(frozen=True)
class LineSamples:
    """Joint samples ``joints[k]`` at ``fractions[k]`` of the line, the first one the start joints."""

    fractions: Vector
    joints: NDArray[np.float64]
    worst: Deviation  # the largest deviation measured on an accepted chord (an upper bound: see ``deviation``)


def sample_line(
    line: StraightLine,
    start_joints: Vector,
    solve: Solve,
    forward: Forward,
    tolerance: LineTolerance = LineTolerance(),
    bounds: SamplingBounds = SamplingBounds(),
    joint_names: Sequence[str] = (),
) -> LineSamples:
    """Joint samples along ``line`` whose joint interpolation stays within ``tolerance`` of it.

    ``start_joints`` must put the TCP at ``line.start``.  Raises :class:`LineSamplingError` when a
    sample has no IK solution, when bisection reaches ``bounds.max_depth`` without bringing a
    chord within tolerance (naming the joint that jumps, if one does), or when the line needs
    more than ``bounds.max_samples`` samples.  ``joint_names`` only make the messages clearer.
    """
    sampler = _Sampler(line, solve, forward, tolerance, bounds, tuple(joint_names))
    return sampler.run(np.asarray(start_joints, dtype=float))


@dataclass(frozen=True)
class TimedLine:
    """A sampled line and the profile that traverses it: what a back end stores or executes."""

    samples: LineSamples
    profile: Trapezoid

    @property
    def times(self) -> Vector:
        """The instant each sample is reached -- a recording stores the samples at these times."""
        return np.array([self.profile.time_at(float(s)) for s in self.samples.fractions])


def plan_line(
    line: StraightLine,
    start_joints: Vector,
    solve: Solve,
    forward: Forward,
    tcp: TcpLimits,
    velocity: Vector,
    acceleration: Vector,
    speed: float = 1.0,
    tolerance: LineTolerance = LineTolerance(),
    bounds: SamplingBounds = SamplingBounds(),
    joint_names: Sequence[str] = (),
) -> TimedLine:
    """:func:`sample_line`, timed by :func:`~core_functions.motion_profile.path_profile`.

    The one call a back end needs for a straight leg: samples within ``tolerance``, and a
    profile under the TCP limits ``tcp`` and the joints' ``velocity`` / ``acceleration`` limits
    (exact for velocity between samples) at speed fraction ``speed``.  A recording stores
    ``joints`` at :attr:`TimedLine.times`; a replay that interpolates joints between them, at any
    control period, stays within the tolerance and the joint speeds.
    """
    samples = sample_line(line, start_joints, solve, forward, tolerance, bounds, joint_names)
    profile = path_profile(samples.fractions, samples.joints, line.length, line.angle, tcp, velocity, acceleration, speed)
    return TimedLine(samples, profile)


class _Sampler:
    def __init__(
        self, line: StraightLine, solve: Solve, forward: Forward, tolerance: LineTolerance, bounds: SamplingBounds, names: tuple[str, ...]
    ) -> None:
        self.line, self.solve, self.forward = line, solve, forward
        self.tolerance, self.bounds, self.names = tolerance, bounds, names
        self.fractions: list[float] = []
        self.joints: list[Vector] = []
        self.worst = Deviation(0.0, 0.0, 0.0, 0.0)

    def run(self, start: Vector) -> LineSamples:
        b = self.bounds
        self.fractions, self.joints = [0.0], [start]
        count = max(1, math.ceil(max(self.line.length / b.step, self.line.angle / b.angle_step)))
        for i in range(1, count + 1):
            sa, qa, sb = self.fractions[-1], self.joints[-1], i / count
            try:
                qb = np.asarray(self.solve(self.line.at(sb), qa), dtype=float)
            except NoSolution as error:
                raise self._exit(sa, qa, sb, error) from None
            self._refine(sa, qa, sb, qb, 0)
        return LineSamples(np.array(self.fractions), np.array(self.joints), self.worst)

    def _solve_at(self, s: float, seed: Vector) -> Vector:
        try:
            return np.asarray(self.solve(self.line.at(s), seed), dtype=float)
        except NoSolution as error:
            raise self._exit(s, seed, s, error) from None

    def _exit(self, sa: float, qa: Vector, sb: float, error: NoSolution) -> LineSamplingError:
        """Where between ``sa`` (solved: ``qa``) and ``sb`` (no solution) the line leaves the workspace."""
        for _ in range(self.bounds.locate if sb > sa else 0):
            sm = 0.5 * (sa + sb)
            try:
                qa, sa = np.asarray(self.solve(self.line.at(sm), qa), dtype=float), sm
            except NoSolution as closer:
                sb, error = sm, closer
        return LineSamplingError(sb, f"the line leaves the reachable workspace at {100 * sb:.1f}% of its length ({error})")

    def _refine(self, sa: float, qa: Vector, sb: float, qb: Vector, depth: int) -> None:
        """Append samples up to ``sb`` so that every chord from ``sa`` on is within tolerance."""
        jump = np.abs(qb - qa)
        worst = self._chord(qa, qb) if float(np.max(jump)) <= self.bounds.max_joint_step else None
        if worst is not None and worst.ratio <= self.bounds.margin:
            self.fractions.append(sb)
            self.joints.append(qb)
            if worst.ratio > self.worst.ratio:
                self.worst = worst
            return
        if depth >= self.bounds.max_depth:
            raise LineSamplingError(sa, self._why(sa, sb, jump, worst))
        if len(self.fractions) >= self.bounds.max_samples:
            raise LineSamplingError(
                sa,
                f"the line needs more than {self.bounds.max_samples} samples to stay within "
                f"{self._tolerance_text()} (reached {100 * sa:.1f}% of its length)",
            )
        sm = 0.5 * (sa + sb)
        qm = self._solve_at(sm, 0.5 * (qa + qb))
        self._refine(sa, qa, sm, qm, depth + 1)
        self._refine(sm, qm, sb, qb, depth + 1)

    def _chord(self, qa: Vector, qb: Vector) -> Deviation:
        margin = self.bounds.margin
        checks = (self.line.deviation(self.forward(qa + (qb - qa) * u), self.tolerance, margin) for u in self.bounds.checks)
        return max(checks, key=lambda d: d.ratio)

    def _why(self, sa: float, sb: float, jump: Vector, worst: Deviation | None) -> str:
        span = self._span_text(sb - sa)
        where = f"near {100 * sa:.1f}% of its length"
        if worst is None or float(np.max(jump)) > self.bounds.max_joint_step:
            k = int(np.argmax(jump))
            name = self.names[k] if k < len(self.names) else f"joint {k}"
            return (
                f"no continuous motion follows the line {where}: {name} would turn {math.degrees(float(jump[k])):.1f} deg "
                f"within {span} of the line (a singularity or a change of configuration on the line)"
            )
        return (
            f"joint interpolation still leaves the line by {worst.position * 1000:.4f} mm / "
            f"{math.degrees(worst.orientation):.4f} deg {where}, between samples {span} apart "
            f"(tolerance {self._tolerance_text()}: a singularity on the line, or a tolerance finer than the IK)"
        )

    def _span_text(self, fraction: float) -> str:
        if self.line.length > 1e-9:
            return f"{fraction * self.line.length * 1000.0:.4f} mm"
        return f"{math.degrees(fraction * self.line.angle):.4f} deg"

    def _tolerance_text(self) -> str:
        return f"{self.tolerance.position * 1000:g} mm / {math.degrees(self.tolerance.orientation):g} deg"
