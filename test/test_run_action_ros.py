"""RunApplication under rclpy: the engine serves the action with the built interface package's
classes (rosidl's ``RunApplication.Impl.SendGoalService`` and the rest), so ``ros2 action
send_goal`` reaches an engine started with ``ros2 run`` as it does one on ``--transport dds``.
On the fake rclpy, whose action classes are built from the same ``.action`` file as rosidl's."""
from __future__ import annotations

import asyncio
import threading
from typing import Any

import ros_fake_graph
import ros_fake_msgs
from crossing_cell import CROSSING, WAIT_OPERATION, CollisionWatch, start_nextage_cell
from rclpy_like import wait_done
from ros_fake_executor import FakeExecutor
from ros_fake_node import FakeNode
from ros_fake_qos import QoSProfile
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from test_ros_transport import BOUND, run_real, with_transport
from test_run_action import TINY

from cell_runner.libraries import APPLICATION_FUNCTIONS
from cell_runner.nodes import serve_goals
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.run_action import ACTION_NAME, GetResult, RunApplicationGoal, SendGoal
from node_transport.action import UUID, GoalStatus
from node_transport.ros import RosTransport
from node_transport.ros_convert import import_ros_type

BAD_APP = """<?xml version="1.0"?>
<application name="tiny" robot="nextage" version="1">
  <operation id="1" name="speeds"><left_arm><function name="set_sped"><params><param name="fraction" value="0.5"/></params></function></left_arm></operation>
</application>
"""


def test_an_actions_parts_resolve_to_rosidl_classes(fake_rclpy: Any) -> None:
    """Where rosidl keeps each part rcl_action puts on the wire: Goal on the class, the services
    and the feedback message in its Impl."""
    package = ros_fake_msgs.INTERFACE_MODULES["dual_arm_executive_interfaces.action"]["RunApplication"]
    base = "dual_arm_executive_interfaces/action/RunApplication"
    assert import_ros_type(f"{base}_Goal") is package.Goal
    assert import_ros_type(f"{base}_SendGoal") is package.Impl.SendGoalService
    assert import_ros_type(f"{base}_SendGoal_Request") is package.Impl.SendGoalService.Request
    assert import_ros_type(f"{base}_GetResult_Response") is package.Impl.GetResultService.Response
    assert import_ros_type(f"{base}_FeedbackMessage") is package.Impl.FeedbackMessage


def test_the_engine_under_rclpy_serves_run_application(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> tuple[Any, Any, bool, Any]:
        engine_node = transport.create_node("execution_engine")
        server = serve_goals(engine_node, ExecutionEngine(engine_node, APPLICATION_FUNCTIONS.catalog(None)))
        caller = transport.create_node("action_client")
        base = f"/{ACTION_NAME}/_action"
        send, result = caller.create_client(SendGoal, f"{base}/send_goal"), caller.create_client(GetResult, f"{base}/get_result")
        goal_id = UUID(tuple(range(16)))
        accepted = await send.call(SendGoal.Request(goal_id, RunApplicationGoal(application_xml=BAD_APP)), timeout=BOUND)
        answer = await result.call(GetResult.Request(goal_id), timeout=BOUND)
        empty = await send.call(SendGoal.Request(UUID(tuple([7] * 16)), RunApplicationGoal()), timeout=BOUND)
        # the service rclpy was given: rosidl's class of the action's SendGoal
        served = ros_fake_graph.GRAPH.services[f"{base}/send_goal"][0]
        return server, (accepted, answer), empty.accepted, served.srv_type

    server, (accepted, answer), empty_accepted, srv_type = run_real(lambda clock: with_transport(clock, body))
    assert server is not None
    assert srv_type is import_ros_type("dual_arm_executive_interfaces/action/RunApplication_SendGoal")
    assert accepted.accepted and accepted.stamp.sec > 1_600_000_000  # ROS time: epoch seconds
    assert answer.status == GoalStatus.STATUS_ABORTED and answer.result.outcome == "invalid" and "set_sped" in answer.result.report
    assert empty_accepted is False


def test_get_result_waits_for_the_run_however_long_not_the_handler_timeout(fake_rclpy: Any) -> None:
    """rclpy answers a request from its callback, so the transport bounds how long a handler may
    take (``handler_timeout``); get_result waits for the whole run on purpose and is exempt.  Here
    the run outlasts the bound: no machine answers within the engine's startup_timeout."""
    async def body(transport: RosTransport) -> tuple[Any, float]:
        engine_node = transport.create_node("execution_engine", parameters={"startup_timeout": 1.5})
        serve_goals(engine_node, ExecutionEngine(engine_node, APPLICATION_FUNCTIONS.catalog(None)))
        caller = transport.create_node("action_client")
        base = f"/{ACTION_NAME}/_action"
        send, result = caller.create_client(SendGoal, f"{base}/send_goal"), caller.create_client(GetResult, f"{base}/get_result")
        goal_id = UUID(tuple([3] * 16))
        assert (await send.call(SendGoal.Request(goal_id, RunApplicationGoal(application_xml=TINY)), timeout=BOUND)).accepted
        asked = transport.clock.now()
        answer = await result.call(GetResult.Request(goal_id), timeout=6 * BOUND)  # the engine waits for each group in turn
        return answer, transport.clock.now() - asked

    answer, waited = run_real(lambda clock: with_transport(clock, body, handler_timeout=0.5))
    assert waited > 0.5
    assert answer.status == GoalStatus.STATUS_ABORTED and "no group machine answered" in answer.result.report


# ====================================== rclpy's ActionClient against the engine, a whole cell over rclpy
def test_rclpy_sees_its_goal_run_cancels_it_and_the_next_goal_goes_back_safely_first(fake_rclpy: Any, tmp_path: Any, monkeypatch: Any) -> None:
    """Issue 20, 4 and 5(a), under (the fake) rclpy: ``ros2 action send_goal``'s client knows a goal
    from its goal response on and drops status entries of goals it does not know; it sees this
    goal EXECUTING (the status follows the answer), so its Ctrl-C cancels it.  The next goal starts
    from where the cancel left the robot -- the left hand in the middle -- and is brought back by
    the way the dry run proved, then runs: no two bodies ever touch on joint_states."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))  # the machines' default trajectory database
    action_type = ros_fake_msgs.INTERFACE_MODULES["dual_arm_executive_interfaces.action"]["RunApplication"]
    ActionClient = __import__("rclpy.action", fromlist=["ActionClient"]).ActionClient

    async def body(transport: RosTransport) -> tuple[Any, ...]:
        clock = transport.clock
        tasks = start_nextage_cell(transport, wait_for_goals=True)
        tool = FakeNode("ros2_action_send_goal")  # the ROS 2 tool: its own node and executor
        watch = CollisionWatch()
        tool.create_subscription(ros_fake_msgs.JointState, "/joint_states", watch, QoSProfile(depth=10))
        client = ActionClient(tool, action_type, f"/{ACTION_NAME}")
        executor = FakeExecutor()
        executor.add_node(tool)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            deadline = clock.now() + BOUND
            while not client.server_is_ready():
                assert clock.now() < deadline
                await clock.sleep(0.02)
            feedback: list[Any] = []
            first = await wait_done(clock, client.send_goal_async(action_type.Goal(application_xml=CROSSING), feedback.append), BOUND)
            result = first.get_result_async()
            deadline = clock.now() + 4 * BOUND
            while not any(f.feedback.operation_index == WAIT_OPERATION for f in feedback):
                assert clock.now() < deadline, "the run never reached its wait"
                await clock.sleep(0.02)
            seen = first.status
            cancelled = None
            if seen in (1, 2):  # ros2 action send_goal on Ctrl-C: cancel a goal it sees running
                cancelled = await wait_done(clock, first.cancel_goal_async(), BOUND)
            ended = await wait_done(clock, result, 4 * BOUND)
            second = await wait_done(clock, client.send_goal_async(action_type.Goal(application_xml=CROSSING)), BOUND)
            answer = await wait_done(clock, second.get_result_async(), 8 * BOUND)
            ours = {bytes(first.goal_id.uuid), bytes(second.goal_id.uuid)}
            # a goal that ended is forgotten, and later arrays still name it until its result expires: not a loss
            dropped = [entry for entry in client.ignored_status if entry[0] in ours and entry[1] in (1, 2, 3)]
            return seen, cancelled, ended, second.accepted, answer, first.statuses, dropped, watch
        finally:
            executor.shutdown()
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    seen, cancelled, ended, accepted, answer, statuses, dropped, watch = run_real(lambda clock: with_transport(clock, body))
    assert dropped == []  # no status of these goals went out before their goal response
    assert seen == GoalStatus.STATUS_EXECUTING and statuses[:1] in ([GoalStatus.STATUS_ACCEPTED], [GoalStatus.STATUS_EXECUTING])
    assert cancelled is not None and cancelled.return_code == 0
    assert ended.status == GoalStatus.STATUS_CANCELED and statuses[-1] == GoalStatus.STATUS_CANCELED
    assert accepted
    assert answer.status == GoalStatus.STATUS_SUCCEEDED, answer.result.report
    assert "the run starts with the way back" in answer.result.report and "application crossing: FINISHED" in answer.result.report
    assert watch.samples > 50 and watch.touching == []
