"""The execution engine: the paper's coordination guarantee, error policies, operator control."""
from __future__ import annotations

import asyncio
from typing import Any

import pytest
from app_builder import Cell, make_app

from execution_engine.app_model.model import ErrorPolicy
from node_transport.clock import Clock
from node_transport import typed
from node_transport.msgs import Bool
from node_transport.qos import LATCHED
from node_transport.wire import ENGINE_STATUS, SAFETY_STOP
from robot_bridges.backend import FaultKind

THREE_OPS = [
    {"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("gripper_open",)},
    {"right_arm": ("move_to_joint_pose", "initial"), "left_arm": ("wait",)},
    {"left_arm": ("gripper_close",), "right_arm": ("set_speed", "0.5"), "torso_head": ("wait", "1.5s")},
]


def test_operations_run_in_order_groups_of_one_operation_concurrently(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 3.0, "end_effector": 1.0, "set_speed": 0.5}).start()
        return await cell.run(make_app(THREE_OPS)), cell

    report, cell = run_sim(main)
    assert report.ok and report.operations_done == 3
    left, right, torso = (cell.functions(g) for g in ("left_arm", "right_arm", "torso_head"))
    # operation 1: both arms start together; operation 2 starts only after the slower (3 s) one
    assert left[0][2] == pytest.approx(0.0) and right[0][2] == pytest.approx(0.0)
    op1_end = max(left[0][3], right[0][3])
    assert op1_end == pytest.approx(3.0, abs=0.05)
    assert right[1][0] == "2" and right[1][2] >= op1_end - 1e-9
    # the left arm sat operation 2 out: no function of operation 2 on it
    assert [f[0] for f in left] == ["1", "3"]
    assert left[1][2] >= right[1][3] - 1e-9  # operation 3 after operation 2 completed
    assert torso == [("3", "wait", pytest.approx(6.0, abs=0.05), pytest.approx(7.5, abs=0.05))]  # wait 1.5 s dwells
    assert report.group_busy["left_arm"] == pytest.approx(4.0, abs=0.05)
    assert report.total == pytest.approx(7.5, abs=0.05)


def test_abort_policy_pauses_the_others_then_stops_everything(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 4.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.25, message="LARM_JOINT1 = 61 deg beyond 60 deg")
        return await cell.run(make_app(THREE_OPS, ErrorPolicy(action="abort"))), cell

    report, cell = run_sim(main)
    assert report.outcome == "failed" and not report.ok
    assert report.operations_done == 0
    assert "left_arm: move_to_joint_pose failed" in report.message and "61 deg" in report.message
    assert [e.group for e in report.errors] == ["left_arm"]
    right_moves = cell.backend.executed("right_arm")
    assert len(right_moves) == 1  # operation 2 was never dispatched
    transitions = [(e["group"], e["from"], e["to"]) for e in cell.events if e["event"] == "transition"]
    assert ("left_arm", "Motion", "ErrorHandling") in transitions
    assert all(("", g) for g in ("left_arm", "right_arm", "torso_head"))
    assert report.finished_cleanly  # every machine reached Finish


def test_the_other_arm_is_paused_while_the_error_is_handled(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 4.0, "end_effector": 10.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.UNREACHABLE, after=0.25, message="no IK solution")
        ops = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("gripper_open",)}]
        return await cell.run(make_app(ops, ErrorPolicy(action="abort"))), cell

    report, cell = run_sim(main)
    right = [(e["from"], e["to"]) for e in cell.events if e["event"] == "transition" and e["group"] == "right_arm"]
    assert right[:4] == [("Ready", "EndEffector"), ("EndEffector", "Pause"), ("Pause", "Stop"), ("Stop", "ErrorHandling")]
    assert report.outcome == "failed"


def test_retry_policy_resends_the_function_and_the_run_finishes(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.TIMEOUT, after=0.5, message="controller did not answer")
        return await cell.run(make_app(THREE_OPS, ErrorPolicy(retries=2, action="abort"))), cell

    report, cell = run_sim(main)
    assert report.ok and report.operations_done == 3 and report.retries == 1
    assert len(report.errors) == 1 and report.errors[0].attempt == 1
    left_moves = [e for e in cell.backend.executed("left_arm") if e.kind == "move_joints"]
    assert [m.outcome for m in left_moves] == ["timeout", "done"]


def test_safe_pose_policy_sends_every_group_to_the_safe_pose(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 5.0}).start()
        for _ in range(2):  # the first attempt and the retry both fail
            cell.backend.fail_next("left_arm", FaultKind.TIMEOUT, after=0.5, message="controller did not answer")
        return await cell.run(make_app(THREE_OPS, ErrorPolicy(retries=1, action="safe_pose", safe_pose="off"))), cell

    report, cell = run_sim(main)
    assert report.outcome == "failed" and report.safe_pose == "off" and report.retries == 1
    assert [e.attempt for e in report.errors] == [1, 2]
    safe = [e for e in cell.backend.log if e.kind == "move_joints" and e.t_start >= report.errors[-1].t - 1e-9]
    assert {e.group for e in safe} == {"left_arm", "right_arm", "torso_head"}
    assert all(e.outcome == "done" for e in safe)
    off = cell.robot.poses["off"]
    for move in safe:
        assert move.primitive.positions == tuple(off[j] for j in move.primitive.joint_names)
    assert report.finished_cleanly


def test_retry_resumes_the_paused_arm_which_finishes_its_own_motion(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 5.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.TIMEOUT, after=0.5, message="controller did not answer")
        return await cell.run(make_app(THREE_OPS, ErrorPolicy(retries=1))), cell

    report, cell = run_sim(main)
    assert report.ok and report.retries == 1
    gripper = cell.backend.executed("right_arm")[0]
    assert gripper.kind == "end_effector" and gripper.outcome == "done"
    # paused from the failure (1 s) until the retry had been sent; executed exactly once
    assert len([e for e in cell.backend.executed("right_arm") if e.kind == "end_effector"]) == 1


def test_alarm_waits_for_an_operator_reset_then_retries(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str], Any]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.COLLISION, after=0.5, message="contact with fixture")
        task = asyncio.ensure_future(cell.run(make_app(THREE_OPS, ErrorPolicy(action="alarm"))))
        await clock.sleep(60.0)  # nobody comes for a minute: the cell stays in alarm
        states = [s["state"] for s in cell.engine_states]
        early_resume = await cell.operator("resume")
        assert (await cell.operator("reset")).success
        return await task, states, early_resume

    report, states, early_resume = run_sim(main)
    assert states[-1] == "alarm"
    assert not early_resume.success and "reset" in early_resume.message
    assert report.ok and report.retries == 1
    assert report.total > 60.0


def test_operator_pause_holds_every_group_and_resume_finishes_the_same_motions(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell, list[str]]:
        cell = await Cell(clock, durations={"move_joints": 3.0, "end_effector": 3.0}).start()
        task = asyncio.ensure_future(cell.run(make_app(THREE_OPS)))
        await clock.sleep(1.0)
        assert (await cell.operator("pause")).success
        await clock.sleep(0.1)
        paused = [m.state for m in cell.deployment.machines.values()]
        await clock.sleep(20.0)
        assert (await cell.operator("resume")).success
        return await task, cell, paused

    report, cell, paused = run_sim(main)
    assert paused[:2] == ["Pause", "Pause"]
    assert report.ok
    # op 1: 3 s of motion + 20 s held; op 2: 3 s; op 3: the 3 s gripper is the longest
    assert report.total == pytest.approx(3.0 + 20.0 + 3.0 + 3.0, abs=0.3)
    first = cell.backend.executed("left_arm")[0]
    assert first.t_end - first.t_start == pytest.approx(23.0, abs=0.2)  # one motion, held 20 s


def test_operator_stop_ends_the_run_as_stopped_with_every_machine_in_finish(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 3.0}).start()
        task = asyncio.ensure_future(cell.run(make_app(THREE_OPS)))
        await clock.sleep(1.0)
        assert (await cell.operator("stop")).success
        return await task, cell

    report, cell = run_sim(main)
    assert report.outcome == "stopped" and "stopped by service /execution_engine/stop" in report.message
    assert report.finished_cleanly
    left = [(e["from"], e["to"]) for e in cell.events if e["event"] == "transition" and e["group"] == "left_arm"]
    assert left == [("Ready", "Motion"), ("Motion", "Stop"), ("Stop", "ErrorHandling"), ("ErrorHandling", "Finish")]


def test_step_runs_one_operation_then_pauses(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[int, int, Any]:
        cell = await Cell(clock, engine_parameters={"autostart": False}).start()
        task = asyncio.ensure_future(cell.run(make_app(THREE_OPS)))
        await clock.sleep(5.0)
        before = cell.deployment.engine.report.operations_done
        assert (await cell.operator("step")).success
        await clock.sleep(30.0)
        after_step = cell.deployment.engine.report.operations_done
        assert cell.deployment.engine.state == "paused"
        assert (await cell.operator("resume")).success
        return before, after_step, await task

    before, after_step, report = run_sim(main)
    assert (before, after_step) == (0, 1)
    assert report.ok and report.operations_done == 3


def test_safety_stop_pauses_and_only_an_operator_resumes(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, list[str]]:
        cell = await Cell(clock, durations={"move_joints": 3.0, "end_effector": 3.0}).start()
        safety = cell.node.create_publisher(Bool, SAFETY_STOP, LATCHED)
        task = asyncio.ensure_future(cell.run(make_app(THREE_OPS)))
        await clock.sleep(1.0)
        safety.publish(Bool(True))
        await clock.sleep(2.0)
        states = [m.state for m in cell.deployment.machines.values()]
        refused = await cell.operator("resume")
        safety.publish(Bool(False))
        await clock.sleep(10.0)
        states += [cell.deployment.engine.state]
        assert (await cell.operator("resume")).success
        return await task, refused, states

    report, refused, states = run_sim(main)
    assert states[:2] == ["Pause", "Pause"] and states[-1] == "paused"  # clearing the sensor does not restart motion
    assert not refused.success and "safety stop is still active" in refused.message
    assert report.ok


def test_missing_machine_fails_the_start_with_a_clear_message(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        cell = await Cell(clock, engine_parameters={"startup_timeout": 3.0}).start()
        cell.deployment.tasks[1].cancel()  # the right_arm machine never ran
        cell.deployment.machines["right_arm"].node.destroy()
        return await cell.run(make_app(THREE_OPS))

    report = run_sim(main)
    assert report.outcome == "failed"
    assert "no group machine answered for right_arm within 3 s" in report.message


def test_synchronised_full_body_move_is_dispatched_with_partners(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"full_body_move": 4.0}).start()
        ops = [{"left_arm": ("full_body_move", "initial"), "right_arm": ("full_body_move", "initial"), "torso_head": ("full_body_move", "initial")}]
        return await cell.run(make_app(ops)), cell

    report, cell = run_sim(main)
    assert report.ok
    assert [(e.group, e.kind) for e in cell.backend.log] == [("left_arm", "full_body_move")]
    ends = {g: cell.functions(g)[0][3] for g in ("left_arm", "right_arm", "torso_head")}
    assert max(ends.values()) - min(ends.values()) < 0.05


def test_a_long_lived_engine_runs_one_application_after_another(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any]:
        cell = await Cell(clock, durations={"move_joints": 3.0}).start()
        engine = cell.deployment.engine
        first = asyncio.ensure_future(engine.run(make_app(THREE_OPS)))
        await clock.sleep(1.0)
        assert (await cell.operator("stop")).success
        stopped = await first
        second = await engine.run(make_app(THREE_OPS))  # the machines restart from Finish; no stop carries over
        await cell.deployment.close()
        return stopped, second

    stopped, second = run_sim(main)
    assert stopped.outcome == "stopped"
    assert second.ok and second.operations_done == 3 and not second.errors


def test_a_tool_that_connects_after_the_run_still_sees_how_it_ended(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[Any]:
        cell = await Cell(clock).start()
        await cell.deployment.engine.run(make_app(THREE_OPS[:1]))
        late: list[Any] = []
        viewer = cell.deployment.transport.create_node("late_viewer")
        viewer.create_subscription(typed.EngineStatusMsg, ENGINE_STATUS, late.append, LATCHED)
        await clock.sleep(0.1)
        await cell.deployment.close()
        return late

    late = run_sim(main)
    assert [s.state for s in late] == ["finished"] and late[0].operation_index == 1 == late[0].operation_count
    assert [(g.group, g.state) for g in late[0].groups] == [("left_arm", "Finish"), ("right_arm", "Finish"), ("torso_head", "Finish")]
