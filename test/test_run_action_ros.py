"""RunApplication under rclpy: the engine serves the action with the built interface package's
classes (rosidl's ``RunApplication.Impl.SendGoalService`` and the rest), so ``ros2 action
send_goal`` reaches an engine started with ``ros2 run`` as it does one on ``--transport dds``.
On the fake rclpy, whose action classes are built from the same ``.action`` file as rosidl's."""
from __future__ import annotations

from typing import Any

import ros_fakes
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from test_ros_transport import BOUND, run_real, with_transport

from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.run_action import ACTION_NAME, GetResult, RunApplicationGoal, SendGoal
from execution_engine.nodes import serve_goals
from execution_engine.transport.action import UUID, GoalStatus
from execution_engine.transport.ros import RosTransport
from execution_engine.transport.ros_convert import import_ros_type

BAD_APP = """<?xml version="1.0"?>
<application name="tiny" robot="nextage" version="1">
  <operation id="1" name="speeds"><left_arm><function name="set_sped"><params><param name="fraction" value="0.5"/></params></function></left_arm></operation>
</application>
"""


def test_an_actions_parts_resolve_to_rosidl_classes(fake_rclpy: Any) -> None:
    """Where rosidl keeps each part rcl_action puts on the wire: Goal on the class, the services
    and the feedback message in its Impl."""
    package = ros_fakes.INTERFACE_MODULES["dual_arm_executive_interfaces.action"]["RunApplication"]
    base = "dual_arm_executive_interfaces/action/RunApplication"
    assert import_ros_type(f"{base}_Goal") is package.Goal
    assert import_ros_type(f"{base}_SendGoal") is package.Impl.SendGoalService
    assert import_ros_type(f"{base}_SendGoal_Request") is package.Impl.SendGoalService.Request
    assert import_ros_type(f"{base}_GetResult_Response") is package.Impl.GetResultService.Response
    assert import_ros_type(f"{base}_FeedbackMessage") is package.Impl.FeedbackMessage


def test_the_engine_under_rclpy_serves_run_application(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> tuple[Any, Any, bool, Any]:
        engine_node = transport.create_node("execution_engine")
        server = serve_goals(engine_node, ExecutionEngine(engine_node))
        caller = transport.create_node("action_client")
        base = f"/{ACTION_NAME}/_action"
        send, result = caller.create_client(SendGoal, f"{base}/send_goal"), caller.create_client(GetResult, f"{base}/get_result")
        goal_id = UUID(tuple(range(16)))
        accepted = await send.call(SendGoal.Request(goal_id, RunApplicationGoal(application_xml=BAD_APP)), timeout=BOUND)
        answer = await result.call(GetResult.Request(goal_id), timeout=BOUND)
        empty = await send.call(SendGoal.Request(UUID(tuple([7] * 16)), RunApplicationGoal()), timeout=BOUND)
        # the service rclpy was given: rosidl's class of the action's SendGoal
        served = ros_fakes.GRAPH.services[f"{base}/send_goal"][0]
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
    from test_run_action import TINY

    async def body(transport: RosTransport) -> tuple[Any, float]:
        engine_node = transport.create_node("execution_engine", parameters={"startup_timeout": 1.5})
        serve_goals(engine_node, ExecutionEngine(engine_node))
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
