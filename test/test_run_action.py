"""The RunApplication action: a goal runs an application through the engine, feedback follows its
status, a cancel is the operator's stop, and a bad goal says why."""
from __future__ import annotations

import asyncio
from typing import Any

from app_builder import Cell

from execution_engine.clock import Clock
from execution_engine.engine.run_action import ACTION_NAME, GetResult, RunApplication, RunApplicationGoal, RunApplicationServer, SendGoal
from execution_engine.transport.action import UUID, CancelGoal, CancelGoalRequest, GoalInfo, GoalStatus, GoalStatusArray, STATUS_QOS
from execution_engine.transport.qos import COMMANDS

TINY = """<?xml version="1.0"?>
<application name="tiny" robot="nextage" version="1">
  <operation id="1" name="speeds"><left_arm><function name="set_speed"><params><param name="fraction" value="0.5"/></params></function></left_arm></operation>
  <operation id="2" name="move"><right_arm><function name="move_to_joint_pose"><params><param name="pose" value="initial"/></params></function></right_arm></operation>
</application>
"""


class Client:
    def __init__(self, cell: Cell) -> None:
        node = cell.deployment.transport.create_node("action_client")
        base = f"/{ACTION_NAME}/_action"
        self.send = node.create_client(SendGoal, f"{base}/send_goal")
        self.result = node.create_client(GetResult, f"{base}/get_result")
        self.cancel = node.create_client(CancelGoal, f"{base}/cancel_goal")
        self.feedback: list[Any] = []
        self.status: list[GoalStatusArray] = []
        node.create_subscription(RunApplication.FeedbackMessage, f"{base}/feedback", self.feedback.append, COMMANDS)
        node.create_subscription(GoalStatusArray, f"{base}/status", self.status.append, STATUS_QOS)

    async def goal(self, goal: RunApplicationGoal, number: int) -> tuple[bool, UUID]:
        goal_id = UUID(tuple([number] * 16))
        response = await self.send.call(SendGoal.Request(goal_id, goal), timeout=5.0)
        return response.accepted, goal_id


async def start(clock: Clock, **durations: float) -> tuple[Cell, Client]:
    cell = await Cell(clock, durations=durations).start()
    RunApplicationServer(cell.deployment.engine.node, cell.deployment.engine)
    return cell, Client(cell)


def test_a_goal_runs_the_application_with_feedback_and_a_result(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[bool, Any, Client]:
        cell, client = await start(clock, move_joints=2.0)
        try:
            accepted, goal_id = await client.goal(RunApplicationGoal(application_xml=TINY), 1)
            answer = await client.result.call(GetResult.Request(goal_id), timeout=60.0)
            return accepted, answer, client
        finally:
            await cell.deployment.close()

    accepted, answer, client = run_sim(main)
    assert accepted
    assert answer.status == GoalStatus.STATUS_SUCCEEDED and answer.result.outcome == "finished" and answer.result.ok
    assert "application tiny: FINISHED" in answer.result.report
    counts = {(f.feedback.operation_index, f.feedback.operation_count) for f in client.feedback}
    assert (1, 2) in counts or (0, 2) in counts
    right = [g for f in client.feedback for g in f.feedback.groups if g.group == "right_arm" and g.function == "move_to_joint_pose"]
    assert right, "feedback names each group's function"
    assert [s.status for s in client.status[-1].status_list] == [GoalStatus.STATUS_SUCCEEDED]


def test_a_cancel_stops_the_run_through_the_engine(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, Any, Cell]:
        cell, client = await start(clock, move_joints=30.0)
        try:
            _, goal_id = await client.goal(RunApplicationGoal(application_xml=TINY), 2)
            await clock.sleep(5.0)
            busy, _ = await client.goal(RunApplicationGoal(application_xml=TINY), 3)
            cancelled = await client.cancel.call(CancelGoalRequest(GoalInfo(goal_id)), timeout=5.0)
            answer = await client.result.call(GetResult.Request(goal_id), timeout=60.0)
            return busy, cancelled, answer, cell
        finally:
            await cell.deployment.close()

    busy, cancelled, answer, cell = run_sim(main)
    assert busy is False  # one run at a time
    assert cancelled.return_code == 0 and len(cancelled.goals_canceling) == 1
    assert answer.status == GoalStatus.STATUS_CANCELED and answer.result.outcome == "stopped" and not answer.result.ok
    moves = cell.backend.executed("right_arm")
    assert moves and moves[-1].outcome == "stopped" and moves[-1].t_end is not None and moves[-1].t_end < 30.0


def test_an_invalid_application_ends_the_goal_aborted_with_its_diagnostics(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        cell, client = await start(clock)
        try:
            _, goal_id = await client.goal(RunApplicationGoal(application_xml=TINY.replace("set_speed", "set_sped")), 4)
            wrong_backend, other_id = await client.goal(RunApplicationGoal(application_xml=TINY, backend="kuka-rsi"), 5)
            first = await client.result.call(GetResult.Request(goal_id), timeout=10.0)
            second = await client.result.call(GetResult.Request(other_id), timeout=10.0)
            empty = await client.goal(RunApplicationGoal(), 6)
            return first, second, empty
        finally:
            await cell.deployment.close()

    first, second, empty = run_sim(main)
    assert first.status == GoalStatus.STATUS_ABORTED and first.result.outcome == "invalid" and "set_sped" in first.result.report
    assert second.status == GoalStatus.STATUS_ABORTED and "runs the nextage-sim back end, not kuka-rsi" in second.result.report
    assert empty[0] is False
