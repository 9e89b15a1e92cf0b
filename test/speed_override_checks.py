"""What every back end's speed override must show, measured from the joint states it reports.

Shared by the tests of each back end (test_speed_override*.py): a running motion sampled from the
robot's joint states; its joint velocities before and after an override change; whether every
sample lies on the path of the same motion played without one; the joints' speeds and
accelerations against their limits; and the bounds a change may take, derived from the
acceleration limits the way robot_bridges/path_rate.py changes the rate.
"""
from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from node_transport.clock import Clock
from robot_bridges.path_rate import MAX_RATE_CHANGE

Probe = Callable[[], np.ndarray]


@dataclass
class Samples:
    """Joint positions (rows) at run times ``t``."""

    t: np.ndarray
    q: np.ndarray

    def window(self, start: float, end: float) -> Samples:
        keep = (self.t >= start) & (self.t <= end)
        return Samples(self.t[keep], self.q[keep])

    def speed(self) -> np.ndarray:
        """The mean speed of each joint over the samples (rad/s)."""
        return np.abs(self.q[-1] - self.q[0]) / (self.t[-1] - self.t[0])

    def velocities(self) -> np.ndarray:
        return np.diff(self.q, axis=0) / np.diff(self.t)[:, None]

    def accelerations(self) -> np.ndarray:
        v = self.velocities()
        mid = 0.5 * (self.t[1:] + self.t[:-1])
        return np.diff(v, axis=0) / np.diff(mid)[:, None]


async def sample(clock: Clock, work: Awaitable[Any], probe: Probe, period: float, actions: dict[float, Callable[[], Any]] | None = None,
                 offset: float = 0.0) -> tuple[Any, Samples]:
    """Run ``work`` and sample ``probe()`` every ``period`` from ``offset`` after its start (between two
    control ticks, so each sample reads one tick's state); ``actions``: run-time offsets -> what to do then."""
    start = clock.now()
    task = asyncio.ensure_future(work)
    pending = sorted((actions or {}).items())
    times, rows = [], []
    await clock.sleep(offset)
    while not task.done():
        now = clock.now() - start
        while pending and pending[0][0] <= now + 1e-9:
            result = pending.pop(0)[1]()
            if asyncio.iscoroutine(result):
                await result
        times.append(now)
        rows.append(np.array(probe(), dtype=float))
        await clock.sleep(period)
    times.append(clock.now() - start)
    rows.append(np.array(probe(), dtype=float))
    return await task, Samples(np.array(times), np.array(rows))


def settle_time(change: float, peak_speed: np.ndarray, acceleration: np.ndarray) -> float:
    """Clock time an override change of ``change`` (a rate difference) takes at most on a cruising path
    whose joints move at ``peak_speed`` as planned: the rate changes at least as fast as the tightest
    joint's acceleration limit allows (path_rate.py)."""
    moving = peak_speed > 1e-9
    slope = MAX_RATE_CHANGE if not moving.any() else min(MAX_RATE_CHANGE, float(np.min(acceleration[moving] / peak_speed[moving])))
    return abs(change) / slope


def distance_to_path(points: np.ndarray, path: np.ndarray) -> float:
    """The largest joint-space distance from any of ``points`` to the polyline through ``path``'s rows."""
    worst = 0.0
    a, b = path[:-1], path[1:]
    d = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    for p in points:
        s = np.clip(np.einsum("ij,ij->i", p - a, d) / length2, 0.0, 1.0)
        nearest = a + s[:, None] * d
        worst = max(worst, float(np.min(np.linalg.norm(nearest - p, axis=1))))
    return worst


def assert_within_limits(samples: Samples, velocity: np.ndarray, acceleration: np.ndarray, slack: float = 0.05) -> None:
    """No joint faster or accelerating harder than its limits (``slack``: the samples' discretisation)."""
    v = np.abs(samples.velocities())
    a = np.abs(samples.accelerations())
    assert np.all(v <= velocity * (1 + slack) + 1e-9), f"speed {v.max(axis=0)} beyond {velocity}"
    assert np.all(a <= acceleration * (1 + slack) + 1e-6), f"acceleration {a.max(axis=0)} beyond {acceleration}"
