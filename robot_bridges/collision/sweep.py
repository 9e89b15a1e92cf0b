"""Conservative advancement: checking a motion for contacts with a proof for the instants between checks.

A fixed sampling (a check every 20 ms of motion) proves nothing between its samples: two hands
moving towards each other at 0.7 m/s each close 28 mm between two of them.  Here each pair of
bodies is checked again only when it could have come close: at a check the pair is ``d`` apart,
and its distance shrinks at most at its *rate* -- the sum over the joints moving it of the joint's
speed bound times the pair's lever about that joint (:mod:`robot_bridges.collision.layout`) --
so it cannot come closer than ``threshold`` before ``(d - threshold) / rate`` seconds.  Far pairs
are checked rarely, close ones often, pairs that do not move never again.

What is proven, with ``threshold`` T and ``resolution`` r (the minimum step, in metres of travel):

* a pair found at least T + r apart stays at least T apart until its next check (exact);
* a pair found between T and T + r apart is checked again after r of travel: it stays at least
  T - r apart until then (the one place the proof gives away r);
* a pair found closer than T is reported (a :class:`Contact`); while apart it is followed in steps
  of its distance (at least r), so a pair reported apart did not touch between two checks that
  found it at least r apart; once touching it is a collision and is checked again only at the
  caller's next boundary (:meth:`Advancement.recheck_reported`: where a call starts, say).

So every pair that comes closer than T - r at any instant is reported, and every pair reported
is closer than T at the instant reported.  A distance is measured by coal where the bounding
spheres say it may be small and taken as the spheres' gap (a lower bound: still a proof) where
they are far apart -- the broad phase, vectorised over all pairs at once.  coal's own broad phase
(``DynamicAABBTreeCollisionManager``) does not fit here from Python: it answers one number for all
its objects (the closest pair, links that touch by construction included: -37 mm at the Nextage's
initial pose), its callback cannot be subclassed from Python in coal 3.0 to filter pairs or keep
each pair's distance, and it costs 38 us per configuration against 15 us for the spheres' gaps of
all 106 pairs of that scene in numpy (measured 2026-11-27).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose
from robot_bridges.collision.layout import Layout
from robot_bridges.collision.scene import CollisionScene, Contact, coal, transform

Vector = NDArray[np.float64]
#: The minimum step: metres a pair may travel between two checks when it is found near the threshold.
RESOLUTION = 0.001
#: Pairs whose bounding spheres are this much farther apart than the threshold are not measured
#: exactly: the spheres' gap is a lower bound and already gives a long step (m).
EXACT_BEYOND = 0.1
#: A pair this far to falling due (a fraction of its wait) is checked with the pairs that are due: early is
#: always safe, and pairs in step share one placement of the robot.
EARLY = 0.25
#: A motion's speed bound is taken per this many equal pieces of it (slower on its ramps: longer steps).
PIECES = 8
_TIME = 1e-9  # s: checks this close are the same instant


class Advancement:
    """Conservative advancement over every pair of a scene (see the module docstring).

    The caller moves time forward segment by segment: within a segment the joints' speed bounds are
    constant (:meth:`set_speeds` at its start), :meth:`advance` checks the pairs as they fall due up
    to the segment's end, and at a boundary the caller changes what changed (a held part:
    :meth:`relayout`, the work: :meth:`set_work`) and calls :meth:`check_due` for the boundary itself.
    """

    def __init__(self, scene: CollisionScene, threshold: float, resolution: float = RESOLUTION) -> None:
        if not resolution > 0.0:
            raise ValueError(f"resolution must be > 0 m, got {resolution!r}")
        self.scene = scene
        self.threshold = float(threshold)
        self.resolution = float(resolution)
        self.checks = 0  # configurations placed and checked
        self._request = coal.DistanceRequest()
        self.layout: Layout = scene.layout()
        self._speeds = np.zeros(scene.model.nq)
        self._work: Mapping[str, Sequence[Pose]] = {}
        self.relayout(0.0)

    # ------------------------------------------------------------------ what changes at a boundary
    def relayout(self, t: float) -> None:
        """The scene's bodies changed (a part taken or let go of): every pair is due at ``t``."""
        self.layout = self.scene.layout()
        n = len(self.layout)
        self._budget = np.zeros(n)  # m the pair may travel from t_ref before it must be checked
        self._t_ref = np.full(n, t)
        self._last = np.full(n, np.inf)  # its distance at its last check
        self._excluded = self.layout.excluded(self._work)
        self._rate = self.layout.levers @ self._speeds
        self._schedule(np.arange(n))

    def set_speeds(self, speeds: Vector, t: float) -> None:
        """From ``t`` on, joint q[j] moves at most ``speeds[j]`` rad/s (the scene's joint order)."""
        speeds = np.asarray(speeds, dtype=float)
        if not np.all(np.isfinite(speeds)):
            raise ValueError("a joint's speed has no finite bound (the motion jumps): conservative advancement cannot step along it")
        self._budget -= self._rate * (t - self._t_ref)
        self._t_ref[:] = t
        self._speeds = speeds
        self._rate = self.layout.levers @ self._speeds
        self._schedule(np.arange(len(self._budget)))

    def set_work(self, work: Mapping[str, Sequence[Pose]], t: float) -> None:
        """Where each arm's motion starts and ends from ``t`` on; a pair no longer excused is due at once."""
        if dict(work) == self._work:
            return
        self._work = dict(work)
        excluded = self.layout.excluded(self._work)
        again = np.nonzero(self._excluded & ~excluded)[0]
        self._budget[again] = 0.0
        self._t_ref[again] = t
        self._excluded = excluded
        self._schedule(np.arange(len(self._budget)))

    def recheck_reported(self, t: float) -> None:
        """Pairs found closer than the threshold are checked again at ``t`` (a call changed: report it there too)."""
        close = np.nonzero(self._last < self.threshold)[0]
        if len(close):
            self._budget[close] = 0.0
            self._t_ref[close] = t
            self._schedule(close)

    def _schedule(self, pairs: NDArray[np.int64]) -> None:
        """When each of ``pairs`` falls due (inf: it does not move, or it is excused) and half-way there."""
        if not hasattr(self, "_due") or len(self._due) != len(self._budget):
            self._due = np.full(len(self._budget), np.inf)
            self._half = np.full(len(self._budget), np.inf)
        budget, rate = self._budget[pairs], self._rate[pairs]
        with np.errstate(divide="ignore", invalid="ignore"):
            wait = np.where(budget <= 0.0, 0.0, np.where(rate > 0.0, budget / rate, np.inf))
        wait[self._excluded[pairs]] = np.inf
        self._due[pairs] = self._t_ref[pairs] + wait
        self._half[pairs] = self._t_ref[pairs] + EARLY * wait

    # ------------------------------------------------------------------ checking
    def due(self) -> float:
        """The next instant a pair must be checked (inf: none moves)."""
        return float(self._due.min()) if len(self._due) else np.inf

    def advance(self, end: float, q_at: Callable[[float], Vector]) -> Iterator[tuple[float, list[Contact]]]:
        """Check the pairs as they fall due before ``end`` (not at it): each instant and what was found."""
        while True:
            t = self.due()
            if t >= end - _TIME:
                return
            yield t, self.check_due(t, q_at(t))

    def check_due(self, t: float, q: Vector) -> list[Contact]:
        """Check at ``t`` (configuration ``q``) every pair due by then; the contacts found.

        Pairs more than half-way to falling due are checked with them (early is always safe): the
        pairs fall into step and one placement of the robot serves several.
        """
        if not self._due.min() <= t + _TIME:
            return []
        due = np.nonzero(self._half <= t + _TIME)[0]
        self.checks += 1
        layout = self.layout
        ia, ib = layout.ia[due], layout.ib[due]
        needed = np.unique(np.concatenate([ia, ib]))
        placements = layout.place(q, needed)
        centres = np.zeros((len(placements), 3))
        centres[needed] = [placements[i][:3, 3] for i in needed.tolist()]
        distance = np.linalg.norm(centres[ia] - centres[ib], axis=1) - layout.pair_radii[due]
        found: list[Contact] = []
        solids = layout.solids
        poses: dict[int, Any] = {}
        for n in np.nonzero(distance < self.threshold + EXACT_BEYOND)[0].tolist():
            i, k = int(ia[n]), int(ib[n])
            a = poses.get(i) or poses.setdefault(i, transform(placements[i]))
            b = poses.get(k) or poses.setdefault(k, transform(placements[k]))
            d = float(coal.distance(solids[i].geometry, a, solids[k].geometry, b, self._request, coal.DistanceResult()))
            distance[n] = d
            if d < self.threshold:
                found.append(Contact(solids[i].body, solids[k].body, d))
        self._last[due] = distance
        self._budget[due] = self._allowance(distance)
        self._t_ref[due] = t
        self._schedule(due)
        return found

    def _allowance(self, d: Vector) -> Vector:
        """The travel a pair found ``d`` apart may make before its next check (module docstring)."""
        T, r = self.threshold, self.resolution
        return np.where(d >= T + r, d - T, np.where(d >= T, r, np.where(d > 0.0, np.maximum(r, d), np.inf)))


@dataclass(frozen=True)
class Track:
    """One motion on a time line: joints ``columns`` (the scene's order) follow ``at(t - start)`` for
    ``duration`` seconds (held at the ends), no joint faster than ``speeds`` (rad/s) -- or than
    ``speeds(a, b)`` between ``a`` and ``b`` s into it."""

    columns: NDArray[np.int64]
    start: float
    duration: float
    at: Callable[[float], Vector]
    speeds: Vector | Callable[[float, float], Vector]

    def bound(self, a: float, b: float) -> Vector:
        return np.asarray(self.speeds(a, b) if callable(self.speeds) else self.speeds, dtype=float)

    @property
    def end(self) -> float:
        return self.start + self.duration


def sweep_tracks(
    scene: CollisionScene,
    q: Vector,
    tracks: Sequence[Track],
    threshold: float,
    resolution: float = RESOLUTION,
    work: Mapping[str, Sequence[Pose]] | None = None,
    start: float | None = None,
) -> Iterator[tuple[float, list[Contact]]]:
    """Check ``tracks`` moving together from ``start`` (default: the first's start) with the rest of
    the robot at ``q``: every instant checked and the pairs found closer than ``threshold`` there."""
    if start is None:
        start = min((t.start for t in tracks), default=0.0)
    engine = Advancement(scene, threshold, resolution)
    engine.set_work(work or {}, start)
    engine.relayout(start)
    cuts = [t.start + t.duration * k / PIECES for t in tracks if callable(t.speeds) for k in range(1, PIECES)]
    boundaries = sorted({start, *(x for t in tracks for x in (t.start, t.end) if x > start), *(x for x in cuts if x > start)})

    def q_at(time: float) -> Vector:
        probe = np.array(q, dtype=float)
        for track in tracks:  # a track not started yet is where it starts
            probe[track.columns] = track.at(time - track.start)
        return probe

    def rates(time: float, until: float) -> Vector:
        out = np.zeros(len(q))
        for track in tracks:
            if track.start - _TIME <= time < track.end - _TIME:
                out[track.columns] = np.maximum(out[track.columns], track.bound(time - track.start, until - track.start))
        return out

    previous = None
    for n, boundary in enumerate(boundaries):
        if previous is not None:
            yield from engine.advance(boundary, q_at)
        engine.set_speeds(rates(boundary, boundaries[n + 1] if n + 1 < len(boundaries) else boundary), boundary)
        found = engine.check_due(boundary, q_at(boundary))
        yield boundary, found
        previous = boundary
