"""Planned recordings on the KUKA back end: joint samples a replay at the RSI cycle keeps to.

A recorded trajectory is a list of joint samples with times; the back end replays it by joint
interpolation at the RSI cycle (:func:`.streaming.resample_path`), so between two samples the TCP
follows the forward kinematics of a joint-space chord.  A ``linear`` leg therefore cannot be kept
as the Cartesian generator's pose every ``sample_period``: the chords between such samples bow
away from the line (0.3 mm and more on a 0.1 m sweep).  Each straight leg is instead sampled where
the line needs it (:func:`core_functions.linear_path.plan_line`: Cartesian bisection until every
chord is within the recording's tolerance), timed by the trapezoid the Nextage simulator and V+
use, and stored with every one of those samples at the instant the profile reaches it -- plus a
sample every ``sample_period`` on the chords, so no gap is longer.  ``ptp`` legs run the loop's own
joint generator offline and keep its state every ``sample_period`` and at the waypoint, as before.

Planning runs on the application's thread and touches nothing of the robot: a failed recording
(out of reach, a singularity on the line, a tolerance finer than the kinematics) moved nothing.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.linear_path import LineSamplingError, LineTolerance, NoSolution, StraightLine, TimedLine, plan_line
from core_functions.motion_profile import TcpLimits, sample_times
from core_functions.primitives import RecordTrajectory, TrajectoryResult
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.otg import VectorOTG

Vector = NDArray[np.float64]


@dataclass(frozen=True)
class RecordingPlanner:
    """Plans ``RecordTrajectory(mode="plan")`` for one KUKA arm at full speed (a replay scales time)."""

    arm: KukaArm
    joint_names: tuple[str, ...]
    velocity: Vector  # rad/s per axis
    joint_accel: float  # rad/s^2: ptp legs and the joint bound of straight legs
    tcp: TcpLimits  # straight legs
    dt: float  # s: the RSI cycle, the step of the joint generator

    def plan(self, label: str, start: Vector, primitive: RecordTrajectory) -> TrajectoryResult:
        """Joint samples from ``start`` through the waypoints; raises ``BridgeError`` UNREACHABLE."""
        q = np.asarray(start, dtype=float)
        times: list[float] = [0.0]
        points: list[Vector] = [q]
        tolerance = LineTolerance(primitive.tolerance, primitive.angle_tolerance)
        for k, waypoint in enumerate(primitive.waypoints):
            goal = self.arm.ik(waypoint.matrix(), q)
            if goal is None:
                raise BridgeError(FaultKind.UNREACHABLE, f"{label}: waypoint {waypoint} of {primitive.name!r} is out of reach")
            if primitive.interpolation == "linear":
                local, leg = self._straight(label, primitive.name, k, q, waypoint, tolerance, primitive.sample_period)
            else:
                local, leg = self._ptp(q, goal, primitive.sample_period)
            times.extend(times[-1] + local[1:])
            points.extend(leg[1:])
            q = points[-1]
        return TrajectoryResult(self.joint_names, tuple(tuple(map(float, p)) for p in points), tuple(map(float, times)))

    # ------------------------------------------------------------------------------ legs
    def _forward(self, q: Vector) -> Pose:
        return Pose.from_matrix(self.arm.fk(q))

    def _solve(self, pose: Pose, seed: Vector) -> Vector:
        q = self.arm.ik(pose.matrix(), seed)
        if q is None:
            raise NoSolution(f"no IK solution within the joint limits for {pose}")
        return q

    def _straight(
        self, label: str, name: str, k: int, q: Vector, waypoint: Pose, tolerance: LineTolerance, period: float
    ) -> tuple[Vector, NDArray[np.float64]]:
        """The leg's line samples at the instants its profile reaches them, and one every ``period``."""
        line = StraightLine(self._forward(q), waypoint)
        try:
            timed = plan_line(
                line, q, self._solve, self._forward, self.tcp, self.velocity, np.broadcast_to(self.joint_accel, len(q)), 1.0,
                tolerance, joint_names=self.joint_names,
            )
        except LineSamplingError as error:
            raise BridgeError(FaultKind.UNREACHABLE, f"{label}: the straight line of {name!r} to waypoint {k} ({waypoint}): {error}") from None
        return _on_chords(timed, period)

    def _ptp(self, start: Vector, goal: Vector, period: float) -> tuple[Vector, NDArray[np.float64]]:
        """The joint generator's states, cycle by cycle, kept every ``period`` and at the end."""
        otg = VectorOTG([1] * 6, self.dt)
        otg.reset(start)
        otg.set_target(goal, self.velocity, self.joint_accel)
        states = [start.copy()]
        while not otg.step():
            states.append(otg.position.copy())
        states.append(otg.position.copy())
        step = max(1, round(period / self.dt))
        kept = list(range(0, len(states), step))
        if kept[-1] != len(states) - 1:
            kept.append(len(states) - 1)
        return np.array(kept, dtype=float) * self.dt, np.array([states[i] for i in kept])


def _on_chords(timed: TimedLine, period: float) -> tuple[Vector, NDArray[np.float64]]:
    """Every line sample at its instant, plus instants every ``period`` placed on the chords between them."""
    profile = timed.profile
    fractions, joints = timed.samples.fractions, timed.samples.joints
    if profile.duration <= 0.0:
        return np.zeros(1), joints[:1]  # the waypoint is where the leg starts: nothing to record
    instants = sample_times(profile.duration, period, timed.times)
    s = np.array([profile.position(float(t)) for t in instants])
    return instants, chord_points(fractions, joints, s)


def chord_points(fractions: Vector, joints: NDArray[np.float64], s: Sequence[float] | Vector) -> NDArray[np.float64]:
    """The joints at line fractions ``s``, linear between the samples (on their chords)."""
    s = np.clip(np.asarray(s, dtype=float), fractions[0], fractions[-1])
    k = np.clip(np.searchsorted(fractions, s, side="right") - 1, 0, len(fractions) - 2)
    span = fractions[k + 1] - fractions[k]
    w = np.where(span > 0.0, (s - fractions[k]) / np.where(span > 0.0, span, 1.0), 1.0)
    out: NDArray[np.float64] = joints[k] + (joints[k + 1] - joints[k]) * w[:, None]
    return out

