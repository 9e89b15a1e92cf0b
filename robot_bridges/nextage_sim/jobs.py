"""Jobs: a primitive in execution holding its groups, and the loop that plays it on the clock.

Pause, resume, stop, BUSY for a held group and the second arm riding along on a multi-group primitive
behave the same whatever the primitive does, so they live here once; a primitive of the simulator
(robot_bridges/nextage_sim/backend.py) only says what the robot is like at each instant of its own time
(``tick``) and how long it lasts.  The job's time is its own: a pause freezes it, so ``resume`` continues
the very same planned motion to its original target.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

from core_functions.primitives import Primitive, describe
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.faults import FaultSpec
from robot_bridges.path_rate import PathRate, Shape, Vector

DONE = 1e-9  # s: a motion this close to a mark has reached it

#: Applies the robot's state at a job's own time t (s).
Tick = Callable[[float], None]


class Job:
    """One primitive in execution and the groups it holds; pause/resume/stop act on it."""

    def __init__(self, groups: frozenset[str], primitive: Primitive, loop: asyncio.AbstractEventLoop, override: float = 1.0) -> None:
        self.groups = groups
        self.primitive = primitive
        self.paused_by: set[str] = set()
        self.stopped = False
        self.wake = asyncio.Event()
        self.finished: asyncio.Future[None] = loop.create_future()
        self.error: BaseException | None = None
        self.progress = 0.0  # s of the primitive's own time elapsed (pauses excluded)
        self.horizon = 0.0  # the next instant the runner must act at (end, fault, sample)
        self.duration = 0.0
        self.tick: Tick = lambda t: None
        self.teaching = False
        #: the speed override on the path (robot_bridges/path_rate.py): the job's own time runs at its rate;
        #: a motion starts at rest, so it starts at the override itself
        self.rate = PathRate(target=override, rate=override)
        self.shape: Shape | None = None  # the motion's derivatives, which bound how fast the rate may change
        self.limits: Vector | None = None  # the moving joints' acceleration limits (rad/s^2)
        self._last = 0.0

    @property
    def paused(self) -> bool:
        return bool(self.paused_by)

    def restart(self, now: float) -> None:
        self.progress = 0.0
        self._last = now

    def progress_at(self, now: float) -> float:
        """Where the job's own time will be at clock ``now`` if nothing changes (held while paused)."""
        if self.paused:
            return self.progress
        return min(self.progress + max(now - self._last, 0.0) * (1.0 if self.teaching else self.rate.rate), self.duration)

    def advance(self, now: float) -> None:
        """Count the time since the last call at the override's rate unless paused, never past the horizon (a
        teaching job is a person's time: the override slows the robot, not the hand that guides it)."""
        if not self.paused:
            covered = (now - self._last) if self.teaching else self.rate.advance(now - self._last, self.progress, self.shape, self.limits)
            self.progress = min(self.progress + covered, self.horizon)
        self._last = now


class JobBoard:
    """Which job holds which group, and the commands that act on a group's job."""

    def __init__(self, clock: Clock, control_period: float) -> None:
        self.clock = clock
        self.control_period = control_period
        self._held: dict[str, Job] = {}
        self.override = 1.0  # the operator's speed override as a rate in [0, 1]

    def set_override(self, rate: float) -> None:
        """Every running job (and every later one) plays at ``rate`` of its planned speed, reached
        within the joints' acceleration limits from where each job is now."""
        self.override = rate
        now = self.clock.now()
        for job in {id(j): j for j in self._held.values()}.values():
            job.advance(now)  # the time so far at the rate it had
            job.rate.aim(rate)
            job.wake.set()

    def of(self, group: str) -> Job | None:
        """The job holding ``group``, if any."""
        return self._held.get(group)

    async def close(self) -> None:
        """Stop every job and wait until each has ended."""
        jobs = {id(j): j for j in self._held.values()}.values()
        for job in jobs:
            job.stopped = True
            job.wake.set()
        await asyncio.gather(*(asyncio.shield(j.finished) for j in jobs), return_exceptions=True)

    def pause(self, group: str) -> None:
        job = self._held.get(group)
        if job is None or job.stopped:
            return
        job.advance(self.clock.now())
        job.paused_by.add(group)
        job.tick(job.progress)  # hold exactly where the motion is now

    def resume(self, group: str) -> None:
        job = self._held.get(group)
        if job is None or group not in job.paused_by:
            return
        job.advance(self.clock.now())
        job.paused_by.discard(group)
        job.wake.set()

    async def stop(self, group: str) -> None:
        job = self._held.get(group)
        if job is None:
            return
        job.stopped = True
        job.wake.set()
        await asyncio.shield(job.finished)

    @contextmanager
    def hold(self, groups: frozenset[str], primitive: Primitive) -> Iterator[Job]:
        """Hold ``groups`` for ``primitive`` (BUSY if any is held), release them afterwards."""
        busy = sorted(g for g in groups if g in self._held)
        if busy:
            running = self._held[busy[0]].primitive
            raise BridgeError(FaultKind.BUSY, f"{', '.join(busy)} already executing {describe(running)}")
        job = Job(groups, primitive, asyncio.get_running_loop(), self.override)
        for g in groups:
            self._held[g] = job
        try:
            yield job
        except BaseException as error:
            job.error = error
            raise
        finally:
            for g in groups:
                if self._held.get(g) is job:
                    del self._held[g]
            if not job.finished.done():
                job.finished.set_result(None)

    async def join(self, group: str, primitive: Primitive) -> bool:
        """If ``group`` is already held by this very multi-group primitive, wait for it instead.

        Both arms' machines may send the same FullBodyMove / MasterSlaveMove; the first starts
        it, the second rides along and gets the same outcome.
        """
        job = self._held.get(group)
        if job is None or job.primitive != primitive:
            return False
        await asyncio.shield(job.finished)
        if isinstance(job.error, BridgeError):
            raise BridgeError(job.error.kind, job.error.detail)
        if job.error is not None:
            raise BridgeError(FaultKind.INTERNAL, f"{describe(primitive)} failed: {job.error!r}")
        return True

    async def run(
        self,
        job: Job,
        duration: float,
        tick: Tick,
        fault: FaultSpec | None,
        fault_error: Callable[[Job, FaultSpec], BridgeError],
        marks: Sequence[float] = (),
    ) -> None:
        """Advance the job's own time over ``[0, duration]`` every control period.

        ``tick(t)`` applies the state at job time ``t``; it runs at every period, at every mark,
        when a pause starts (so the hold is exact) and at the end.  A stop, an injected fault at
        its fraction of ``duration`` (raised as ``fault_error`` makes it) or an error out of
        ``tick`` ends the run by raising.
        """
        clock = self.clock
        fail_at = None if fault is None else fault.after * duration
        stops = sorted({*(m for m in marks if 0.0 < m < duration), *([fail_at] if fail_at is not None else []), duration})
        job.duration = duration
        job.tick = tick
        job.restart(clock.now())
        job.horizon = stops[0]
        tick(0.0)
        while True:
            if job.stopped:
                raise BridgeError(
                    FaultKind.STOPPED,
                    f"{', '.join(sorted(job.groups))}: {describe(job.primitive)} stopped after {job.progress:.3f} of {duration:.3f} s",
                )
            if job.progress >= job.horizon - DONE:
                tick(job.horizon)
                if fault is not None and job.horizon >= fault.after * duration - DONE:
                    raise fault_error(job, fault)
                if job.horizon >= duration - DONE:
                    return
                job.horizon = next(s for s in stops if s > job.horizon + DONE)
                continue
            if job.paused or (job.rate.holding and not job.teaching):  # paused, or held on the path by a 0 % override
                job.wake.clear()
                await job.wake.wait()
                job.advance(clock.now())
                continue
            tick(job.progress)
            rate = job.rate.rate
            ahead = (job.horizon - job.progress) / rate if rate > 0.0 else self.control_period
            await clock.sleep(min(self.control_period, ahead))
            job.advance(clock.now())
