"""A scaled clock (``--speed 10``) counts only the loop's idle waits: work and stalls are not robot time.

Nothing here sleeps for a result: the wall clock the paced loop reads is injected, and a test
"burns" or "stalls" wall time by moving it.  A clock that counted wall time would see a minute
pass in every burn below, and the assertions would fail by orders of magnitude.
"""
from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from machine_harness import Harness
from robot_bridges.camera import vision
from scripted_backend import ScriptedBackend

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.runner import dry_run
from core_functions.primitives import Primitive, PrimitiveResult
from execution_engine.app_model import load_application
from execution_engine.engine.report import RunReport
from node_transport.clock import MAX_SPEED, MIN_SPEED, Clock, PacedLoop, run_with_clock, scaled_clock, simulated_clock
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

APPS = Path(__file__).resolve().parents[1] / "apps_xml"
FAST = 1000.0  # the fastest scaled clock: a second of robot time is a millisecond of waiting


class FakeWall:
    """The monotonic clock plus whatever the test burnt or stalled.

    ``burn(s)``: the process worked ``s`` seconds (a render, a detection, a busy computer) -- the
    wall clock jumps at once.  ``stall_next_wait(s)``: the process is descheduled for ``s`` seconds
    during the loop's next idle wait; ``on_wait`` (a function) runs in another thread as that wait
    begins, like a peer answering meanwhile.
    """

    def __init__(self) -> None:
        self.offset = 0.0
        self._stall = 0.0
        self.on_wait: Any = None

    def burn(self, seconds: float) -> None:
        self.offset += seconds

    def stall_next_wait(self, seconds: float, on_wait: Any = None) -> None:
        self._stall, self.on_wait = seconds, on_wait

    def __call__(self) -> float:
        value = time.monotonic() + self.offset
        if self._stall:  # the loop reads the wall clock as it begins to wait: the stall comes next
            self.offset += self._stall
            self._stall = 0.0
            if self.on_wait is not None:
                threading.Thread(target=self.on_wait, name="peer answering during the stall").start()
        return value


# ----------------------------------------------------------------------------- the clock itself
def test_work_on_the_loop_is_not_robot_time() -> None:
    wall = FakeWall()

    async def main(clock: Clock) -> list[float]:
        seen = []
        await clock.sleep(1.0)
        seen.append(clock.now())
        wall.burn(60.0)  # a minute of rendering on the loop: 60,000 s of robot time if wall time counted
        seen.append(clock.now())
        await clock.sleep(1.0)
        seen.append(clock.now())
        return seen

    assert run_with_clock(main, scaled_clock(FAST), wall=wall) == [pytest.approx(1.0), pytest.approx(1.0), pytest.approx(2.0)]


def test_a_stall_during_a_wait_moves_time_to_the_timer_and_no_further() -> None:
    wall = FakeWall()

    async def main(clock: Clock) -> list[float]:
        wall.stall_next_wait(100.0)  # the process loses its core for 100 s while it waits 100 run seconds (0.1 s)
        await clock.sleep(100.0)
        after_stall = clock.now()
        await clock.sleep(1.0)
        return [after_stall, clock.now()]

    assert run_with_clock(main, scaled_clock(FAST), wall=wall) == [pytest.approx(100.0), pytest.approx(101.0)]


def test_an_answer_that_came_during_a_stall_beats_its_own_timeout() -> None:
    """The stall ends with both the answer and the timeout due: the answer is handled first."""
    wall = FakeWall()

    async def main(clock: Clock) -> tuple[str, float]:
        loop = asyncio.get_running_loop()
        answer: asyncio.Future[str] = loop.create_future()
        wall.stall_next_wait(100.0, on_wait=lambda: loop.call_soon_threadsafe(answer.set_result, "accepted"))
        got = await clock.wait_for(answer, 5.0)
        return got, clock.now()

    got, now = run_with_clock(main, scaled_clock(1.0 / MIN_SPEED), wall=wall)  # 5 run s are 0.05 wall s
    assert got == "accepted" and now < 5.0 - 1e-5  # short of the deadline: a wait that checks its deadline first still takes the answer


@pytest.mark.parametrize("kind", ["simulated", "paced"])
def test_work_in_a_worker_thread_holds_time(kind: str) -> None:
    """Idle jumps (simulated) and idle waits (paced) count only when no work the loop waits for is pending."""
    gate = threading.Event()

    def work() -> float:
        threading.Timer(0.02, gate.set).start()  # the work takes a little real time
        gate.wait(10.0)
        return 42.0

    async def main(clock: Clock) -> tuple[float, float, bool]:
        sleeper = asyncio.ensure_future(clock.sleep(10.0))
        result = await asyncio.get_running_loop().run_in_executor(None, work)
        during, woke = clock.now(), sleeper.done()
        await sleeper
        return result, during, woke

    clock = simulated_clock() if kind == "simulated" else scaled_clock(FAST)
    result, during, woke = run_with_clock(main, clock)
    assert result == 42.0 and during == pytest.approx(0.0, abs=1e-3) and not woke


def test_speed_one_is_the_wall_clock_and_other_speeds_are_paced() -> None:
    assert not scaled_clock(1.0).paced
    assert scaled_clock(10.0).paced and scaled_clock(MIN_SPEED).paced and scaled_clock(MAX_SPEED).paced

    async def main(clock: Clock) -> bool:
        loop = asyncio.get_running_loop()
        return isinstance(loop, PacedLoop) and not loop.paced

    assert run_with_clock(main, scaled_clock(1.0))  # a real controller's timeouts stay wall seconds


@pytest.mark.parametrize("speed", [1e-300, 0.001, 1000.5, 1e308])
def test_a_speed_outside_its_range_is_refused(speed: float) -> None:
    with pytest.raises(ValueError, match=r"speed must be in \[0.01, 1000\]"):
        scaled_clock(speed)


def test_a_scaled_clock_refuses_a_loop_that_counts_wall_time() -> None:
    async def main() -> None:
        scaled_clock(10.0).bind()

    with pytest.raises(RuntimeError, match="needs a PacedLoop"):
        asyncio.run(main())


def test_a_sleep_shorter_than_the_loop_can_tell_apart_still_lets_time_pass() -> None:
    """A motion's last sliver: at x1000 on a computer up for a month, sleeping the 1.7 ns left to a mark
    (a wall wait far below asyncio's 1 ns timer resolution) once waited at the same instant for ever."""
    month = 30 * 86400.0

    async def main(clock: Clock) -> list[float]:
        mark, seen = clock.now() + 1.7e-9, []
        for _ in range(1000):  # bounded: a livelock ends the loop, not the test run
            if clock.now() >= mark:
                break
            await clock.sleep(mark - clock.now())
            seen.append(clock.now())
        return seen

    for make, wall in ((lambda: scaled_clock(FAST), lambda: time.monotonic() + month), (simulated_clock, None)):
        seen = run_with_clock(main, make(), **({"wall": wall} if wall else {}))
        assert 1 <= len(seen) <= 2, f"{len(seen)} sleeps to pass a mark 1.7 ns away"
        assert seen == sorted(seen) and seen[-1] > seen[0] - 1e-12


# ------------------------------------------------------------------------------ the machines
class StallingBackend(ScriptedBackend):
    """A bridge whose computer stalls a minute before each primitive can be accepted."""

    wall: FakeWall

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        self.wall.burn(60.0)  # before the first await: the bridge's 'accepted' comes after it
        return await super().execute(group, primitive)


def test_the_bridge_accept_timeout_does_not_fire_when_the_computer_stalls() -> None:
    wall = FakeWall()
    StallingBackend.wall = wall

    async def main(clock: Clock) -> tuple[list[Any], list[Any]]:
        h = await Harness(clock, parameters={"bridge_timeout": 5.0}, backend_class=StallingBackend).start()
        try:
            first = h.send("left_arm", "move_to_joint_pose", "initial")
            second = h.send("right_arm", "move_to_joint_pose", "initial")
            results = [await h.result(first), await h.result(second)]
            return results, h.backend.executed()
        finally:
            await h.close()

    results, executed = run_with_clock(main, scaled_clock(FAST), wall=wall)
    assert [r.outcome for r in results] == ["succeeded", "succeeded"], [r.error for r in results]
    assert wall.offset >= 120.0  # two minutes of stalls: 120,000 s at x1000 if wall time counted
    assert [e.t_end - e.t_start for e in executed] == [pytest.approx(1.0), pytest.approx(1.0)]  # robot time as planned


# ----------------------------------------------------------------------- the rivet demonstrator
def test_a_slow_detector_leaves_the_rivet_demonstrators_cycle_time_as_the_dry_run_predicts(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Each hole detection burns 3 s of wall time; at x1000 the run still takes the dry run's 88.77 s."""
    app = load_application(APPS / "rivet_installation.xml", full_catalog())
    options = BackendOptions(robot=app.robot)
    predicted = dry_run(app, "nextage-sim", options, str(tmp_path / "t.sqlite"))
    wall = FakeWall()
    detections: list[float] = []
    locate = vision.locate

    def slow_locate(*args: Any, **kwargs: Any) -> Any:
        wall.burn(3.0)
        detections.append(wall.offset)
        return locate(*args, **kwargs)

    monkeypatch.setattr(vision, "locate", slow_locate)

    async def run(clock: Clock) -> RunReport:
        backend = await create_backend("nextage-sim", clock, options)
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": str(tmp_path / "run.sqlite")})
        try:
            return await deployment.engine.run(app)
        finally:
            await deployment.close()

    report = run_with_clock(run, scaled_clock(FAST), wall=wall)
    assert report.ok and report.retries == 0 and not report.errors
    assert len(detections) >= 4  # every hole was looked for, each three seconds of wall time
    assert report.total == pytest.approx(predicted.cycle_time, rel=1e-6)
