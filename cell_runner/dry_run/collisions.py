"""The collision sweep of a dry run: every motion of every group, at the times they would run.

The dry run keeps each motion with its time (:mod:`motions`); here the robot is put through all
of them together on the report's time line -- two arms that move at once are checked at the
same instants, an arm that waits is checked where it waits -- every :data:`STEP` seconds of
motion and at each motion's end, with the held parts that the grippers took and let go of on
the way.  Each pair closer than the margin (robot_bridges/collision/scene.py) becomes a
finding of kind ``collision`` at the call of every group involved, naming both bodies and the
call of the other group, so a collision of two arms is reported at the lines of both functions.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cell_runner.dry_run.motions import GripRecord, MotionRecord
from cell_runner.dry_run.recorder import Recorder
from core_functions.geometry import Pose
from execution_engine.app_model.model import Application
from robot_bridges.collision import CollisionScene, Contact, cell_boxes, held_part, scene_for
from robot_bridges.collision.scene import STATIC

COLLISION = "collision"
#: Seconds of motion between two checks: at the Nextage's top joint speed (1 rad/s) no point of
#: an arm travels more than 14 mm between two of them (and less at the speeds skills use).
STEP = 0.02


@dataclass(frozen=True)
class SweepStats:
    """How much the sweep checked: motions, configurations (samples) and body pairs found close."""

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
) -> SweepStats:
    """Check every motion (see the module docstring); findings go to ``recorder``."""
    index = {name: k for k, name in enumerate(scene.joint_names)}
    q = np.zeros(len(scene.joint_names))
    for name, value in zip(*initial):
        if name in index:
            q[index[name]] = value
    snapshot = app.cell.to_snapshot(app.robot) if app.cell is not None else None
    ordered = sorted(motions, key=lambda m: m.start)
    columns = [np.array([index[j] for j in m.joints if j in index], dtype=np.int64) for m in ordered]
    keep = [np.array([k for k, j in enumerate(m.joints) if j in index], dtype=np.int64) for m in ordered]
    times = sorted({t for m in ordered for t in _samples(m)} | {g.t for g in grips})
    grip_queue = sorted(grips, key=lambda g: g.t)
    calls = _Calls(app, recorder)
    work: dict[str, tuple[Pose, ...]] = {}
    worst: dict[tuple[str, str, str], tuple[Contact, float, tuple[str, str] | None]] = {}
    started, active, g_next, samples, found = 0, [], 0, 0, 0
    for t in times:
        while started < len(ordered) and ordered[started].start <= t + 1e-12:
            active.append(started)
            motion = ordered[started]
            ends = (motion.at(0.0)[keep[started]], motion.at(motion.duration)[keep[started]])
            work[motion.group] = tuple(p for e in ends if (p := _tcp(scene, q, columns[started], e, motion.group)) is not None)
            started += 1
        still = []
        for k in active:
            motion = ordered[k]
            q[columns[k]] = motion.at(t - motion.start)[keep[k]]
            if t < motion.end - 1e-12:
                still.append(k)
        active = still
        while g_next < len(grip_queue) and grip_queue[g_next].t <= t + 1e-12:
            grip = grip_queue[g_next]
            g_next += 1
            if grip.group in scene.tcps:
                scene.place(q)
                tcp = Pose.from_matrix(scene.tcp_matrix(grip.group))
                scene.set_held(grip.group, held_part(snapshot, tcp) if grip.closed and snapshot is not None else None)
        samples += 1
        for contact in scene.contacts(q, work):
            found += 1
            _note(worst, contact, t, calls.at(t))
    for (group, operation, function), (contact, t, other) in worst.items():
        recorder.add(group, operation, function, COLLISION, "", _message(contact, scene.margin, group, other, app), t)
    return SweepStats(len(ordered), samples, found)


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


def _samples(motion: MotionRecord) -> list[float]:
    """Check times of one motion: its start, every STEP, its end."""
    if motion.duration <= 0.0:
        return [motion.start]
    count = int(motion.duration / STEP)
    return [motion.start + k * STEP for k in range(count + 1)] + [motion.end]


def _tcp(scene: CollisionScene, q: np.ndarray, columns: np.ndarray, end: np.ndarray, group: str) -> Pose | None:
    """Where an arm's TCP is with a motion's joints at ``end`` (the work it comes from or goes to)."""
    if group not in scene.tcps:
        return None
    probe = q.copy()
    probe[columns] = end
    scene.place(probe)
    return Pose.from_matrix(scene.tcp_matrix(group))


def _note(worst: dict, contact: Contact, t: float, calls: dict[str, tuple[str, str]]) -> None:
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
            worst[key] = (contact, t, None if other is None else (other_group, *other))


def _message(contact: Contact, margin: float, group: str, other: tuple[str, str, str] | None, app: Application) -> str:
    text = contact.describe(margin)
    if other is not None:
        other_group, operation, function = other
        line = next((c.line for op in app.operations if op.id == operation for g, c in op.calls.items() if g == other_group), 0)
        text += f", against {other_group} {function} of operation {operation}" + (f" (line {line})" if line else "")
    return text

