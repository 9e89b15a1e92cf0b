"""The simulator's collision check: every running motion swept once, when the plan changes, not every tick.

What the robot will do is known the moment a motion starts: each running motion is a function of
its own time (robot_bridges/nextage_sim/trajectory.py) and, until something changes, every job's
time runs with the clock.  So when the plan changes -- a motion starts or ends, a job pauses,
resumes or stops, a part is taken or let go of, the cell or a tool changes, a teaching arm is
guided -- the guard sweeps every running motion together from now to the end of the longest,
by the same conservative advancement as the dry run (robot_bridges/collision/sweep.py), and
finds the first instant two bodies would touch.  Each tick only compares the clock with that
instant; the tick that reaches it puts the moving joints back where they touched and the motion
fails with a ``collision`` fault.  Every motion is checked this way, vision-corrected or not, with
the sweep's proof between its checks; a tick that finds a job behind or ahead of the plan (it
cannot, but the check costs nothing) sweeps again from where everything is.  Under a speed
override (robot_bridges/path_rate.py) a job's time runs at its rate: the sweep plays its motion at
that rate from where it is, and while a rate is still changing every tick sweeps again, so the
arms' timing against each other is the one they really have.

What is proven: no two bodies overlap by more than :data:`RESOLUTION` at any instant of a motion
that is not stopped (a touching pair is found at its first check closer than 0, and a pair found
at least ``RESOLUTION`` apart cannot touch before its next check).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from core_functions.geometry import Pose
from robot_bridges.collision import CollisionScene, Contact
from robot_bridges.collision.sweep import Track, sweep_tracks
from robot_bridges.nextage_sim.jobs import Job
from robot_bridges.nextage_sim.trajectory import Motion

#: m: the least travel between two checks of a pair found closer than this (the proof's one give).
RESOLUTION = 0.0001
#: Only touching counts at run time (distance <= 0): the smallest threshold above 0.
TOUCHING = float(np.nextafter(0.0, 1.0))
_TIME = 1e-9  # s


@dataclass(frozen=True)
class Touch:
    """Where the plan first touches: the instant on the clock and the contact."""

    at: float
    contact: Contact


class CollisionGuard:
    """Sweeps the running motions when the plan changes; tells a tick whether it has reached a contact."""

    def __init__(self, scene: CollisionScene) -> None:
        self.scene = scene
        self.sweeps = 0  # how many times the running motions were swept (one per change of plan)
        self._plan: dict[Job, tuple[float, float, float]] | None = None  # job -> (clock, its time then, its rate) at the sweep
        self._touch: Touch | None = None

    def invalidate(self) -> None:
        """Something changed what the robot will do: sweep again at the next tick."""
        self._plan = None

    def check(self, now: float, job: Job, t: float, q: np.ndarray, moving: Mapping[Job, Motion], work: Mapping[str, Sequence[Pose]]) -> Touch | None:
        """The contact ``job`` has reached at job time ``t`` (clock ``now``), or None; sweeps first if the plan changed.

        ``q`` is the simulator's joint vector (the model's order, the scene's), ``moving`` every job
        playing a motion and its motion, ``work`` where each arm's current motion starts and ends.
        """
        if self._plan is None or job not in self._plan or not all(j.rate.settled for j in moving) or self._off_plan(job, now, t):
            self._sweep(now, q, moving, work)
        touch = self._touch
        if touch is None or now < touch.at - _TIME:
            return None
        return touch

    def _off_plan(self, job: Job, now: float, t: float) -> bool:
        if job.paused or self._plan is None:
            return False
        at, progress, rate = self._plan[job]
        return abs(progress + (now - at) * rate - t) > 1e-6

    def _sweep(self, now: float, q: np.ndarray, moving: Mapping[Job, Motion], work: Mapping[str, Sequence[Pose]]) -> None:
        self.sweeps += 1
        q = np.array(q, dtype=float)
        plan: dict[Job, tuple[float, float, float]] = {}
        tracks: list[Track] = []
        for job, motion in moving.items():
            progress = job.progress_at(now)
            q[motion.indices] = motion.at(progress)
            rate = job.rate.rate
            plan[job] = (now, progress, rate)
            if not job.paused and rate > 0.0 and progress < motion.duration - _TIME:
                tracks.append(track(motion, now, progress, rate))
        self._plan = plan
        self._touch = first_touch(self.scene, q, tracks, work, now)


def track(motion: Motion, now: float, progress: float, rate: float) -> Track:
    """``motion`` as the sweep sees it: from clock ``now``, where it is (``progress``), at ``rate``."""
    if rate == 1.0:  # as planned: its own time is the clock's
        return Track(motion.indices, now - progress, motion.duration, motion.at, motion.speed_bound)

    def at(u: float) -> np.ndarray:
        return motion.at(progress + u * rate)

    def speed_bound(start: float = 0.0, end: float = float("inf")) -> np.ndarray:
        return motion.speed_bound(progress + start * rate, progress + end * rate) * rate

    return Track(motion.indices, now, (motion.duration - progress) / rate, at, speed_bound)


def first_touch(scene: CollisionScene, q: np.ndarray, tracks: Sequence[Track], work: Mapping[str, Sequence[Pose]], now: float) -> Touch | None:
    """The first instant from ``now`` at which two bodies touch, each motion started at its clock time."""
    for t, contacts in sweep_tracks(scene, q, tracks, TOUCHING, RESOLUTION, work, now):
        if contacts:
            return Touch(t, min(contacts, key=lambda c: c.distance))
    return None
