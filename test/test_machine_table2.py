"""Paper Table 2, row by row: each (state, signal) is driven for real and its transition observed.

The expected rows come from the one table in execution_engine.machine.table; this test makes
the machine produce every row on the status topic, so the running machine, the table and the
paper cannot drift apart.
"""
from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import pytest
from machine_harness import Harness

from core_functions.primitives import TrajectoryResult, WorkState
from node_transport.clock import Clock
from execution_engine.machine.table import (
    ERROR_HANDLING,
    FINISH,
    PAUSE,
    READY,
    STATES,
    STOP,
    TABLE_2,
    WORKING_STATES,
)
from execution_engine.smach import HISTORY
from robot_bridges.backend import FaultKind

ROWS = [(state, signal, target) for state, row in TABLE_2.items() for signal, target in row.items()]


def test_table_2_has_every_state_of_table_1_and_the_control_states() -> None:
    assert set(TABLE_2) == set(STATES)
    assert set(WORKING_STATES) == {w.value for w in WorkState}
    assert {"Motion", "FullBodyMotion", "RecordTrajectory", "TrajectoryExecution", "EndEffector", "Vision", "MasterSlave"} == set(WORKING_STATES)
    for working in WORKING_STATES:  # paper: ok / pause / stop / error from every working state
        assert dict(TABLE_2[working]) == {"ok": READY, "pause": PAUSE, "stop": STOP, "error": ERROR_HANDLING}
    assert dict(TABLE_2[PAUSE]) == {"resume": HISTORY, "stop": STOP, "error": ERROR_HANDLING}
    assert dict(TABLE_2[STOP]) == {"error": ERROR_HANDLING}
    assert dict(TABLE_2[ERROR_HANDLING]) == {"ok": READY, "end": FINISH}
    assert TABLE_2[READY]["end"] == FINISH
    assert {TABLE_2[READY][w.request_signal] for w in WorkState} == set(WORKING_STATES)
    assert len(ROWS) == 8 + 7 * 4 + 3 + 1 + 2


# ------------------------------------------------------------------ entering each state
async def _enter(h: Harness, state: str) -> tuple[str, list[str]]:
    """Start a function whose first primitive runs in ``state``; returns (group, request ids)."""
    if state == "Motion":
        return "left_arm", [h.send("left_arm", "move_to_joint_pose", "initial")]
    if state == "EndEffector":
        return "left_arm", [h.send("left_arm", "gripper_open")]
    if state == "Vision":
        return "left_arm", [h.send("left_arm", "locate", "hole_1")]
    if state == "RecordTrajectory":
        return "left_arm", [h.send("left_arm", "teach_trajectory", "taught", "2.0")]
    if state == "TrajectoryExecution":
        names = h.robot.group("left_arm").joint_names
        h.machines["left_arm"].store.save("left_arm", "stored", TrajectoryResult(names, ((0.0,) * 6, (0.1,) * 6), (0.0, 1.0)), "plan", 0.0)
        return "left_arm", [h.send("left_arm", "execute_trajectory", "stored")]
    if state == "FullBodyMotion":
        partners = ("left_arm", "right_arm")
        return "left_arm", [h.send(g, "full_body_move", "initial", sync="k1", partners=partners) for g in partners]
    if state == "MasterSlave":
        partners = ("left_arm", "right_arm")
        return "left_arm", [
            h.send("left_arm", "master_move", "above", "right_arm", sync="k2", partners=partners),
            h.send("right_arm", "slave_follow", "left_arm", sync="k2", partners=partners),
        ]
    raise AssertionError(state)


Scenario = Callable[[Harness], Awaitable[tuple[str, str]]]


async def _working_row(h: Harness, state: str, signal: str) -> tuple[str, str]:
    if signal == "error":  # armed before the primitive starts; it fails half-way through
        h.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="LARM_JOINT2 beyond its limit")
    group, ids = await _enter(h, state)
    await h.until_state(group, state)
    if signal == "ok":
        for rid in ids:
            assert (await h.result(rid)).outcome == "succeeded"
    elif signal == "pause":
        await h.clock.sleep(0.3)
        assert (await h.service(group, "pause")).success
        await h.until_state(group, PAUSE)
    elif signal == "stop":
        await h.clock.sleep(0.3)
        assert (await h.service(group, "stop")).success
        result = await h.result(ids[0])
        assert result.outcome == "preempted"
    elif signal == "error":
        result = await h.result(ids[0])
        assert result.outcome == "aborted" and "LARM_JOINT2 beyond its limit" in (result.error or "")
    return group, state


async def _pause_row(h: Harness, signal: str) -> tuple[str, str]:
    if signal == "error":
        h.backend.fail_next("left_arm", FaultKind.CONNECTION, message="controller link lost", while_paused=True)
    group, ids = await _enter(h, "Motion")
    await h.until_state(group, "Motion")
    await h.clock.sleep(0.2)
    assert (await h.service(group, "pause")).success
    await h.until_state(group, PAUSE) if signal != "error" else None
    if signal == "resume":
        assert (await h.service(group, "resume")).success
        assert (await h.result(ids[0])).outcome == "succeeded"
    elif signal == "stop":
        assert (await h.service(group, "stop")).success
        assert (await h.result(ids[0])).outcome == "preempted"
    elif signal == "error":
        result = await h.result(ids[0])
        assert result.outcome == "aborted" and "controller link lost" in (result.error or "")
    return group, PAUSE


async def _control_row(h: Harness, state: str, signal: str) -> tuple[str, str]:
    group = "left_arm"
    if state == READY and signal == "end":
        h.end(group)
        await h.until_state(group, FINISH)
        return group, READY
    # Stop and ErrorHandling rows: stop a motion, then leave ErrorHandling by reset or end.
    _, ids = await _enter(h, "Motion")
    await h.until_state(group, "Motion")
    assert (await h.service(group, "stop")).success
    await h.until_state(group, ERROR_HANDLING)
    if state == ERROR_HANDLING and signal == "ok":
        assert (await h.service(group, "reset")).success
        await h.until_state(group, READY)
    elif state == ERROR_HANDLING and signal == "end":
        h.end(group)
        await h.until_state(group, FINISH)
    return group, state


@pytest.mark.parametrize(("state", "signal", "target"), ROWS, ids=[f"{s}--{g}-->{t}" for s, g, t in ROWS])
def test_row(run_sim: Any, state: str, signal: str, target: str) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[str, str, str]], str]:
        h = await Harness(clock).start()
        try:
            if state in WORKING_STATES:
                group, paused = await _working_row(h, state, signal)
            elif state == READY and signal != "end":
                working = next(w for w in WORKING_STATES if TABLE_2[READY][signal] == w)
                group, paused = await _working_row(h, working, "ok")
            elif state == PAUSE:
                group, paused = await _pause_row(h, signal)
            else:
                group, paused = await _control_row(h, state, signal)
            await clock.sleep(0.1)
            return h.transitions(group), paused
        finally:
            await h.close()

    transitions, context = run_sim(main)
    expected_target = "Motion" if target == HISTORY else target
    assert (state, signal, expected_target) in transitions, transitions
    # every transition the machine made is a row of the table (history resolved)
    for source, sig, dest in transitions:
        table_target = TABLE_2[source][sig]
        assert dest == table_target or table_target == HISTORY, (source, sig, dest)
