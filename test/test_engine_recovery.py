"""Recovery an operator can trust: retry what a second try can cure, and a safe pose that is safe.

A fault's kind travels from the bridge through the machine's result to the engine; the engine
retries timeouts and vision failures, never an unreachable target, a joint limit or a collision;
the way to the safe pose backs each working arm out along its tool axis, slows down, then moves,
and the report says how each step went.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from app_builder import Cell, make_app
from machine_harness import Harness

from app_functions.registry import full_catalog
from core_functions.primitives import MoveJoints, MoveRelative, SetSpeed
from execution_engine.app_model import load_application, validate_application
from execution_engine.app_model.model import ErrorPolicy
from node_transport.clock import Clock
from execution_engine.engine.faults import RETRY_TABLE, verdict
from node_transport.wire import FaultKind

ARMS_BUSY = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("gripper_open",)}, {"left_arm": ("gripper_close",)}]


# ------------------------------------------------------------------------ the fault's kind
def test_the_machine_result_carries_the_bridge_fault_kind(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any]:
        bench = await Harness(clock).start()
        bench.backend.fail_next("left_arm", FaultKind.COLLISION, message="contact with the fixture")
        collided = await bench.result(bench.send("left_arm", "move_to_joint_pose", "initial"))
        await bench.until_state("left_arm", "ErrorHandling")
        await bench.service("left_arm", "reset")
        await bench.until_state("left_arm", "Ready")
        missing = await bench.result(bench.send("left_arm", "execute_trajectory", "never_recorded"))
        await bench.close()
        return collided, missing

    collided, missing = run_sim(main)
    assert collided.outcome == "aborted" and collided.fault is FaultKind.COLLISION
    assert missing.outcome == "aborted" and missing.fault is FaultKind.SKILL  # the skill's own code raised


def test_a_bridge_that_does_not_finish_in_time_is_a_timeout(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        bench = await Harness(clock, durations={"move_joints": 30.0}, parameters={"primitive_timeout": 2.0}).start()
        result = await bench.result(bench.send("left_arm", "move_to_joint_pose", "initial"))
        await bench.close()
        return result

    result = run_sim(main)
    assert result.fault is FaultKind.TIMEOUT and "did not finish" in (result.error or "")


def test_only_faults_a_second_try_can_cure_are_retryable() -> None:
    assert set(RETRY_TABLE) == set(FaultKind)
    assert {k for k, r in RETRY_TABLE.items() if r.retryable} == {FaultKind.TIMEOUT, FaultKind.CONNECTION, FaultKind.VISION, FaultKind.BUSY}
    assert verdict([FaultKind.TIMEOUT, FaultKind.JOINT_LIMIT]) == (False, "joint_limit is deterministic")  # partners: all must be
    assert verdict([None])[0] is False  # a fault without a kind is not trusted with a retry


# ------------------------------------------------------------------------------ retrying
def run_failing_once(run_sim: Any, kind: FaultKind, policy: ErrorPolicy) -> tuple[Any, Cell, list[str]]:
    """The left arm's first move fails with ``kind``: (report, cell, the outcome of each of its moves)."""

    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.backend.fail_next("left_arm", kind, after=0.5, message=f"a {kind.value} fault")
        return await cell.run(make_app(ARMS_BUSY, policy)), cell

    report, cell = run_sim(main)
    return report, cell, [m.outcome for m in cell.backend.executed("left_arm") if m.kind == "move_joints"]


@pytest.mark.parametrize("kind", [FaultKind.UNREACHABLE, FaultKind.JOINT_LIMIT, FaultKind.COLLISION])
def test_a_deterministic_fault_is_not_retried(run_sim: Any, kind: FaultKind) -> None:
    report, cell, moves = run_failing_once(run_sim, kind, ErrorPolicy(retries=3, action="abort"))
    assert report.outcome == "failed" and report.retries == 0
    assert moves == [kind.value]  # tried once
    assert report.errors[0].fault == kind.value
    assert report.errors[0].recovery.startswith(f"not retried: {kind.value} is deterministic")
    assert any(f"not retried: {kind.value} is deterministic" in line for line in report.summary_lines())
    console = [s["message"] for s in cell.engine_states if s["state"] == "error"]  # what the live console prints
    assert console and f"not retried: {kind.value} is deterministic" in console[0]


@pytest.mark.parametrize("kind", [FaultKind.TIMEOUT, FaultKind.VISION])
def test_a_transient_fault_is_retried_and_the_run_finishes(run_sim: Any, kind: FaultKind) -> None:
    report, _, moves = run_failing_once(run_sim, kind, ErrorPolicy(retries=2, action="abort"))
    assert report.ok and report.retries == 1
    assert moves == [kind.value, "done"]
    assert report.errors[0].recovery.startswith(f"retrying (attempt 2 of 3): {kind.value}")


def test_a_synchronised_partner_reports_the_leaders_fault_and_neither_is_retried(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"full_body_move": 4.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="CHEST_JOINT0 beyond its limit")
        ops = [{g: ("full_body_move", "initial") for g in ("left_arm", "right_arm", "torso_head")}]
        return await cell.run(make_app(ops, ErrorPolicy(retries=2, action="abort"))), cell

    report, cell = run_sim(main)
    assert report.outcome == "failed" and report.retries == 0
    assert [e.kind for e in cell.backend.log] == ["full_body_move"]  # the leader's one command, not sent again
    assert report.errors[0].fault == "joint_limit" and report.errors[0].recovery.startswith("not retried: joint_limit")


def test_an_alarm_comes_at_once_after_a_deterministic_fault_and_a_reset_retries(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str]]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        run = clock.loop.create_task(cell.run(make_app(ARMS_BUSY, ErrorPolicy(retries=5, action="alarm"))))
        await clock.sleep(10.0)
        states = [s["state"] for s in cell.engine_states]
        assert (await cell.operator("reset")).success  # the operator fixed the cause
        return await run, states

    report, states = run_sim(main)
    assert states[-1] == "alarm" and report.ok and report.retries == 1
    assert report.errors[0].recovery == "not retried: joint_limit is deterministic; alarm reset by an operator: retried"


# ----------------------------------------------------------------------------- safe pose
def safe_pose_moves(cell: Cell, report: Any) -> dict[str, list[Any]]:
    after = report.errors[-1].t - 1e-9
    moves: dict[str, list[Any]] = {}
    for entry in cell.backend.log:
        if entry.t_start >= after:
            moves.setdefault(entry.group, []).append(entry)
    return moves


def test_the_safe_pose_is_a_retreat_along_the_tool_then_the_safe_speed_then_the_move(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 5.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        policy = ErrorPolicy(retries=1, action="safe_pose", safe_pose="off", safe_speed=0.4, retreat=0.03)
        return await cell.run(make_app(ARMS_BUSY, policy)), cell

    report, cell = run_sim(main)
    moves = safe_pose_moves(cell, report)
    off = cell.robot.poses["off"]
    for arm in ("left_arm", "right_arm"):  # both were working: the left arm failed, the right one was stopped
        retreat, speed, move = (m.primitive for m in moves[arm])
        assert isinstance(retreat, MoveRelative) and retreat.reference == "tool" and retreat.interpolation == "linear"
        assert (retreat.delta.x, retreat.delta.y, retreat.delta.z) == pytest.approx((0.0, 0.0, -0.03))
        assert speed == SetSpeed(0.4)
        assert isinstance(move, MoveJoints) and move.positions == tuple(off[j] for j in move.joint_names)
    assert [type(m.primitive) for m in moves["torso_head"]] == [SetSpeed, MoveJoints]  # no tool to retreat
    assert max(m.t_end for g in moves for m in moves[g] if m.kind == "move_relative") <= min(m.t_start for g in moves for m in moves[g] if m.kind == "set_speed")
    assert all(m.outcome == "done" for g in moves for m in moves[g])
    steps = [(s.group, s.step, s.outcome) for s in report.safe_pose_steps]
    assert ("left_arm", "retreat", "done") in steps and ("torso_head", "move", "done") in steps
    assert "  robot at safe pose 'off'" in report.summary_lines()


def test_an_arm_that_had_finished_its_function_does_not_retreat(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 1.0, "end_effector": 4.0}).start()
        cell.backend.fail_next("right_arm", FaultKind.COLLISION, after=0.75, message="finger hit the tray")
        return await cell.run(make_app(ARMS_BUSY, ErrorPolicy(action="safe_pose", safe_pose="off"))), cell

    report, cell = run_sim(main)
    moves = safe_pose_moves(cell, report)
    assert [m.kind for m in moves["left_arm"]] == ["set_speed", "move_joints"]
    assert [m.kind for m in moves["right_arm"]] == ["move_relative", "set_speed", "move_joints"]
    assert moves["right_arm"][0].primitive.delta.z == pytest.approx(-0.05) and moves["right_arm"][1].primitive == SetSpeed(0.3)  # defaults
    skipped = [s for s in report.safe_pose_steps if s.group == "left_arm" and s.step == "retreat"]
    assert skipped[0].outcome == "skipped" and "not working" in skipped[0].detail


def run_with_a_failed_retreat(run_sim: Any, kind: FaultKind, message: str) -> tuple[Any, list[tuple[str, str]]]:
    """The left arm fails, then its retreat fails with ``kind``: (report, the left arm's safe-pose primitives)."""

    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 5.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        cell.backend.fail_next("left_arm", kind, after=0.5, message=message, on="move_relative")
        return await cell.run(make_app(ARMS_BUSY, ErrorPolicy(action="safe_pose", safe_pose="off"))), cell

    report, cell = run_sim(main)
    return report, [(m.kind, m.outcome) for m in safe_pose_moves(cell, report)["left_arm"]]


def test_a_retreat_that_is_out_of_reach_is_skipped_and_the_arm_still_goes_to_the_safe_pose(run_sim: Any) -> None:
    report, left_moves = run_with_a_failed_retreat(run_sim, FaultKind.UNREACHABLE, "no IK for the retreat")
    assert left_moves == [("move_relative", "unreachable"), ("set_speed", "done"), ("move_joints", "done")]
    left = {s.step: s for s in report.safe_pose_steps if s.group == "left_arm"}
    assert left["retreat"].outcome == "skipped" and "no IK for the retreat" in left["retreat"].detail
    assert left["move"].outcome == "done" and "  robot at safe pose 'off'" in report.summary_lines()


def test_a_collision_while_retreating_leaves_the_arm_and_the_report_does_not_claim_the_safe_pose(run_sim: Any) -> None:
    report, left_moves = run_with_a_failed_retreat(run_sim, FaultKind.COLLISION, "hit the part backing out")
    assert left_moves == [("move_relative", "collision")]  # nothing after the collision
    assert report.safe_pose_missed == ["left_arm"]
    lines = report.summary_lines()
    assert "  safe pose 'off' NOT reached by left_arm" in lines and not any("robot at safe pose" in line for line in lines)
    assert any("left_arm     retreat  failed" in line and "the arm stays where it is" in line for line in lines)


def test_a_failed_move_to_the_safe_pose_is_reported_as_failed(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Cell]:
        cell = await Cell(clock, durations={"move_joints": 2.0, "end_effector": 5.0}).start()
        cell.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, after=0.5, message="limit")
        cell.backend.fail_next("torso_head", FaultKind.CONTROLLER, after=0.5, message="drive fault", on="move_joints")
        return await cell.run(make_app(ARMS_BUSY, ErrorPolicy(action="safe_pose", safe_pose="off"))), cell

    report, _ = run_sim(main)
    assert report.safe_pose_missed == ["torso_head"]
    assert "  safe pose 'off' NOT reached by torso_head" in report.summary_lines()
    torso = [s for s in report.safe_pose_steps if s.group == "torso_head" and s.step == "move"]
    assert torso[0].outcome == "failed" and "drive fault" in torso[0].detail


# ------------------------------------------------------------------ the XML attributes
def test_error_policy_reads_safe_speed_and_retreat_with_defaults_and_ranges(tmp_path: Path) -> None:
    def app(policy: str) -> Path:
        path = tmp_path / "app.xml"
        path.write_text(
            f'<application name="a" robot="nextage">{policy}<operation id="1"><left_arm><function name="gripper_open"/></left_arm></operation></application>',
            encoding="utf-8",
        )
        return path

    catalog = full_catalog()
    given = load_application(app('<error_policy action="safe_pose" safe_speed="0.5" retreat="0.02"/>'), catalog).error_policy
    assert (given.safe_speed, given.retreat) == (0.5, 0.02)
    default = load_application(app('<error_policy action="safe_pose"/>'), catalog).error_policy
    assert (default.safe_speed, default.retreat) == (0.3, 0.05)
    problems = [str(d) for d in validate_application(app('<error_policy safe_speed="30%" retreat="1"/>'), catalog)]
    assert any("safe_speed" in p for p in problems) and any("retreat" in p for p in problems)
