"""One FollowJointTrajectory goal played on one group, through the joint motions its back end already makes safely.

The plan (:mod:`robot_bridges.trajectory_goal`) becomes the back end's own
:class:`~core_functions.primitives.ExecuteTrajectory`, which every back end checks against its limits
again and plays with its own interpolation and supervision (the Nextage simulator's limit and collision
checks every period, the V+ acknowledgements, the KUKA RSI loop's generators and set-point check).
The group's speed fraction is set to 1 first, so the path keeps the goal's own timing -- unless the
operator's speed override scales it down on its path (robot_bridges/path_rate.py), as it does every
motion: the follower's time is then where the arm is on the path, never ahead of the clock.

A back end that holds an arm inside a running motion (:attr:`RobotBackend.holds_within_motion`) gets
the whole path as one motion, and a stop lands on the path wherever the arm is.  One that runs a motion
it was sent to its end (V+ AdeptServer) gets it in legs of at most :data:`LEG_TIME` ending on points
of the path (a segment longer than that is cut by points on it): a stop lets the leg under way end on
its point and sends nothing more.  A leg, once sent,
is never sent again: a failed one ends the goal.

While the path plays, the follower samples the arm every ``period`` s: where the path says it should
be (its own time stands still while the cell holds the motion, :meth:`Follower.hold`), where it is by
the back end's word, and the difference -- the feedback of the action and of the controller's state.
A path tolerance is checked at every sample where the back end reports the arm while it moves, and at
the end of every leg where it reports it only there; the goal tolerances once the path has ended,
for at most the goal time tolerance.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core_functions.primitives import ExecuteTrajectory, SetSpeed
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind, JointLimits, RobotBackend
from robot_bridges.trajectory_goal import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_GOAL,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    FollowPlan,
    Refused,
    continued,
    path_time_near,
)

#: s of path per motion sent to a back end that cannot hold an arm inside a motion.
LEG_TIME = 1.0
_HELD = object()  # a leg's outcome: the cell held the motion, and the arm stopped on its path
_REFUSED_BY_BACKEND = (FaultKind.JOINT_LIMIT, FaultKind.UNSUPPORTED, FaultKind.UNREACHABLE, FaultKind.COLLISION)


@dataclass(frozen=True)
class Sample:
    """Where the path says the group is (``desired``, with its speed), where it is (``actual``), at path time ``t``."""

    t: float
    desired: NDArray[np.float64]
    desired_velocity: NDArray[np.float64]
    actual: NDArray[np.float64]
    actual_velocity: NDArray[np.float64]

    @property
    def error(self) -> NDArray[np.float64]:
        return self.desired - self.actual


def refined(plan: FollowPlan, step: float) -> FollowPlan:
    """The same path with a point at least every ``step`` s: points on its straight segments, where a leg may end."""
    times = [float(plan.times[0])]
    for start, stop in zip(plan.times[:-1], plan.times[1:]):
        pieces = max(1, math.ceil((stop - start) / step - 1e-9))
        times.extend(float(start + (stop - start) * i / pieces) for i in range(1, pieces))
        times.append(float(stop))
    grid = np.array(times)
    points = np.array([plan.at(t)[0] for t in grid[:-1]] + [plan.points[-1]])
    return replace(plan, times=grid, points=points)


def legs(plan: FollowPlan, whole: bool) -> list[tuple[int, int]]:
    """Index ranges ``(first, last)`` of the plan's points, one per motion sent (sharing their ends)."""
    count = len(plan.times)
    if whole or count <= 2:
        return [(0, count - 1)]
    out: list[tuple[int, int]] = []
    first = 0
    for k in range(1, count):
        if k == count - 1 or plan.times[k + 1] - plan.times[first] > LEG_TIME:
            out.append((first, k))
            first = k
    return out


class Follower:
    """Plays one plan on ``group``; :meth:`run` says how it ended as (error code, error string)."""

    def __init__(
        self, backend: RobotBackend, group: str, plan: FollowPlan, limits: JointLimits, clock: Clock, period: float, name: str,
        observe: Callable[[Sample], None],
    ) -> None:
        whole = backend.holds_within_motion
        self.backend, self.group, self.limits, self.clock, self.period, self.name = backend, group, limits, clock, period, name
        self.plan = plan if whole else refined(plan, LEG_TIME)  # a leg may end between two far-apart points
        self.observe = observe
        self.elapsed = 0.0  # s of path time played (stands still while held)
        self.held = False
        self.latest: Sample | None = None
        self._ending: tuple[int, str] | None = None  # why the goal ends early (cancel, preemption, safety stop)
        self._stopping = asyncio.Event()
        self._released = asyncio.Event()
        self._released.set()
        self._index = [backend.joint_state()[0].index(n) for n in plan.joint_names]
        self._last: tuple[float, NDArray[np.float64]] | None = None
        self._held_at = 0.0  # path time when the cell held the motion
        self._leg_end = 0.0  # path time the leg under way ends at
        self._stopped_for_hold = False  # the back end's stop was a hold's: the motion's STOPPED is the hold (however late)
        self.scaled = False  # the speed override has played this goal slower than written: its time is the arm's

    # ----------------------------------------------------------------------------- control
    def end(self, code: int, reason: str) -> None:
        """End the goal early: the arm stops on its path (the back end's stop), nothing more is sent."""
        if self._ending is None:
            self._ending = (code, reason)
        self._stopping.set()
        self._released.set()

    async def stop_backend(self) -> None:
        await self.backend.stop(self.group)

    async def hold(self) -> None:
        """The cell holds the motion (paused): the arm stops on its path (the back end's stop), the path's time
        stands still; :meth:`release` goes on with the rest of the path from where the arm stands (:func:`continued`).
        Stopping rather than pausing the back end's motion: a back end's resume may start its motion over."""
        if self.held or self._ending is not None:
            return
        self.held = self._stopped_for_hold = True
        self._held_at = self.elapsed
        self._released.clear()
        await self.backend.stop(self.group)

    async def release(self) -> None:
        if not self.held:
            return
        self.held = False
        self._released.set()

    # ------------------------------------------------------------------------------- run
    async def run(self) -> tuple[int, str]:
        code, text = await self._play()
        if self._ending is not None and not self.backend.holds_within_motion:
            try:  # the leg under way ends on its point first: the goal ends once the arm stands there, its joints read again
                await self.backend.measure(self.group)
            except BridgeError as error:
                text = f"{text}; where the arm stopped could not be read: {error}"
        return code, text

    async def _play(self) -> tuple[int, str]:
        plan = self.plan
        if plan.start_delay > 0.0 and await self._wait_stopping(plan.start_delay):
            return self._ended()
        try:
            await self.backend.execute(self.group, SetSpeed(1.0))
            while True:
                outcome = await self._legs()
                if outcome is not _HELD:
                    if outcome is not None:
                        return outcome  # type: ignore[return-value]
                    break
                while self.held and self._ending is None:  # stopped on the path: the rest once the cell lets go
                    await self._released.wait()
                if self._ending is not None:
                    return self._ended()
                rest = await self._rest()
                if rest is None:
                    break
                self.plan, self.elapsed = rest, 0.0
        except Refused as refused:
            return refused.code, str(refused)
        except BridgeError as error:
            if self._ending is not None and error.kind is FaultKind.STOPPED:
                return self._ended()
            code = INVALID_GOAL if error.kind in _REFUSED_BY_BACKEND and self.elapsed == 0.0 else PATH_TOLERANCE_VIOLATED
            return code, f"{self.group}: the robot did not follow the path at {self.elapsed:.3f} s: {error}"
        if self._ending is not None:
            return self._ended()
        return await self._settle()

    async def _legs(self) -> tuple[int, str] | object | None:
        """Play the plan leg by leg: None when it has all been played, an outcome, or ``_HELD``."""
        for first, last in legs(self.plan, self.backend.holds_within_motion):
            while self.held and self._ending is None:
                await self._released.wait()
            if self._ending is not None:
                return self._ended()
            outcome = await self._leg(first, last)
            if outcome is not None:
                return outcome
        return None

    async def _rest(self) -> FollowPlan | None:
        """The rest of the path after a hold, from where the arm stands by the robot's word."""
        measured = await self.backend.measure(self.group)
        where = dict(zip(measured.joint_names, measured.positions))
        here = np.array([where[n] for n in self.plan.joint_names])
        # near where the path's time stood: the arm stopped within a braking distance of it, or (V+) at the end of
        # the leg under way; never further, so a path that comes back to this place later is not cut short
        at = path_time_near(self.plan, here, max(0.0, self._held_at - 0.25), min(self._leg_end, self._held_at + LEG_TIME))
        return continued(self.plan, at, here, self.limits)

    async def _leg(self, first: int, last: int) -> tuple[int, str] | object | None:
        plan = self.plan
        start = float(plan.times[first])
        primitive = ExecuteTrajectory(
            self.name, plan.joint_names, tuple(tuple(float(v) for v in p) for p in plan.points[first:last + 1]),
            tuple(float(t - start) for t in plan.times[first:last + 1]),
        )
        self._stopped_for_hold = False  # a hold's stop before this leg stopped nothing of it
        motion = asyncio.ensure_future(self.backend.execute(self.group, primitive))
        end = self._leg_end = float(plan.times[last])
        live = self.backend.holds_within_motion
        stopped = False
        try:
            while not motion.done():
                before = self.clock.now()
                try:
                    await self.clock.wait_for(asyncio.shield(motion), self.period)
                except (asyncio.TimeoutError, BridgeError):
                    pass  # a period passed, or the motion ended: below
                if not self.held:
                    self._advance(end, max(0.0, self.clock.now() - before))
                sample = self.sample()
                if live and not self.held and self._ending is None and not motion.done():
                    violation = self._outside(sample, plan.path.position, "path")
                    if violation is not None:
                        self.end(PATH_TOLERANCE_VIOLATED, violation)
                if (self._ending is not None or self.held) and not stopped and not motion.done():
                    self._stopped_for_hold = self._ending is None
                    # the goal ends or is held while its motion runs: stop it here too -- a stop asked for in the
                    # instant between sending the motion and the back end taking it up found nothing to stop
                    stopped = True
                    await self.stop_backend()
            try:
                motion.result()
            except BridgeError as error:  # a stop for a hold is the hold; anything else the caller decides on
                if error.kind is FaultKind.STOPPED and self._stopped_for_hold and self._ending is None:
                    self._stopped_for_hold = False
                    return _HELD
                raise
        finally:
            if not motion.done():
                motion.cancel()
                await asyncio.gather(motion, return_exceptions=True)
        self.elapsed = end
        sample = self.sample()
        if self._ending is not None:
            return self._ended()
        violation = self._outside(sample, plan.path.position, "path") if last < len(plan.times) - 1 else None
        if violation is not None:
            return PATH_TOLERANCE_VIOLATED, violation
        return None

    def _advance(self, end: float, step: float) -> None:
        """The path's time after ``step`` s of the clock: the clock's own, or, once the speed override has played
        this goal slower than written, where the arm is on the path (it never runs ahead of the clock)."""
        self.scaled = self.scaled or self.backend.speed_override < 1.0
        if not self.scaled or not self.backend.holds_within_motion:
            self.elapsed = min(end, self.elapsed + step * (self.backend.speed_override if self.scaled else 1.0))
            return
        positions = self.backend.joint_state()[1]
        here = np.array([positions[i] for i in self._index], dtype=float)
        self.elapsed = path_time_near(self.plan, here, self.elapsed, min(end, self.elapsed + step))

    async def _settle(self) -> tuple[int, str]:
        """The path has ended: the goal tolerances, met at once or within the goal time tolerance."""
        plan = self.plan
        checks = 1 + math.ceil(plan.goal_time / self.period - 1e-9)  # at the end, then every period up to the goal time
        for check in range(checks):
            if check and await self._wait_stopping(plan.goal_time / (checks - 1)):
                return self._ended()
            sample = self.sample()
            violation = self._outside(sample, plan.goal.position, "goal") or self._too_fast(sample)
            if violation is None:
                return SUCCESSFUL, ""
        assert violation is not None
        return GOAL_TOLERANCE_VIOLATED, violation + (f" {plan.goal_time:g} s after the path's end" if plan.goal_time > 0 else " at the path's end")

    # --------------------------------------------------------------------------- samples
    def sample(self) -> Sample:
        """The arm now against the path at the follower's time (told to ``observe``: feedback, state)."""
        desired, rate = self.plan.at(self.elapsed)
        positions = self.backend.joint_state()[1]
        actual = np.array([positions[i] for i in self._index], dtype=float)
        now = self.clock.now()
        velocity = np.zeros_like(actual)
        if self._last is not None and now - self._last[0] > 1e-9:
            velocity = (actual - self._last[1]) / (now - self._last[0])
        if self._last is None or now - self._last[0] > 1e-9:
            self._last = (now, actual)
        self.latest = Sample(self.elapsed, desired, rate if not self.held else np.zeros_like(rate), actual, velocity)
        self.observe(self.latest)
        return self.latest

    def _outside(self, sample: Sample, bound: NDArray[np.float64], which: str) -> str | None:
        error = np.abs(sample.error)
        over = np.nonzero(error > bound)[0]
        if not len(over):
            return None
        j = int(over[np.argmax((error - bound)[over])])
        target = "where the path is" if which == "path" else "the last point"
        return (
            f"{self.group}: {self.plan.joint_names[j]} is {error[j]:.4f} rad from {target} at {sample.t:.3f} s "
            f"(at {sample.actual[j]:.4f} rad, {sample.desired[j]:.4f} rad wanted), beyond its {which} tolerance {bound[j]:g} rad"
        )

    def _too_fast(self, sample: Sample) -> str | None:
        bound = self.plan.goal.velocity
        speed = np.abs(sample.actual_velocity)
        over = np.nonzero(speed > bound)[0]
        if not len(over):
            return None
        j = int(over[0])
        return f"{self.group}: {self.plan.joint_names[j]} still moves at {speed[j]:.4f} rad/s, beyond its goal velocity tolerance {bound[j]:g} rad/s"

    def _ended(self) -> tuple[int, str]:
        assert self._ending is not None
        return self._ending

    async def _wait_stopping(self, seconds: float) -> bool:
        """Wait ``seconds`` of run time or until the goal is ended early; True if it was."""
        if math.isfinite(seconds) and seconds > 0.0:
            try:
                await self.clock.wait_for(self._stopping.wait(), seconds)
            except asyncio.TimeoutError:
                pass
        return self._stopping.is_set()
