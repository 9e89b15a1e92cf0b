"""An alarm waits only for someone who can answer it, and only for a bounded time.

Without an operator (the embedded run without ``--interactive`` or without a terminal) an alarm
ends the run at once, saying what it asked; with one, simulated time stands still while the run
waits (no racing to 30,000 s at ``--speed max``); the default wait is ten minutes of the
operator's wall time, and ``alarm_timeout="0"`` is bounded too (a day).
"""
from __future__ import annotations

import asyncio
from typing import Any

from app_builder import Cell, make_app

from execution_engine.app_model.model import ALARM_TIMEOUT, ErrorPolicy
from node_transport.clock import Clock
from node_transport.wall_clock import ManualWallClock
from node_transport.wire import FaultKind

OPS = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("gripper_open",)}, {"left_arm": ("gripper_close",)}]


def test_an_alarm_nobody_can_answer_ends_the_run_at_once_with_the_question(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[dict[str, Any]], float]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.deployment.engine.operators = False
        cell.deployment.engine.wall_clock = ManualWallClock()  # never moved: only "at once" can end it
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="A3 at its limit")
        report = await asyncio.wait_for(cell.run(make_app(OPS, ErrorPolicy(action="alarm"))), 60.0)
        return report, cell.engine_states, clock.now()

    report, states, ended = run_sim(main)
    assert report.outcome == "failed"
    assert report.message.startswith("left_arm: move_to_joint_pose failed:") and "A3 at its limit" in report.message
    assert "the alarm asks an operator: retry (reset) or abort (stop)? - and no operator can answer it here" in report.message
    assert "run with --interactive at a terminal, or on ROS" in report.message
    assert report.errors[0].recovery.endswith("alarm cannot be answered: no operator console and no service client can reach this engine")
    alarm = next(s for s in states if s["state"] == "alarm")  # the question is still said, with how it would be answered
    assert "to retry: key 'x'" in alarm["message"] and "/execution_engine/reset" in alarm["message"]
    assert ended < 30.0  # simulated seconds: the run did not wait


def test_while_an_operator_is_waited_for_simulated_time_stands_still(run_sim: Any) -> None:
    """hold_for_operators: the alarm holds the virtual clock; only the wall-clock deadline moves the run on.

    Held, the deadline is the real one (a timer thread, 0.3 s): the loop sleeps in ``select`` until the thread wakes
    it.  Not held, the cell's periodic work spins simulated time on while nobody answers: there the wall clock is a
    manual one, moved past the deadline once a minute of run time has gone by in the alarm -- so the contrast does not
    depend on how many turns a loaded machine's loop makes in 0.3 s.
    """
    free_run = 60.0  # run seconds the unheld alarm is left to race before its wall-clock deadline comes

    def run(hold: bool) -> tuple[Any, float]:
        async def main(clock: Clock) -> tuple[Any, float]:
            cell = await Cell(clock, durations={"move_joints": 2.0}).start()
            engine = cell.deployment.engine
            engine.hold_for_operators = hold
            wall = None if hold else ManualWallClock()
            if wall is not None:
                engine.wall_clock = wall

            async def periodic() -> None:
                """The cell's periodic work (state publishing, diagnostics): what makes simulated time race."""
                alarm_at = None
                while True:
                    await clock.sleep(1.0)
                    if alarm_at is None and engine.state == "alarm":
                        alarm_at = clock.now()
                    if wall is not None and alarm_at is not None and clock.now() - alarm_at >= free_run:
                        wall.advance(0.3)

            cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
            ticker = asyncio.ensure_future(periodic())
            report = await asyncio.wait_for(cell.run(make_app(OPS, ErrorPolicy(action="alarm", alarm_timeout=0.3))), 3600.0)
            ticker.cancel()
            at_alarm = next(s["t"] for s in cell.engine_states if s["state"] == "alarm")
            return report, report.t_end - at_alarm

        return run_sim(main)

    held_report, held_span = run(True)
    assert "alarm not answered within 0.3 s (wall clock)" in held_report.message
    assert held_span < 5.0  # the wait itself took no run time: only the stop after it
    free_report, free_span = run(False)
    assert "alarm not answered within 0.3 s (wall clock)" in free_report.message
    assert free_span >= free_run  # without the hold, periodic work raced simulated time on while nobody answered


def test_the_default_alarm_wait_is_ten_minutes_and_zero_is_a_day(run_sim: Any) -> None:
    assert ErrorPolicy().alarm_timeout == ALARM_TIMEOUT == 600.0

    async def main(clock: Clock) -> tuple[Any, list[str]]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        wall = ManualWallClock()
        cell.deployment.engine.wall_clock = wall
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        run = asyncio.ensure_future(cell.run(make_app(OPS, ErrorPolicy(action="alarm", alarm_timeout=0.0))))
        while cell.deployment.engine.state != "alarm":
            await clock.sleep(0.01)
        seen = []
        wall.advance(86_399.0)
        await clock.sleep(0.1)
        seen.append(cell.deployment.engine.state)
        wall.advance(1.0)
        return await run, seen

    report, seen = run_sim(main)
    assert seen == ["alarm"]
    assert "alarm not answered within 86400 s (wall clock)" in report.message
