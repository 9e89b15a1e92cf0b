"""The collision sweep of a dry run: every motion of every group, at the times they would run.

The dry run keeps each motion with its time and a bound on its joints' speeds (:mod:`motions`);
here the robot is put through all of them together on the report's time line -- two arms that
move at once are checked at the same instants, an arm that waits is checked where it waits --
by conservative advancement (robot_bridges/collision/sweep.py): each pair of bodies is checked
again when the joints moving it could have brought it within the margin, so every pair that
comes closer than the margin less :data:`~robot_bridges.collision.sweep.RESOLUTION` at any
instant is found, not only at samples.  The time line is cut where the speeds change (a motion
starts or ends), where a gripper takes or lets go of a part, and where a call starts (a pair
already too close is reported at that call too).  Each pair closer than the margin
(robot_bridges/collision/scene.py) becomes a finding of kind ``collision`` at the call of every
group involved, naming both bodies and the call of the other group, so a collision of two arms is
reported at the lines of both functions.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cell_runner.dry_run.motions import GripRecord, MotionRecord
from cell_runner.dry_run.recorder import Recorder
from cell_runner.dry_run.report import FoundBody
from core_functions.geometry import Pose
from execution_engine.app_model.model import Application
from robot_bridges.collision import CollisionScene, Contact, cell_boxes, held_part, scene_for
from robot_bridges.collision.scene import STATIC, Body
from robot_bridges.collision.sweep import PIECES, Advancement

COLLISION = "collision"
#: The former sweep's fixed step (s), kept as :func:`sweep`'s reference: at the Nextage's top joint speed
#: (1 rad/s) a point of an arm travels up to 14 mm between two samples, and nothing between is proven.
SAMPLED_STEP = 0.02
_TIME = 1e-9  # s: instants this close are the same


@dataclass(frozen=True)
class SweepStats:
    """How much the sweep checked: motions, configurations (instants checked) and body pairs found close."""

    motions: int
    samples: int
    contacts: int


def scene_of(app: Application) -> CollisionScene | None:
    """The collision model of the application's robot in its cell, or None for a robot without one."""
    try:
        scene = scene_for(app.robot)
    except KeyError:
        return None
    if app.cell is not None:
        scene.set_cell(cell_boxes(app.cell.to_snapshot(app.robot)))
    return scene


def sweep(
    app: Application,
    scene: CollisionScene,
    initial: tuple[tuple[str, ...], tuple[float, ...]],
    motions: Sequence[MotionRecord],
    grips: Sequence[GripRecord],
    recorder: Recorder,
    step: float | None = None,
) -> SweepStats:
    """Check every motion by conservative advancement (see the module docstring); findings go to ``recorder``.

    ``step``: the former fixed sampling instead, every ``step`` seconds of motion and at each end
    (:data:`SAMPLED_STEP` was the dry run's), which proves nothing between samples: kept as the
    reference the benches measure against.
    """
    line = _Timeline(app, scene, initial, motions, grips)
    findings = _Findings(app, recorder)
    if line.first is None:
        return SweepStats(0, 0, 0)
    if step is not None:
        times = sorted({t for m in line.ordered for t in _samples(m, step)} | {g.t for g in grips})
        for t in times:
            line.reach(t)
            findings.note(t, scene.contacts(line.q, line.work), line.now)
        findings.report(scene.margin, scene.joint_names)
        return SweepStats(len(line.ordered), len(times), findings.found)
    spans = [s.start for s in recorder.spans if s.start > line.first]
    pieces = [m.start + m.duration * k / PIECES for m in line.ordered for k in range(1, PIECES)]
    boundaries = sorted({line.first, *(m.start for m in line.ordered), *(m.end for m in line.ordered), *(g.t for g in grips), *spans, *pieces})
    engine = Advancement(scene, scene.margin)
    previous = None
    for n, b in enumerate(boundaries):
        if previous is not None:
            for t, contacts in engine.advance(b, line.q_at):
                findings.note(t, contacts, line.q_at)
        held = line.reach(b)
        engine.set_speeds(line.speeds(b, boundaries[n + 1] if n + 1 < len(boundaries) else b), b)
        if held or previous is None:
            engine.relayout(b)
        engine.set_work(line.work, b)
        engine.recheck_reported(b)
        findings.note(b, engine.check_due(b, line.q), line.now)
        previous = b
    findings.report(scene.margin, scene.joint_names)
    return SweepStats(len(line.ordered), engine.checks, findings.found)


class _Timeline:
    """Where the robot is along the dry run's motions: joints, held parts and work, as time goes on (only forward)."""

    def __init__(self, app: Application, scene: CollisionScene, initial: tuple[tuple[str, ...], tuple[float, ...]],
                 motions: Sequence[MotionRecord], grips: Sequence[GripRecord]) -> None:
        self.scene = scene
        index = {name: k for k, name in enumerate(scene.joint_names)}
        self.q = np.zeros(len(scene.joint_names))
        for name, value in zip(*initial):
            if name in index:
                self.q[index[name]] = value
        self.snapshot = app.cell.to_snapshot(app.robot) if app.cell is not None else None
        self.ordered = sorted(motions, key=lambda m: m.start)
        self.columns = [np.array([index[j] for j in m.joints if j in index], dtype=np.int64) for m in self.ordered]
        self.keep = [np.array([k for k, j in enumerate(m.joints) if j in index], dtype=np.int64) for m in self.ordered]
        self.first = min([m.start for m in self.ordered] + [g.t for g in grips], default=None)
        self.grips = sorted(grips, key=lambda g: g.t)
        self.work: dict[str, tuple[Pose, ...]] = {}
        self.active: list[int] = []
        self._started = 0
        self._grip = 0

    def q_at(self, t: float) -> np.ndarray:
        """The joints at ``t`` (no later than the next motion's start)."""
        probe = self.q.copy()
        for k in self.active:
            probe[self.columns[k]] = self.ordered[k].at(t - self.ordered[k].start)[self.keep[k]]
        return probe

    def now(self, t: float) -> np.ndarray:
        """The joints the timeline has reached (``t``: the instant it was moved on to)."""
        return self.q

    def reach(self, t: float) -> bool:
        """Move on to ``t``: motions started and ended by then, parts taken and let go of (True: a grip changed the bodies)."""
        self.q = self.q_at(t)
        self.active = [k for k in self.active if t < self.ordered[k].end - _TIME]
        while self._started < len(self.ordered) and self.ordered[self._started].start <= t + _TIME:
            k, motion = self._started, self.ordered[self._started]
            ends = (motion.at(0.0)[self.keep[k]], motion.at(motion.duration)[self.keep[k]])
            self.work[motion.group] = tuple(p for e in ends if (p := _tcp(self.scene, self.q, self.columns[k], e, motion.group)) is not None)
            self.q[self.columns[k]] = motion.at(t - motion.start)[self.keep[k]]
            if t < motion.end - _TIME:
                self.active.append(k)
            self._started += 1
        held = False
        while self._grip < len(self.grips) and self.grips[self._grip].t <= t + _TIME:
            grip = self.grips[self._grip]
            self._grip += 1
            if grip.group in self.scene.tcps:
                self.scene.place(self.q)
                tcp = Pose.from_matrix(self.scene.tcp_matrix(grip.group))
                closed = grip.closed and self.snapshot is not None
                self.scene.set_held(grip.group, held_part(self.snapshot, tcp) if closed and self.snapshot is not None else None)
                held = True
        return held

    def speeds(self, start: float, end: float) -> np.ndarray:
        """Each joint's speed bound between ``start`` and ``end`` (no motion starting in between)."""
        rates = np.zeros(len(self.q))
        for k in self.active:
            motion = self.ordered[k]
            bound = motion.speeds_between(start - motion.start, end - motion.start)[self.keep[k]]
            rates[self.columns[k]] = np.maximum(rates[self.columns[k]], bound)
        return rates


class _Findings:
    """The closest contact of each call of each group, reported at the end (one finding per call)."""

    def __init__(self, app: Application, recorder: Recorder) -> None:
        self.app = app
        self.recorder = recorder
        self.calls = _Calls(app, recorder)
        self.worst: dict[tuple[str, str, str], _Worst] = {}
        self.found = 0

    def note(self, t: float, contacts: list[Contact], q_at: Callable[[float], np.ndarray]) -> None:
        """Contacts found at ``t``; ``q_at(t)``: the joints then, read only for a contact closer than its call's closest so far."""
        for contact in contacts:
            self.found += 1
            _note(self.worst, contact, t, self.calls.at(t), q_at)

    def report(self, margin: float, joint_names: tuple[str, ...]) -> None:
        for (group, operation, function), (contact, t, other, q) in self.worst.items():
            self.recorder.add(group, operation, function, COLLISION, "", _message(contact, margin, group, other, self.app), t,
                              joints=(joint_names, tuple(float(v) for v in q)), bodies=(_found(contact.a), _found(contact.b)))


class _Calls:
    """Which call each group is in at a time of the sweep (times only grow).

    A group's call is the one of its latest primitive; in lock-step (every operation a barrier) a
    group that sits an operation out is in that operation's call of its own (a ``wait``) as soon
    as another group starts working in it.
    """

    def __init__(self, app: Application, recorder: Recorder) -> None:
        self.spans = sorted(recorder.spans, key=lambda s: s.start)
        self.next = 0
        self.current: dict[str, tuple[str, str]] = {}
        self.order = {op.id: k for k, op in enumerate(app.operations)}
        self.operations = app.operations
        self.lock_step = getattr(app, "sync", "operation") == "operation"

    def at(self, t: float) -> dict[str, tuple[str, str]]:
        while self.next < len(self.spans) and self.spans[self.next].start <= t + 1e-12:
            span = self.spans[self.next]
            self.next += 1
            for group in span.groups:
                self.current[group] = (span.operation, span.function)
            if self.lock_step and span.operation in self.order:
                here = self.order[span.operation]
                for group, call in self.operations[here].calls.items():
                    known = self.current.get(group)
                    if known is None or self.order.get(known[0], -1) < here:
                        self.current[group] = (span.operation, call.function)
        return self.current


def _samples(motion: MotionRecord, step: float) -> list[float]:
    """Check times of one motion for the fixed sampling: its start, every ``step``, its end."""
    if motion.duration <= 0.0:
        return [motion.start]
    count = int(motion.duration / step)
    return [motion.start + k * step for k in range(count + 1)] + [motion.end]


def _tcp(scene: CollisionScene, q: np.ndarray, columns: np.ndarray, end: np.ndarray, group: str) -> Pose | None:
    """Where an arm's TCP is with a motion's joints at ``end`` (the work it comes from or goes to)."""
    if group not in scene.tcps:
        return None
    probe = q.copy()
    probe[columns] = end
    scene.place(probe)
    return Pose.from_matrix(scene.tcp_matrix(group))


#: The closest contact of one call: the contact, its instant, the call of the other group in it, the joints then.
_Worst = tuple[Contact, float, tuple[str, str, str] | None, np.ndarray]


def _found(body: Body) -> FoundBody:
    """A body of the collision model as the finding keeps it (whose: a group, ``cell`` or ``robot``)."""
    owner = "robot" if body.group == STATIC else body.group
    return FoundBody(owner, body.name, body.label())


def _note(worst: dict[tuple[str, str, str], _Worst], contact: Contact, t: float, calls: dict[str, tuple[str, str]],
          q_at: Callable[[float], np.ndarray]) -> None:
    """Keep the closest contact of each call of each group involved (the first time it came that close)."""
    groups = [b.group for b in (contact.a, contact.b) if b.group not in (STATIC, "cell")]
    for group in groups:
        call = calls.get(group)
        if call is None:
            continue
        other_group = next((g for g in groups if g != group), None)
        other = None if other_group is None else calls.get(other_group)
        key = (group, call[0], call[1])
        known = worst.get(key)
        if known is None or contact.distance < known[0].distance - 1e-9:
            worst[key] = (contact, t, None if other is None else (other_group, *other), q_at(t).copy())


def _message(contact: Contact, margin: float, group: str, other: tuple[str, str, str] | None, app: Application) -> str:
    text = contact.describe(margin)
    if other is not None:
        other_group, operation, function = other
        line = next((c.line for op in app.operations if op.id == operation for g, c in op.calls.items() if g == other_group), 0)
        text += f", against {other_group} {function} of operation {operation}" + (f" (line {line})" if line else "")
    return text

