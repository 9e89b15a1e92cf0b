"""The run's cycle time is the application's: from its first operation to its end, as the dry run counts it.

Waiting for the machines to come up or for an operator's Start is not part of a cycle: on a real
clock it would make the report longer than the prediction by however long the cell took to start.
"""
from __future__ import annotations

import asyncio
from typing import Any

import pytest
from app_builder import Cell, make_app

from node_transport.clock import Clock

OPS = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("move_to_joint_pose", "initial")}]


def test_the_report_counts_from_the_start_command_not_from_the_wait_for_it(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, float, Any]:
        cell = await Cell(clock, durations={"move_joints": 4.0}, engine_parameters={"autostart": False}).start()
        run = asyncio.ensure_future(cell.run(make_app(OPS)))
        await clock.sleep(30.0)  # nobody presses Start for half a minute
        started = clock.now()
        assert (await cell.operator("start")).success
        report = await run
        return report, started, cell

    report, started, cell = run_sim(main)
    assert report.ok
    assert report.t_start >= started
    assert report.total == pytest.approx(4.0, abs=0.05)  # the motion, not the 30 s before it
