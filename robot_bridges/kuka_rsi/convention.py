"""Which of the controller's reports the cross-check believes: the set-point convention, found in the first cycles.

RSI does not say what the reported set point (``ASPos``; ``RSol`` for the TCP) shows while corrections run.
A controller may report the set point with the corrections in it -- it *follows* them -- or keep reporting
the set point of the programmed motion, which under RSI_MOVECORR is the pose it started from -- *frozen* at
the start, as ROS-Industrial's ``kuka_rsi_simulator`` does while its actual axes (``AIPos``) follow the
corrections.  kroshu's KSS and iiQKA configurations send no set point at all (*absent*).  Which one a
real KR C4 follows is not settled; the external system must be safe with each:

* **follows**: the reported set point must match the commanded one (:func:`.guard.joint_disagreement`),
  as before;
* **frozen**: the reported set point must stay at the start, and the actual axes (or TCP) must lie among
  the set points commanded over the last :attr:`RobotLink.follow_time` seconds (:func:`.guard.joint_outside_tube`):
  a servo trails its set point, it never leaves the path it was given;
* **absent**: the actual values are checked the same way.

The convention is decided in the first cycles in which the commanded set point has left the start by more
than twice the tolerance -- before that a report may fit both, and the actual values are checked as for a frozen report -- and
reported once.  A report that fits neither is a fault,
as is a frozen report that moves later, or an actual position off the commanded path: the controller does
something it was not told, or says something untrue.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.guard import AXES, describe_joint_fault, joint_disagreement, joint_outside_tube, pose_disagreement, pose_outside_tube

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]


class Convention(Enum):
    """What the controller's reported set point shows under corrections."""

    UNDECIDED = "undecided"  # the commanded set point has not yet left the start: both conventions fit
    FOLLOWS = "follows"  # the set point with the corrections in it
    FROZEN = "frozen"  # the start pose, for ever (ROS-Industrial's kuka_rsi_simulator)
    ABSENT = "absent"  # the configuration sends no set point: the actual values are checked


class ReportCheck:
    """One robot's cross-check of what the controller reports against what the external system commanded.

    ``note(level, text)`` reports the convention once it is decided (a ``logging`` level).
    """

    def __init__(self, tolerance: Vector, tcp_tolerance: tuple[float, float], has_setpoint: bool, window_ms: float, note: Callable[[int, str], None]) -> None:
        self.tolerance = tolerance  # rad, per axis
        self.tcp_tolerance = tcp_tolerance  # m, rad
        self.window_ms = window_ms
        self._note = note
        self.convention = Convention.UNDECIDED if has_setpoint else Convention.ABSENT
        self.start_axes: Vector | None = None
        self.start_pose: Matrix | None = None

    def begin(self, setpoint_axes: Vector | None, setpoint_pose: Matrix | None) -> None:
        """RSI_MOVECORR began: the reports of this moment are the start a frozen report keeps showing."""
        self.start_axes = None if setpoint_axes is None else setpoint_axes.copy()
        self.start_pose = None if setpoint_pose is None else setpoint_pose.copy()

    # ------------------------------------------------------------------------------ joints
    def joints(self, recent: Sequence[Vector], window: Sequence[Vector], setpoint: Vector | None, actual: Vector) -> str | None:
        """None when the reports fit the commanded set points (``recent``: the last ones the report may
        show, newest last; ``window``: those of the last :attr:`window_ms`); else what disagrees."""
        tol = self.tolerance
        if setpoint is not None and self.convention in (Convention.UNDECIDED, Convention.FOLLOWS):
            if self.convention is Convention.FOLLOWS:
                found = joint_disagreement(setpoint, recent, tol)
                return None if found is None else describe_joint_fault(found[0], found[1], setpoint, tol)
            problem = self._decide_joints(recent, setpoint)
            if problem is not None or self.convention is Convention.FOLLOWS:
                return problem
        if setpoint is not None and self.convention is Convention.FROZEN:
            assert self.start_axes is not None
            off = np.abs(setpoint - self.start_axes) > tol
            if off.any():
                i = int(np.argmax(np.abs(setpoint - self.start_axes) / tol))
                return (
                    f"{AXES[i]}: the controller's set point (ASPos) stayed at the start, {math.degrees(float(self.start_axes[i])):.3f} deg, "
                    f"and now reads {math.degrees(float(setpoint[i])):.3f} deg (tolerance {math.degrees(float(tol[i])):.3f} deg); "
                    "the controller changed how it reports its set point"
                )
        outside = joint_outside_tube(actual, window, tol)
        if outside is None:
            return None
        i, low, high = outside
        return (
            f"{AXES[i]}: the actual axis (AIPos) reads {math.degrees(float(actual[i])):.3f} deg, outside the "
            f"{math.degrees(low):.3f}..{math.degrees(high):.3f} deg the commanded set point passed through in the last "
            f"{self.window_ms:g} ms (tolerance {math.degrees(float(tol[i])):.3f} deg); the controller does not follow the set point it was sent"
        )

    def _decide_joints(self, recent: Sequence[Vector], setpoint: Vector) -> str | None:
        assert self.start_axes is not None
        tol = self.tolerance
        follows = joint_disagreement(setpoint, recent, tol) is None
        frozen = bool((np.abs(setpoint - self.start_axes) <= tol).all())
        # The commanded set point has left the start by twice the tolerance: no report can fit both.
        decidable = joint_disagreement(self.start_axes, recent, 2.0 * tol) is not None
        if decidable and follows:
            self._decide(Convention.FOLLOWS, "ASPos")
        elif decidable and frozen:
            self._decide(Convention.FROZEN, "ASPos")
        elif not (follows or frozen):
            i = int(np.argmax(np.minimum(np.abs(setpoint - recent[-1]), np.abs(setpoint - self.start_axes)) / tol))
            return (
                f"{AXES[i]}: the controller reports its set point (ASPos) at {math.degrees(float(setpoint[i])):.3f} deg, neither the "
                f"commanded {math.degrees(float(recent[-1][i])):.3f} deg (a set point following the corrections) nor the start "
                f"{math.degrees(float(self.start_axes[i])):.3f} deg (a set point frozen at the start) (tolerance {math.degrees(float(tol[i])):.3f} deg); "
                "the controller does not hold the set point it was sent"
            )
        return None

    # ------------------------------------------------------------------------------- poses
    def pose(self, recent: Sequence[Matrix], window: Sequence[Matrix], setpoint: Matrix | None, actual: Matrix | None) -> str | None:
        """The same under Cartesian corrections: ``recent`` and ``setpoint`` in the controller's model
        (RSol), ``window`` and ``actual`` in ours (RIst brought into it); None when they fit."""
        tol_m, tol_rad = self.tcp_tolerance
        if setpoint is not None and self.convention in (Convention.UNDECIDED, Convention.FOLLOWS):
            follows = pose_disagreement(setpoint, recent, tol_m, tol_rad)
            if self.convention is Convention.FOLLOWS:
                return None if follows is None else _tcp_fault(recent[-1], setpoint, follows, tol_m, tol_rad)
            assert self.start_pose is not None
            frozen = pose_disagreement(setpoint, [self.start_pose], tol_m, tol_rad) is None
            decidable = pose_disagreement(self.start_pose, recent, 2.0 * tol_m, 2.0 * tol_rad) is not None
            if decidable and follows is None:
                self._decide(Convention.FOLLOWS, "RSol")
                return None
            if decidable and frozen:
                self._decide(Convention.FROZEN, "RSol")
            elif follows is not None and not frozen:
                return _tcp_fault(recent[-1], setpoint, follows, tol_m, tol_rad) + " (nor does it stay at the start: it fits no convention)"
        if setpoint is not None and self.convention is Convention.FROZEN:
            assert self.start_pose is not None
            moved = pose_disagreement(setpoint, [self.start_pose], tol_m, tol_rad)
            if moved is not None:
                return (
                    f"TCP: the controller's set point (RSol) stayed at the start and has now moved {moved[0] * 1000.0:.3f} mm and "
                    f"{math.degrees(moved[1]):.3f} deg from it; the controller changed how it reports its set point"
                )
        if actual is None and self.convention is Convention.UNDECIDED:
            return None  # both conventions still fit, and nothing else to check against
        if actual is None:
            return "TCP: the controller's set point (RSol) stays at the start and it sends no RIst: nothing confirms the Cartesian corrections"
        outside = pose_outside_tube(actual, window, tol_m, tol_rad)
        if outside is None:
            return None
        return (
            f"TCP: the actual TCP (RIst) lies {outside[0] * 1000.0:.3f} mm and {math.degrees(outside[1]):.3f} deg off the path the commanded "
            f"set point took in the last {self.window_ms:g} ms (tolerance {tol_m * 1000.0:g} mm, {math.degrees(tol_rad):g} deg); "
            "the controller does not follow the set point it was sent"
        )

    def _decide(self, convention: Convention, report: str) -> None:
        self.convention = convention
        if convention is Convention.FOLLOWS:
            self._note(20, f"the controller's set point ({report}) follows the corrections: the cross-check compares it with the commanded set point")
        else:
            self._note(
                30,
                f"the controller reports its set point ({report}) frozen at the start pose while the robot follows the corrections "
                "(as ROS-Industrial's kuka_rsi_simulator): the cross-check compares the actual axes (AIPos; RIst for the TCP) "
                "with the set points the bridge commanded",
            )


def _tcp_fault(commanded: Matrix, reported: Matrix, off: tuple[float, float], tol_m: float, tol_rad: float) -> str:
    c = np.round(commanded[:3, 3] * 1000.0, 3).tolist()
    r = np.round(reported[:3, 3] * 1000.0, 3).tolist()
    return (
        f"TCP: commanded {c} mm, the controller reports {r} mm ({off[0] * 1000.0:.3f} mm and "
        f"{math.degrees(off[1]):.3f} deg apart; tolerance {tol_m * 1000.0:g} mm, {math.degrees(tol_rad):g} deg); "
        "the controller does not hold the set point it was sent"
    )
