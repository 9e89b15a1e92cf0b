"""Simulated time across processes: bounded holds of a paced loop, a bridge's turnarounds, a follower of /clock.

Nothing here asserts a wall-clock duration: the paced loop's wall clock is injected where a bound
must pass, a release comes from another thread whenever it comes, and the follower of ``/clock``
runs on virtual time.
"""
from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import pytest

from node_transport.clock import Clock, FollowingClock, real_clock, run_with_clock, scaled_clock
from node_transport import typed
from node_transport.local import LocalTransport
from node_transport.port import poll_until
from node_transport.qos import COMMANDS, EVENTS
from node_transport.wire import ENGINE_EVENTS, EngineEvent, SmRequest, SmResult, sm_topic
from robot_bridges.turnaround import Turnaround

FAST = 1000.0  # a robot second is a wall millisecond


class Wall:
    """time.monotonic plus what a test moved it by."""

    def __init__(self) -> None:
        self.offset = 0.0

    def __call__(self) -> float:
        return time.monotonic() + self.offset


# ------------------------------------------------------------------------------- PacedLoop.hold_for
def test_a_bounded_hold_stops_robot_time_until_it_is_released() -> None:
    """A 1 ms sleep of robot time under a hold nobody but another thread ends: when the release
    comes, whenever that is, the sleep has not ended and no robot time has passed."""
    async def main(clock: Clock) -> tuple[bool, float, float]:
        loop: Any = asyncio.get_running_loop()
        seen: list[tuple[bool, float]] = []
        loop.hold_for("turnaround", 3600.0)
        sleeper = asyncio.ensure_future(clock.sleep(1.0))

        def release() -> None:
            seen.append((sleeper.done(), clock.now()))
            loop.release("turnaround")

        threading.Timer(0.05, loop.call_soon_threadsafe, (release,)).start()
        await sleeper
        (done_at_release, now_at_release), = seen
        return done_at_release, now_at_release, clock.now()

    done_at_release, now_at_release, after = run_with_clock(main, scaled_clock(FAST))
    assert not done_at_release and now_at_release == 0.0
    assert after == pytest.approx(1.0)


def test_a_hold_nobody_releases_ends_by_itself_at_its_bound() -> None:
    wall = Wall()

    async def main(clock: Clock) -> float:
        loop: Any = asyncio.get_running_loop()
        loop.hold_for("gone", 5.0)
        wall.offset += 6.0  # the bound passes (the peer that would have answered is gone)
        await clock.sleep(1.0)
        return clock.now()

    assert run_with_clock(main, scaled_clock(FAST), wall=wall) == pytest.approx(1.0)


def test_a_real_clock_ignores_holds() -> None:
    """Real controllers run on the wall clock: nothing may stop it."""
    async def main(clock: Clock) -> Any:
        loop: Any = asyncio.get_running_loop()
        loop.hold_for("turnaround", 3600.0)
        return loop.held_until(loop.wall())

    assert run_with_clock(main, real_clock()) is None


# ------------------------------------------------------------------------------------- Turnaround
def _request(kind: str = "execute") -> Any:
    return typed.to_msg(SmRequest(id="r1", kind=kind, operation="1", function="move_to"), real_clock())  # type: ignore[arg-type]


def _result(group: str) -> Any:
    return typed.to_msg(SmResult(id="r1", group=group, outcome="succeeded", operation="1", function="move_to"), real_clock())


def _state(state: str) -> Any:
    return typed.to_msg(EngineEvent("state", 0.0, state), real_clock())


def test_a_turnaround_is_held_from_a_step_on_its_way_to_the_groups_next_command() -> None:
    async def main(clock: Clock) -> list[bool]:
        loop: Any = asyncio.get_running_loop()
        transport = LocalTransport(clock)
        executing: set[str] = set()
        turn = Turnaround(transport.create_node("bridge"), loop, ["left_arm", "right_arm"], lambda: executing)
        engine = transport.create_node("engine")
        requests = {g: engine.create_publisher(typed.MachineRequestMsg, sm_topic(g, "request"), COMMANDS) for g in ("left_arm", "right_arm")}
        results = {g: engine.create_publisher(typed.MachineResultMsg, sm_topic(g, "result"), COMMANDS) for g in ("left_arm", "right_arm")}
        events = engine.create_publisher(typed.EngineEventMsg, ENGINE_EVENTS, EVENTS)

        async def held() -> bool:
            await asyncio.sleep(0)  # local delivery: on the loop's next turn
            await asyncio.sleep(0)
            return loop.held_until(loop.wall()) is not None

        seen = [await held()]
        turn.hold("left_arm")  # its primitive ended
        seen.append(await held())
        turn.commanded("right_arm")  # another group's command ends nothing of left_arm's
        seen.append(await held())
        turn.commanded("left_arm")
        seen.append(await held())
        requests["right_arm"].publish(_request())  # the engine asked right_arm for a function
        seen.append(await held())
        executing.add("left_arm")
        results["right_arm"].publish(_result("right_arm"))  # done while left_arm moves: the operation waits for that
        seen.append(await held())
        requests["left_arm"].publish(_request("end"))  # go to Finish: no command follows
        events.publish(_state("stopping"))  # the engine winds the run up
        seen.append(await held())
        events.publish(_state("finished"))
        seen.append(await held())
        return seen

    assert run_with_clock(main, scaled_clock(FAST)) == [False, True, True, False, True, False, True, False]


# --------------------------------------------------------------------------------- FollowingClock
def test_after_a_stall_the_follower_runs_on_the_wall_clock_so_a_poll_reaches_its_deadline(run_sim: Any) -> None:
    """The source stops: after the stall bound the fault is reported once and pending waits end;
    then time goes on at the source's last rate, so a loop polling until a deadline ends there
    instead of waking every few seconds for ever; when the source is back, time never goes back."""
    async def main(clock: Clock) -> tuple[bool, list[str], list[float], bool]:
        stalls: list[str] = []
        follower = FollowingClock(stall_timeout=3.0, on_stall=stalls.append)
        follower.bind(clock.loop)
        follower.advance_to(100.0)
        await clock.sleep(0.1)
        follower.advance_to(101.0)  # ten source seconds per wall second
        reached = await clock.wait_for(poll_until(follower, lambda: False, 60.0, 0.5), 600.0)
        times = [follower.now()]
        stalled = follower.stalled
        follower.advance_to(102.0)  # back, behind the time the follower reached meanwhile
        times.append(follower.now())
        await clock.sleep(0.1)
        follower.advance_to(103.0)
        times.append(follower.now())
        return reached or not stalled, stalls, times, follower.stalled

    failed, stalls, times, still_stalled = run_sim(main)
    assert not failed and len(stalls) == 1 and "no time from the clock source for 3 s" in stalls[0]
    assert times[0] >= 61.0 and times[1] == pytest.approx(times[0]) and times[2] == pytest.approx(times[1] + 1.0)
    assert not still_stalled


def test_a_simulator_slower_than_its_bound_never_makes_a_timeout_fire_early(run_sim: Any) -> None:
    """A 1 s timeout of the source's time while the source says nothing for 8 s of wall time (under the
    10 s bound: a busy computer, a bridge holding its time): the timeout has not fired, and fires once the
    source passes it."""
    async def main(clock: Clock) -> tuple[bool, bool, list[str]]:
        stalls: list[str] = []
        follower = FollowingClock(stall_timeout=10.0, on_stall=stalls.append)
        follower.bind(clock.loop)
        follower.advance_to(100.0)
        waiting = asyncio.ensure_future(follower.wait_for(asyncio.Event().wait(), 1.0))
        await clock.sleep(8.0)
        early = waiting.done()
        follower.advance_to(101.5)
        try:
            await clock.wait_for(waiting, 1.0)
        except asyncio.TimeoutError:
            pass
        return early, waiting.done(), stalls

    early, ended, stalls = run_sim(main)
    assert not early and ended and stalls == []


def test_a_source_that_never_ticked_gets_the_longer_first_tick_bound(run_sim: Any) -> None:
    """A simulator still starting (models, scene) has not stopped: the first tick may take longer than a stall."""
    async def main(clock: Clock) -> tuple[float, list[str]]:
        stalls: list[str] = []
        follower = FollowingClock(stall_timeout=3.0, first_tick_timeout=8.0, on_stall=stalls.append)
        follower.bind(clock.loop)
        started = clock.now()
        with pytest.raises(asyncio.TimeoutError):
            await follower.wait_for(asyncio.Event().wait(), 100.0)
        return clock.now() - started, stalls

    waited, stalls = run_sim(main)
    assert 8.0 <= waited <= 12.0 + 1e-6  # the bound, checked every half of it
    assert stalls == ["no time from the clock source for 8 s (it never ticked): pending waits end now, "
                      "and time runs on the wall clock at x1 until it ticks again"]
