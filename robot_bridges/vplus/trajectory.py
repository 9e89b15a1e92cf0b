"""Recorded trajectories on AdeptServer: planned on the Viper's kinematics, replayed as a chain of JMOVEs.

AdeptServer has no timed-trajectory skill and no straight-line one (its ``MOVE`` is joint
interpolated).  What it has is ``move_joints`` -- a ``JMOVE`` -- so a trajectory is replayed as
one ``JMOVE`` from stored sample to stored sample: a straight line in joint space each, the very
chord any joint-interpolating replay runs.  A ``linear`` recording sampled by
:mod:`core_functions.linear_path` therefore keeps its tolerance here too, which makes a recorded
linear path the way to get a straight TCP line out of AdeptServer.

Two things are particular to V+:

* Joints travel in degrees with three decimals.  The recording rounds every sample the same way
  *before* checking the chords, so the tolerance holds for the joints the controller really
  receives (the rounding alone moves the TCP by up to ~0.02 mm; a tolerance finer than that is
  refused as one the line cannot keep).
* ``SPEED`` lasts one motion and every ``JMOVE`` stops at its end (no blending in the simulator;
  a real controller blends only with ``CP`` on).  Each segment is sent with the speed at which
  its limiting joint cruises at the segment's recorded mean speed, so no segment is faster than
  the recording (scaled by the set speed); the stops make the replay somewhat slower than the
  recorded times.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.linear_path import (
    LineSamplingError,
    LineTolerance,
    NoSolution,
    SamplingBounds,
    StraightLine,
    plan_line,
)
from core_functions.motion_profile import TcpLimits, joint_profile, sample_times
from core_functions.primitives import ExecuteTrajectory, RecordTrajectory, TrajectoryResult, describe
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.vplus import codec
from robot_bridges.vplus.codec import Command
from robot_bridges.vplus.kinematics import IKError, ViperKinematics

Vector = NDArray[np.float64]

#: s to full joint speed at 100 %: the acceleration the simulated controller uses (``SimulatedArm.ramp``).
JOINT_RAMP = 0.2
_MIN_PERCENT = 0.001  # the smallest speed the wire can say (three decimals)


def on_the_wire(q: Vector) -> Vector:
    """``q`` (rad) as the controller receives it: degrees written with three decimals, read back."""
    return np.radians([float(codec.format_number(d)) for d in np.degrees(np.asarray(q, dtype=float))])


@dataclass(frozen=True)
class TrajectoryPlanner:
    """Plans recordings for one Viper: its kinematics, TCP limits and line sampling."""

    kin: ViperKinematics
    tcp: TcpLimits = TcpLimits()
    sampling: SamplingBounds = SamplingBounds()
    ramp: float = JOINT_RAMP

    @property
    def acceleration(self) -> Vector:
        return self.kin.max_velocity / self.ramp

    def forward(self, q: Vector) -> Pose:
        return Pose.from_matrix(self.kin.forward(q))

    def record(self, label: str, start: Vector, primitive: RecordTrajectory) -> TrajectoryResult:
        """Joint samples through ``primitive.waypoints`` from ``start``, timed at full speed.

        ``ptp`` legs are ``JMOVE``-like synchronised trapezoids sampled every ``sample_period``;
        ``linear`` legs are the samples of their straight line (:func:`plan_line`), each reached
        at the instant the leg's profile gets there.  Raises ``BridgeError`` UNREACHABLE /
        JOINT_LIMIT before anything moves.
        """
        q = on_the_wire(start)
        times: list[float] = [0.0]
        points: list[Vector] = [q]
        tolerance = LineTolerance(primitive.tolerance, primitive.angle_tolerance)
        for k, waypoint in enumerate(primitive.waypoints):
            what = f"{label}: {describe(primitive)}, waypoint {k} ({waypoint})"
            if primitive.interpolation == "linear":
                local, leg = self._line(what, q, waypoint, tolerance)
            else:
                local, leg = self._joint_leg(what, q, waypoint, primitive.sample_period)
            times.extend(times[-1] + local[1:])
            points.extend(leg[1:])
            q = points[-1]
        names = self.kin.joint_names
        return TrajectoryResult(names, tuple(tuple(map(float, p)) for p in points), tuple(map(float, times)))

    def _line(self, what: str, q: Vector, target: Pose, tolerance: LineTolerance) -> tuple[Vector, Vector]:
        line = StraightLine(self.forward(q), target)

        def solve(goal: Pose, seed: Vector) -> Vector:
            try:
                return on_the_wire(self.kin.inverse(goal.matrix(), seed))
            except IKError as error:
                raise NoSolution(str(error)) from None

        velocity, acceleration = self.kin.max_velocity, self.acceleration
        try:
            timed = plan_line(line, q, solve, self.forward, self.tcp, velocity, acceleration, 1.0, tolerance, self.sampling, self.kin.joint_names)
        except LineSamplingError as error:
            raise BridgeError(FaultKind.UNREACHABLE, f"{what}: straight line: {error}") from None
        return timed.times, timed.samples.joints

    def _joint_leg(self, what: str, q: Vector, target: Pose, period: float) -> tuple[Vector, Vector]:
        try:
            goal = on_the_wire(self.kin.inverse(target.matrix(), q))
        except IKError as error:
            kind = FaultKind.JOINT_LIMIT if error.reason == "joint_limit" else FaultKind.UNREACHABLE
            raise BridgeError(kind, f"{what}: {error}") from None
        profile = joint_profile(q, goal, self.kin.max_velocity, self.acceleration, 1.0)
        local = sample_times(profile.duration, period)
        return local, np.array([q + (goal - q) * profile.position(float(t)) for t in local])


@dataclass(frozen=True)
class Replay:
    """What a replay sends -- ``[set_speed,] move_joints`` per segment, then ``break`` -- and how long it may take."""

    commands: tuple[Command, ...]
    goal: Vector
    estimate: float  # s, an upper estimate of the motion time


def plan_replay(kin: ViperKinematics, label: str, primitive: ExecuteTrajectory, speed_percent: float, ramp: float = JOINT_RAMP) -> Replay:
    """The ``JMOVE`` chain of ``primitive``: first to its first point at the set speed, then sample to sample.

    Each segment's speed is the one at which its limiting joint cruises at the recorded mean
    speed (times scaled by the set speed), so the replay is never faster than the recording.
    Raises ``BridgeError`` JOINT_LIMIT for a point beyond a joint's range or a segment faster
    than a joint can go, UNSUPPORTED for joints other than the arm's.
    """
    points = _in_arm_order(kin, label, primitive)
    for k, point in enumerate(points):
        violations = kin.limit_violations(point)
        if violations:
            raise BridgeError(FaultKind.JOINT_LIMIT, f"{label}: point {k} of trajectory {primitive.name!r}: " + "; ".join(violations))
    fraction = speed_percent / 100.0
    times = (np.asarray(primitive.times, dtype=float) - primitive.times[0]) / fraction
    commands: list[Command] = [] if speed_percent == 100.0 else [codec.set_speed(speed_percent)]
    commands.extend(codec.move_joints(np.degrees(points[0]), brk=False))
    estimate = ramp
    for k in range(1, len(points)):
        step = np.abs(points[k] - points[k - 1])
        if float(np.max(step)) <= 1e-9:
            continue  # a hold: nothing to move (a JMOVE stops anyway)
        span = float(times[k] - times[k - 1])
        needed = step / span if span > 0.0 else np.full(step.shape, math.inf)
        share = float(np.max(needed / kin.max_velocity))  # of full speed
        if share > 1.0 + 1e-6:
            j = int(np.argmax(needed / kin.max_velocity))
            raise BridgeError(
                FaultKind.JOINT_LIMIT,
                f"{label}: trajectory {primitive.name!r}: {kin.joint_names[j]} would move at {needed[j]:.3f} rad/s between "
                f"points {k - 1} and {k} (at speed {speed_percent:g} %), above its limit {kin.max_velocity[j]:.3f} rad/s",
            )
        percent = min(100.0, max(_MIN_PERCENT, math.floor(share * 100.0 * 1000.0) / 1000.0))
        if percent != 100.0:
            commands.append(codec.set_speed(percent))
        commands.extend(codec.move_joints(np.degrees(points[k]), brk=False))
        estimate += float(np.max(step / (kin.max_velocity * percent / 100.0))) + ramp
    commands.append(codec.BREAK)
    return Replay(tuple(commands), points[-1], estimate)


def _in_arm_order(kin: ViperKinematics, label: str, primitive: ExecuteTrajectory) -> Sequence[Vector]:
    names = tuple(primitive.joint_names)
    if sorted(names) != sorted(kin.joint_names):
        raise BridgeError(
            FaultKind.UNSUPPORTED, f"{label}: trajectory {primitive.name!r} is for joints {list(names)}, not {list(kin.joint_names)}"
        )
    order = [names.index(n) for n in kin.joint_names]
    return [np.asarray(p, dtype=float)[order] for p in primitive.points]
