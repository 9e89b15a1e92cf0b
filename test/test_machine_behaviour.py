"""What an integrator relies on from a group machine, beyond the table itself."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from machine_harness import CELL, Harness
from scripted_backend import VISION_OFFSET

from core_functions.primitives import ExecuteTrajectory, MasterSlaveMove, MoveCartesian
from node_transport.clock import Clock
from execution_engine.machine.table import ERROR_HANDLING, FINISH, PAUSE, READY, TABLE_2
from node_transport import typed
from node_transport.qos import COMMANDS, LATCHED
from node_transport.wire import sm_topic


def test_structure_and_state_are_latched_for_late_viewers(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[Any]]:
        h = await Harness(clock).start()
        try:
            await clock.sleep(1.0)
            viewer = h.transport.create_node("late_viewer")
            got: dict[str, list[Any]] = {"structure": [], "state": []}
            viewer.create_subscription(typed.MachineStructureMsg, sm_topic("right_arm", "structure"), got["structure"].append, LATCHED)
            viewer.create_subscription(typed.MachineStateMsg, sm_topic("right_arm", "state"), got["state"].append, LATCHED)
            await clock.sleep(0.1)
            return got["structure"][0], got["state"]
        finally:
            await h.close()

    structure, states = run_sim(main)  # the typed messages a viewer (ros2 topic echo, Foxglove) reads
    assert structure.group == "right_arm" and structure.initial == READY
    assert set(structure.states) == set(TABLE_2) | {FINISH}
    rows = {(t.source, t.signal, t.target) for t in structure.transitions}
    assert rows == {(s, g, t) for s, row in TABLE_2.items() for g, t in row.items()}
    assert [(s.group, s.state) for s in states] == [("right_arm", READY)]
    assert states[0].header.stamp.sec > 1_600_000_000  # ROS time (since 1970), not run seconds


def test_request_while_busy_is_refused_and_the_running_function_is_untouched(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, int]:
        h = await Harness(clock).start()
        try:
            first = h.send("left_arm", "move_to_joint_pose", "initial")
            await h.until_state("left_arm", "Motion")
            second = h.send("left_arm", "gripper_open", operation="2")
            refused = await h.result(second)
            done = await h.result(first)
            return refused, done, len(h.backend.executed("left_arm"))
        finally:
            await h.close()

    refused, done, executed = run_sim(main)
    assert refused.outcome == "aborted" and "request refused" in refused.error and "Motion" in refused.error
    assert done.outcome == "succeeded"
    assert executed == 1


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (typed.MachineRequestMsg(id="x", kind="teleport", function="gripper_open"), "field 'kind': 'teleport' is not one of"),
        (typed.MachineRequestMsg(id=7, kind="execute", function="gripper_open"), "field 'id': expected a string"),
        (typed.MachineRequestMsg(id="x", kind="execute"), "an execute request needs a function"),
        (typed.MachineRequestMsg(id="x", kind="execute", function="gripper_open", params=(1,)), "field 'params[0]': expected a string"),
    ],
)
def test_garbage_requests_are_reported_and_change_nothing(run_sim: Any, raw: Any, expected: str) -> None:
    async def main(clock: Clock) -> tuple[list[dict[str, Any]], str, int]:
        h = await Harness(clock).start()
        try:
            h.send_raw("left_arm", raw)
            await clock.sleep(0.5)
            return h.events("left_arm", "error"), h.machines["left_arm"].state, len(h.backend.log)
        finally:
            await h.close()

    errors, state, executed = run_sim(main)
    assert len(errors) == 1 and expected in errors[0]["error"] and "/left_arm/sm/request" in errors[0]["error"]
    assert state == READY and executed == 0


@pytest.mark.parametrize(
    ("function", "params", "expected"),
    [
        ("debur_drill", ("hole_1",), "unknown function 'debur_drill' (did you mean 'debur_drilling'?)"),
        ("move_to_joint_pose", (), "takes 1 params, got 0"),
        ("set_speed", ("150%",), "above the maximum"),
        ("move_to", ("hole_9",), "unknown frame 'hole_9'"),
        ("full_body_move", ("nowhere",), "unknown joint pose 'nowhere'"),
    ],
)
def test_bad_calls_are_aborted_before_anything_moves(run_sim: Any, function: str, params: tuple[str, ...], expected: str) -> None:
    async def main(clock: Clock) -> tuple[Any, int, str]:
        h = await Harness(clock).start()
        try:
            result = await h.result(h.send("left_arm", function, *params))
            return result, len(h.backend.log), h.machines["left_arm"].state
        finally:
            await h.close()

    result, executed, state = run_sim(main)
    assert result.outcome == "aborted" and expected in result.error
    assert executed == 0 and state == READY


def test_pause_mid_primitive_then_resume_completes_the_same_primitive(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[Any], float, float]:
        h = await Harness(clock, durations={"move_joints": 4.0}).start()
        try:
            rid = h.send("left_arm", "move_to_joint_pose", "initial")
            await clock.sleep(1.0)
            assert (await h.service("left_arm", "pause")).success
            await h.until_state("left_arm", PAUSE)
            paused_at = clock.now()
            await clock.sleep(10.0)
            assert h.machines["left_arm"].state == PAUSE
            assert (await h.service("left_arm", "resume")).success
            result = await h.result(rid)
            return result, h.backend.executed("left_arm"), paused_at, clock.now()
        finally:
            await h.close()

    result, executed, paused_at, _ = run_sim(main)
    assert result.outcome == "succeeded"
    assert len(executed) == 1  # one primitive, not re-sent
    assert executed[0].t_end - executed[0].t_start == pytest.approx(14.0, abs=0.05)  # 4 s of motion + 10 s held
    assert result.t_end - result.t_start == pytest.approx(14.0, abs=0.05)


def test_pause_mid_skill_then_resume_runs_each_remaining_primitive_once_in_order(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], Any]:
        h = await Harness(clock, durations={"default": 1.0}).start()
        try:
            rid = h.send("left_arm", "debur_drilling", "hole_1")
            await h.until_state("left_arm", "Vision")
            assert (await h.service("left_arm", "pause")).success  # pauses the vision primitive
            await h.until_state("left_arm", PAUSE)
            await clock.sleep(5.0)
            assert (await h.service("left_arm", "resume")).success
            result = await h.result(rid)
            return h.backend.executed("left_arm"), result
        finally:
            await h.close()

    executed, result = run_sim(main)
    kinds = [e.kind for e in executed]
    # ... the last two: up to the clearance, then aside (the other arm works at this hole next)
    assert kinds == ["move_cartesian", "vision", "move_cartesian", "end_effector", "set_speed", "move_cartesian", "set_speed", "dwell", "move_cartesian", "end_effector", "move_cartesian", "move_cartesian"]
    assert result.outcome == "succeeded" and result.primitives == len(kinds)
    # the vision-corrected hole is used for every contact move after the vision step
    nominal = CELL.frames[0].pose
    contact = executed[5].primitive
    assert isinstance(contact, MoveCartesian)
    assert contact.target.x == pytest.approx(nominal.x + VISION_OFFSET) and contact.target.y == pytest.approx(nominal.y)


def test_pause_while_ready_holds_the_next_function_until_resume(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], Any, bool]:
        h = await Harness(clock).start()
        try:
            assert (await h.service("left_arm", "pause")).success
            again = (await h.service("left_arm", "pause")).success
            rid = h.send("left_arm", "gripper_open")
            await clock.sleep(20.0)
            held = list(h.backend.log)
            assert (await h.service("left_arm", "resume")).success
            return held, await h.result(rid), again
        finally:
            await h.close()

    held, result, paused_twice = run_sim(main)
    assert held == []  # accepted, but nothing moved while paused
    assert not paused_twice  # a second pause is refused: already holding
    assert result.outcome == "succeeded" and result.t_end >= 20.0


def test_stop_abandons_the_function_and_reset_brings_the_machine_back(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str], Any, str]:
        h = await Harness(clock).start()
        try:
            rid = h.send("left_arm", "debur_drilling", "hole_1")
            await h.until_state("left_arm", "Vision")
            assert (await h.service("left_arm", "stop")).success
            stopped = await h.result(rid)
            await h.until_state("left_arm", ERROR_HANDLING)
            refused = await h.result(h.send("left_arm", "gripper_open"))
            assert not (await h.service("left_arm", "resume")).success
            assert (await h.service("left_arm", "reset")).success
            await h.until_state("left_arm", READY)
            again = await h.result(h.send("left_arm", "gripper_open"))
            return stopped, [e.kind for e in h.backend.executed("left_arm")], refused, again.outcome
        finally:
            await h.close()

    stopped, kinds, refused, again = run_sim(main)
    assert stopped.outcome == "preempted" and "stopped by /left_arm/sm/stop" in stopped.error
    assert kinds == ["move_cartesian", "vision", "end_effector"]  # nothing after the stopped vision step
    assert refused.outcome == "aborted" and "reset it before new requests" in refused.error
    assert again == "succeeded"


def test_full_body_motion_waits_for_both_arms_and_moves_once(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, list[Any], float]:
        h = await Harness(clock, durations={"full_body_move": 3.0}).start()
        try:
            partners = ("left_arm", "right_arm")
            left = h.send("left_arm", "full_body_move", "initial", sync="fb", partners=partners)
            await clock.sleep(2.0)  # the right arm is late: the left arm waits at the barrier
            assert h.machines["left_arm"].state == "FullBodyMotion" and not h.backend.log
            right = h.send("right_arm", "full_body_move", "initial", sync="fb", partners=partners)
            results = await h.result(left), await h.result(right)
            return results[0], results[1], h.backend.log, clock.now()
        finally:
            await h.close()

    left, right, log, _ = run_sim(main)
    assert [(e.group, e.kind) for e in log] == [("left_arm", "full_body_move")]
    assert len(log[0].primitive.positions) == 15
    assert log[0].t_start == pytest.approx(2.0, abs=0.05)  # starts only when both are in FullBodyMotion
    assert left.outcome == right.outcome == "succeeded"
    assert right.t_end == pytest.approx(left.t_end, abs=0.05)  # the follower is done when the move is


def test_barrier_partner_that_never_comes_is_an_error(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, str]:
        h = await Harness(clock, parameters={"sync_timeout": 4.0}).start()
        try:
            rid = h.send("left_arm", "full_body_move", "initial", sync="fb", partners=("left_arm", "right_arm"))
            result = await h.result(rid)
            return result, h.machines["left_arm"].state
        finally:
            await h.close()

    result, state = run_sim(main)
    assert result.outcome == "aborted"
    assert "right_arm did not reach the FullBodyMotion barrier within 4 s" in result.error
    assert result.t_end == pytest.approx(4.0, abs=0.05)
    assert state == ERROR_HANDLING


def test_master_slave_sends_one_command_from_the_master(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], Any, Any]:
        h = await Harness(clock).start()
        try:
            partners = ("left_arm", "right_arm")
            master = h.send("left_arm", "master_move", "above", "right_arm", sync="ms", partners=partners)
            slave = h.send("right_arm", "slave_follow", "left_arm", sync="ms", partners=partners)
            return h.backend.log, await h.result(master), await h.result(slave)
        finally:
            await h.close()

    log, master, slave = run_sim(main)
    assert len(log) == 1 and log[0].group == "left_arm"
    move = log[0].primitive
    assert isinstance(move, MasterSlaveMove) and move.slave == "right_arm" and move.master_path == (CELL.frames[1].pose,)
    assert master.outcome == slave.outcome == "succeeded"


def test_taught_trajectory_is_stored_in_sqlite_and_replayed_by_a_new_machine(run_sim: Any, tmp_path: Path) -> None:
    db = str(tmp_path / "trajectories.sqlite")

    async def teach(clock: Clock) -> Any:
        h = await Harness(clock, parameters={"trajectory_db": db}).start()
        try:
            return await h.result(h.send("right_arm", "teach_trajectory", "wipe", "3s", "100ms"))
        finally:
            await h.close()

    async def replay(clock: Clock) -> tuple[Any, list[Any]]:
        h = await Harness(clock, parameters={"trajectory_db": db}).start()
        try:
            result = await h.result(h.send("right_arm", "execute_trajectory", "wipe"))
            missing = await h.result(h.send("right_arm", "execute_trajectory", "nothing_like_it"))
            return (result, missing), h.backend.log
        finally:
            await h.close()

    assert run_sim(teach).outcome == "succeeded"
    (result, missing), log = run_sim(replay)
    assert result.outcome == "succeeded"
    replayed = log[0].primitive
    assert isinstance(replayed, ExecuteTrajectory) and replayed.name == "wipe" and len(replayed.points) == 2
    assert missing.outcome == "aborted" and "no trajectory 'nothing_like_it' recorded for right_arm" in missing.error
    assert "wipe" in missing.error  # the message lists what is recorded


def test_a_bridge_that_never_answers_is_a_timeout_error(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, str]:
        h = await Harness(clock, parameters={"bridge_timeout": 2.0}).start()
        try:
            h.bridge.node.destroy()  # the bridge process died
            result = await h.result(h.send("left_arm", "gripper_open"))
            return result, h.machines["left_arm"].state
        finally:
            await h.close()

    result, state = run_sim(main)
    assert result.outcome == "aborted"
    assert "end_effector(gripper_open): timeout: no bridge subscribed to /left_arm/bridge/command" in result.error
    assert result.t_end == pytest.approx(2.0)
    assert state == ERROR_HANDLING


def test_a_fault_in_a_callback_puts_the_working_machine_in_error_handling(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[dict[str, Any]]]:
        h = await Harness(clock, durations={"move_joints": 5.0}).start()
        try:
            rid = h.send("left_arm", "move_to_joint_pose", "initial")
            await h.until_state("left_arm", "Motion")
            h.machines["left_arm"].node.report_fault("tcp_pose subscription", ValueError("NaN in pose"))
            return await h.result(rid), h.events("left_arm", "error")
        finally:
            await h.close()

    result, errors = run_sim(main)
    assert result.outcome == "aborted" and "tcp_pose subscription: ValueError: NaN in pose" in result.error
    assert errors and "NaN in pose" in errors[-1]["error"]


def test_status_events_carry_operation_function_and_primitive_index(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[dict[str, Any]]:
        h = await Harness(clock).start()
        try:
            await h.result(h.send("left_arm", "debur_drilling", "hole_1", operation="op7"))
            return h.status["left_arm"]
        finally:
            await h.close()

    events = run_sim(main)
    starts = [e for e in events if e["event"] == "primitive_start"]
    assert [e["index"] for e in starts] == list(range(1, 13))
    assert all(e["operation"] == "op7" and e["function"] == "debur_drilling" for e in events if e["event"] != "transition" or e["to"] != READY)
    end = [e for e in events if e["event"] == "function_end"][0]
    assert end["count"] == 12 and end["outcome"] == "succeeded"
    times = [e["t"] for e in events]
    assert times == sorted(times)
    json.dumps(events)


# ================================================================== lost commands (DDS start-up)
def test_a_lost_command_is_sent_again_with_its_id_and_run_once(run_sim: Any) -> None:
    """Over DDS a command can be lost before discovery matched; the machine sends it again, the
    bridge carries the id out once."""

    async def main(clock: Clock) -> tuple[Any, list[str], int]:
        h = await Harness(clock, parameters={"bridge_timeout": 2.0}).start()
        try:
            publisher = h.machines["left_arm"].ctx.pub.bridge
            sent: list[str] = []
            real_publish = publisher.publish

            def lossy(msg: Any) -> None:  # the first command never arrives, every copy is recorded
                sent.append(msg.id)
                if len(sent) > 1:
                    real_publish(msg)

            publisher.publish = lossy  # type: ignore[method-assign]
            result = await h.result(h.send("left_arm", "gripper_open"))
            return result, sent, len(h.backend.executed("left_arm"))
        finally:
            await h.close()

    result, sent, executed = run_sim(main)
    assert result.outcome == "succeeded"
    assert len(sent) == 2 and sent[0] == sent[1]  # the same id again, after resend_interval (0.5 s)
    assert executed == 1


def test_the_bridge_runs_a_repeated_command_id_once_and_repeats_its_answer(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[dict[str, Any]], int]:
        h = await Harness(clock).start()
        try:
            feedback: list[Any] = []
            h.engine.create_subscription(typed.BridgeFeedbackMsg, "left_arm/bridge/feedback", feedback.append, COMMANDS)
            commands = h.engine.create_publisher(typed.BridgeCommandMsg, "left_arm/bridge/command")
            command = typed.BridgeCommandMsg(id="dup-1", group="left_arm", op="execute", primitive_kind="end_effector", primitive_json='{"action":"gripper_open"}')
            commands.publish(command)
            await clock.sleep(2.0)
            commands.publish(command)  # the machine heard nothing and sends it again
            await clock.sleep(2.0)
            return feedback, len(h.backend.executed("left_arm"))
        finally:
            await h.close()

    feedback, executed = run_sim(main)
    assert executed == 1
    finals = [f for f in feedback if f.status == "done"]
    assert len(finals) == 2 and finals[0] == finals[1]  # the latest answer, repeated as it was
