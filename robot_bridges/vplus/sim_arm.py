"""The simulated controller behind the V+ simulator: what each AdeptServer skill does to the arm.

Semantics follow AdeptServer's V+ programs (seed 000 and its ``adeptserver.V2``):

* ``move_to`` is ``MOVE TRANS(x,y,z,yaw,pitch,roll)``; ``move_rel_tool`` is ``MOVE here:TRANS(...)``;
  ``move_rel_world`` adds the six numbers to ``DECOMPOSE`` of the current location, component by
  component (so its angles add as Z-Y-Z' Euler angles); ``move_joints`` / ``move_rel_joints`` are
  ``JMOVE`` absolute / relative; ``movehome`` is ``MOVE #PPOINT(0,-90,180,0,90,0)``.  ``MOVE`` is
  joint-interpolated.
* A motion instruction returns as soon as the motion has *started*; if a motion is still running
  it first waits for that one to end (V+ does not start a second motion early; we do not model
  blending).  ``break`` (V+ ``BREAK``) returns when the arm has arrived.
* ``set_speed`` (V+ ``SPEED s``, without ``ALWAYS``) scales the joint speeds of the *next* motion
  only, as the seed says ("a speed factor for the subsequent motion command").
* ``monitor_speed`` (V+ ``SPEED s MONITOR``, the operator's monitor speed) scales every motion, the one
  under way included, on its path: the controller's motion time runs at that share of the clock, reached
  within the joints' accelerations (robot_bridges/path_rate.py); 0 holds the arm on its path and a value
  above 0 goes on from there.  It is the operator's setting, not a program's: the server takes it at
  once, beside the motion it scales (simulator.py).
* Air and gripper are digital outputs: air on signal 8; ``gripper_close`` turns air on and sets
  99 on / 100 off; ``gripper_open`` turns air on and sets 99 off / 100 on.

A skill that V+ would stop with an error -- a location out of reach or beyond a joint limit --
raises :class:`SkillError`; the server then sends no ack, as the real one does.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from node_transport.clock import Clock
from robot_bridges.path_rate import PathRate, sampled_shape
from robot_bridges.vplus.codec import Command, Skill
from robot_bridges.vplus.kinematics import (
    HOME_DEG,
    IKError,
    Location,
    ViperKinematics,
    location_to_matrix,
    matrix_to_location,
)

Joints = NDArray[np.float64]

_ARRIVED = 1e-6  # s
AIR_SIGNAL = 8
GRIPPER_CLOSE_SIGNAL = 99
GRIPPER_OPEN_SIGNAL = 100


class SkillError(Exception):
    """A skill failed on the controller (V+ would halt the program with an error message)."""


@dataclass(frozen=True)
class Segment:
    """One joint-interpolated motion with a trapezoidal profile of the path parameter u in [0, 1]."""

    start: Joints
    goal: Joints
    t0: float
    velocity: float  # du/dt at cruise
    acceleration: float  # d2u/dt2

    @property
    def duration(self) -> float:
        v, a = self.velocity, self.acceleration
        if v * v / a >= 1.0:  # never reaches cruise: triangular profile
            return 2.0 * math.sqrt(1.0 / a)
        return 1.0 / v + v / a

    @property
    def t_end(self) -> float:
        return self.t0 + self.duration

    def fraction(self, t: float) -> float:
        """The path parameter at run time ``t``."""
        tau = min(max(t - self.t0, 0.0), self.duration)
        v, a, total = self.velocity, self.acceleration, self.duration
        t_acc = min(v / a, total / 2.0)
        if tau <= t_acc:
            return 0.5 * a * tau * tau
        if tau >= total - t_acc:
            rest = total - tau
            return 1.0 - 0.5 * a * rest * rest
        return 0.5 * a * t_acc * t_acc + v * (tau - t_acc)

    def at(self, t: float) -> Joints:
        if t >= self.t_end:
            return self.goal
        return self.start + (self.goal - self.start) * self.fraction(t)


class SimulatedArm:
    """A Viper s850 on a V+ controller, as far as AdeptServer's skills can see it.

    Time is the injectable clock's: a motion of 2 s takes 2 s of run time, which a simulated
    clock skips and a scaled clock compresses.
    """

    def __init__(
        self,
        clock: Clock,
        kinematics: ViperKinematics | None = None,
        *,
        joints_deg: Sequence[float] = HOME_DEG,
        ramp: float = 0.2,
    ) -> None:
        if not ramp > 0:
            raise ValueError(f"ramp must be > 0 s, got {ramp}")
        self.clock = clock
        self.kin = kinematics or ViperKinematics()
        self.ramp = ramp  # seconds to reach full joint speed at 100 %
        start = np.radians(np.asarray(joints_deg, dtype=float))
        if not self.kin.within_limits(start):
            raise ValueError("initial joints beyond limits: " + "; ".join(self.kin.limit_violations(start)))
        self._segment: Segment | None = None  # the motion under way, if any
        self._rest = start  # where the arm is when no motion is under way (the last goal)
        self._next_speed = 100.0
        #: The monitor speed as the rate the controller's motion time runs at (1: the clock's), and that time:
        #: ``_own`` at clock ``_mark``.  A segment's times are on this motion clock.
        self.monitor = PathRate()
        self._own = self._mark = clock.now()
        self._changed: asyncio.Event | None = None
        self.signals: dict[int, bool] = {AIR_SIGNAL: False, GRIPPER_CLOSE_SIGNAL: False, GRIPPER_OPEN_SIGNAL: False}
        self.motions = 0

    # --------------------------------------------------------------------------- state
    def joints(self) -> Joints:
        """Joint positions (rad) now."""
        return self._segment.at(self.motion_time()) if self.moving and self._segment else self._rest

    def motion_time(self) -> float:
        """The controller's motion clock now: the run clock's time, at the monitor speed's rate since it changed."""
        now = self.clock.now()
        rate, segment = self.monitor, self._segment
        if now <= self._mark:
            return self._own
        if rate.settled:
            self._own += (now - self._mark) * rate.rate
        elif segment is None or self._own >= segment.t_end:  # nothing moves: nothing to ramp
            rate.rate = rate.target
            self._own += (now - self._mark) * rate.rate
        else:  # ramping within the joints' accelerations, in steps no longer than 5 ms
            shape = sampled_shape(lambda tau: segment.at(segment.t0 + tau), segment.duration)
            limits = self.kin.max_velocity / self.ramp
            t = self._mark
            while t < now - 1e-12:
                dt = min(0.005, now - t)
                self._own += rate.advance(dt, self._own - segment.t0, shape, limits)
                t += dt
        self._mark = now
        return self._own

    def set_monitor_speed(self, percent: float) -> None:
        """V+ ``SPEED percent MONITOR``: every motion, the running one included, at that share of its speed on its path."""
        self.motion_time()  # the time so far at the rate it had
        self.monitor.aim(percent / 100.0)
        if self._changed is not None:
            self._changed.set()

    def location(self) -> Location:
        """Flange location now (x, y, z mm; yaw, pitch, roll deg), as V+ ``HERE`` + ``DECOMPOSE``."""
        return matrix_to_location(self.kin.forward(self.joints()))

    @property
    def moving(self) -> bool:
        # A timer may fire a hair before its time (loop clock resolution): count that as arrived,
        # or a wait for the end could spin on sleeps too short to move the clock.
        return self._segment is not None and self.motion_time() < self._segment.t_end - _ARRIVED

    @property
    def motion_end(self) -> float:
        """Run time at which the current (or last) motion ends (at the monitor speed now; inf while held at 0)."""
        if self._segment is None:
            return 0.0
        left = self._segment.t_end - self.motion_time()
        if left <= 0.0:
            return self.clock.now() + left
        return self.clock.now() + left / self.monitor.rate if self.monitor.rate > 0.0 else math.inf

    # --------------------------------------------------------------------------- skills
    async def run(self, command: Command) -> None:
        """Execute one skill; returns when V+ would return from ``CALLS``."""
        skill, args = command.skill, command.args
        if skill is Skill.BREAK:
            await self._wait_motion()
        elif skill is Skill.SET_SPEED:
            self._next_speed = args[0]
        elif skill is Skill.MONITOR_SPEED:
            self.set_monitor_speed(args[0])
        elif skill is Skill.ENABLE_AIR:
            self.signals[AIR_SIGNAL] = True
        elif skill is Skill.DISABLE_AIR:
            self.signals[AIR_SIGNAL] = False
        elif skill is Skill.GRIPPER_CLOSE:
            self.signals.update({AIR_SIGNAL: True, GRIPPER_CLOSE_SIGNAL: True, GRIPPER_OPEN_SIGNAL: False})
        elif skill is Skill.GRIPPER_OPEN:
            self.signals.update({AIR_SIGNAL: True, GRIPPER_CLOSE_SIGNAL: False, GRIPPER_OPEN_SIGNAL: True})
        else:
            await self._wait_motion()  # V+ starts a motion only after the previous one
            self._start(self._target(skill, args))

    def _target(self, skill: Skill, args: tuple[float, ...]) -> Joints:
        here = self.joints()
        if skill is Skill.MOVE_JOINTS:
            goal = np.radians(np.asarray(args))
        elif skill is Skill.MOVE_REL_JOINTS:
            goal = here + np.radians(np.asarray(args))
        elif skill is Skill.MOVEHOME:
            goal = np.radians(np.asarray(HOME_DEG))
        else:
            goal = self._solve(self._cartesian_goal(skill, args, here), here)
        violations = self.kin.limit_violations(goal)
        if violations:
            raise SkillError(f"{skill.value}: joint limit: " + "; ".join(violations))
        return goal

    def _cartesian_goal(self, skill: Skill, args: tuple[float, ...], here: Joints) -> np.ndarray:
        if skill is Skill.MOVE_TO:
            return location_to_matrix(args)
        if skill is Skill.MOVE_REL_TOOL:
            return self.kin.forward(here) @ location_to_matrix(args)
        if skill is Skill.MOVE_REL_WORLD:
            current = matrix_to_location(self.kin.forward(here))
            return location_to_matrix([c + d for c, d in zip(current, args)])
        raise SkillError(f"{skill.value} is not a motion skill")  # pragma: no cover - dispatch is exhaustive

    def _solve(self, target: np.ndarray, seed: Joints) -> Joints:
        try:
            return self.kin.inverse(target, seed)
        except IKError as error:
            raise SkillError(f"location out of range: {error}") from None

    def _start(self, goal: Joints) -> None:
        start = self.joints()
        speed = self._next_speed / 100.0
        self._next_speed = 100.0  # SPEED without ALWAYS: this motion only
        delta = np.abs(goal - start)
        moving = delta > 1e-12
        self._rest = goal
        self.motions += 1
        if not np.any(moving):  # already there: a motion of zero length
            self._segment = None
            return
        vmax = self.kin.max_velocity[moving] * speed
        amax = self.kin.max_velocity[moving] / self.ramp
        velocity = float(np.min(vmax / delta[moving]))
        acceleration = float(np.min(amax / delta[moving]))
        self._segment = Segment(start, goal, self.motion_time(), velocity, acceleration)

    async def _wait_motion(self) -> None:
        """Sleep until the current motion has ended (returns at once when idle); a change of the monitor speed
        wakes it to look again, and while the rate ramps it looks every 5 ms."""
        if self._changed is None:
            self._changed = asyncio.Event()
        while self.moving and self._segment is not None:
            self._changed.clear()
            end = self.motion_end
            wait = 0.005 if not self.monitor.settled else end - self.clock.now()
            if math.isinf(wait):  # held on the path at 0 %: until the monitor speed changes
                await self._changed.wait()
                continue
            if self.monitor.rate == 1.0 and self.monitor.settled and self._own == self._mark:
                await self.clock.sleep_until(end)  # the clock's own time: as before any monitor speed
                continue
            try:
                await self.clock.wait_for(self._changed.wait(), max(0.0, wait))
            except asyncio.TimeoutError:
                pass
