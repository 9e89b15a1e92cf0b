"""The RunApplication action: a goal runs an application through the engine, feedback follows its
status, a cancel is the operator's stop, and a bad goal says why."""
from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from app_builder import Cell

from core_functions.robots import NEXTAGE_OPEN
from crossing_cell import COLLIDING, CROSSING, WAIT_OPERATION, CollisionWatch
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.cell_start import CellStarts
from execution_engine.engine.run_action import ACTION_NAME, GetResult, RunApplication, RunApplicationGoal, RunApplicationServer, SendGoal
from node_transport.action import UUID, CancelGoal, CancelGoalRequest, GoalInfo, GoalStatus, GoalStatusArray, STATUS_QOS
from node_transport.clock import Clock
from node_transport.msgs import JointState
from node_transport.qos import COMMANDS, SENSOR
from node_transport.wire import JOINT_STATES
from rclpy_like import RclpyLikeActionClient
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

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
            first = await client.result.call(GetResult.Request(goal_id), timeout=10.0)  # one goal at a time: the next once it ended
            wrong_backend, other_id = await client.goal(RunApplicationGoal(application_xml=TINY, backend="kuka-rsi"), 5)
            second = await client.result.call(GetResult.Request(other_id), timeout=10.0)
            empty = await client.goal(RunApplicationGoal(), 6)
            return first, second, empty
        finally:
            await cell.deployment.close()

    first, second, empty = run_sim(main)
    assert first.status == GoalStatus.STATUS_ABORTED and first.result.outcome == "invalid" and "set_sped" in first.result.report
    assert second.status == GoalStatus.STATUS_ABORTED and "runs the nextage-sim back end, not kuka-rsi" in second.result.report
    assert empty[0] is False


# ===================================================================== ROS 2 action protocol order
def test_a_client_that_learns_of_its_goal_from_the_answer_sees_it_run_and_can_cancel_it(run_sim: Any) -> None:
    """rclpy's ActionClient (and so ``ros2 action send_goal``) knows a goal from its goal response
    on and drops status entries of goals it does not know: the server answers first, then says
    ACCEPTED/EXECUTING, so the client sees the goal run, its Ctrl-C cancels it, the next goal runs."""
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell = await Cell(clock, durations={"move_joints": 30.0}).start()
        RunApplicationServer(cell.deployment.engine.node, cell.deployment.engine)
        client = RclpyLikeActionClient(cell.deployment.transport.create_node("ros2_action_send_goal"))
        try:
            first = await client.send_goal(RunApplicationGoal(application_xml=TINY), 1)
            assert first is not None
            await clock.sleep(5.0)  # the run is in its 30 s move
            seen_running = first.status
            cancelled = await client.cancel_if_active(first)  # Ctrl-C
            ended = await client.result(first)
            second = await client.send_goal(RunApplicationGoal(application_xml=TINY.replace("30", "3")), 2)
            assert second is not None
            finished = await client.result(second)
            await clock.sleep(0.5)
            return seen_running, cancelled, ended, first, second, finished, client.dropped
        finally:
            await cell.deployment.close()

    seen_running, cancelled, ended, first, second, finished, dropped = run_sim(main)
    assert seen_running == GoalStatus.STATUS_EXECUTING
    assert cancelled is not None and cancelled.return_code == 0 and len(cancelled.goals_canceling) == 1
    assert ended.status == GoalStatus.STATUS_CANCELED
    assert dropped == []  # no status went out before the goal's answer
    order = [GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING, GoalStatus.STATUS_CANCELED]
    assert first.statuses == sorted(first.statuses, key=order.index) and first.statuses[-1] == GoalStatus.STATUS_CANCELED
    assert GoalStatus.STATUS_EXECUTING in first.statuses
    assert finished.status == GoalStatus.STATUS_SUCCEEDED and finished.result.ok
    assert GoalStatus.STATUS_EXECUTING in second.statuses and second.statuses[-1] == GoalStatus.STATUS_SUCCEEDED


# ============================================== every goal checked from where the robot is (finding 4)
async def _nextage_goal_cell(clock: Clock) -> tuple[Any, Any, Any, Any]:
    """The Nextage simulator (collision check on), machines, and the engine serving goals as its
    process does: each goal's run checked from joint_states first (cell_runner/nodes.py)."""
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
    deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:"})
    engine = deployment.engine
    RunApplicationServer(engine.node, engine, CellStarts(engine.node, engine, ":memory:", engine.startup_timeout).run_goal)
    watch = CollisionWatch()
    node = deployment.transport.create_node("ros2_action_send_goal")
    node.create_subscription(JointState, JOINT_STATES, watch, SENSOR)
    return deployment, backend, RclpyLikeActionClient(node), watch


def test_after_a_cancelled_goal_the_next_one_goes_back_safely_first_and_never_crosses_the_hands(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        deployment, _, client, watch = await _nextage_goal_cell(clock)
        try:
            first = await client.send_goal(RunApplicationGoal(application_xml=CROSSING), 1)
            assert first is not None
            for _ in range(1200):  # until the feedback says the run is in its wait
                if any(f.operation_index == WAIT_OPERATION for f in first.feedback):
                    break
                await clock.sleep(0.05)
            await clock.sleep(1.0)
            await client.cancel_if_active(first)
            ended = await client.result(first)
            second = await client.send_goal(RunApplicationGoal(application_xml=CROSSING), 2)
            assert second is not None
            return ended, await client.result(second), watch
        finally:
            await deployment.close()

    ended, answer, watch = run_sim(main)
    assert ended.status == GoalStatus.STATUS_CANCELED and "operations: 3/5" in ended.result.report
    assert answer.status == GoalStatus.STATUS_SUCCEEDED and answer.result.outcome == "finished", answer.result.report
    report = answer.result.report
    assert "the robot is not where crossing starts" in report and "the run starts with the way back" in report
    assert "application crossing (way back): FINISHED" in report and "application crossing: FINISHED" in report
    assert watch.samples > 100 and watch.touching == []


def test_a_goal_whose_run_would_collide_is_aborted_with_the_findings_and_nothing_moves(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, Any]:
        deployment, backend, client, _ = await _nextage_goal_cell(clock)
        try:
            before = backend.joint_state()
            handle = await client.send_goal(RunApplicationGoal(application_xml=COLLIDING), 1)
            assert handle is not None
            return await client.result(handle), before, backend.joint_state()
        finally:
            await deployment.close()

    answer, before, after = run_sim(main)
    assert answer.status == GoalStatus.STATUS_ABORTED and answer.result.outcome == "refused" and not answer.result.ok
    lines = answer.result.report.splitlines()
    assert any(line.startswith(f"{Path.cwd() / 'goal.xml'}:4:") and "operation 1 left_arm move_to: collision:" in line for line in lines), lines
    assert lines[-1].endswith("not run: 2 problem(s) found by the dry run from where the robot is (/joint_states)")
    assert after == before
