"""The bridge's stop under rclpy (the fake rclpy, its control_msgs built from the interface files): rclpy's own
ActionClient, in a node and executor of its own, has a goal running and its result asked for when the bridge node
stops; the result reaches it (ABORTED, "shutting down") before the node's services go, and the stop leaves
nothing of the bridge running on the loop.  No wall-clock assert: what is answered and what is left."""
from __future__ import annotations

import asyncio
import threading
from typing import Any

import ros_fake_msgs
from fjt_client import NEXTAGE, start_bridge
from ros_fake_executor import FakeExecutor
from ros_fake_node import FakeNode
from ros_fake_qos import QoSProfile
from rclpy_like import wait_done
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from test_ros_transport import run_real, with_transport

from node_transport.action import GoalStatus
from node_transport.ros import RosTransport

BOUND = 20.0
ACTION = f"/{NEXTAGE.controller}/follow_joint_trajectory"


def test_a_running_goals_rclpy_client_hears_its_end_when_the_bridge_stops(fake_rclpy: Any) -> None:
    action_type = ros_fake_msgs.INTERFACE_MODULES["control_msgs.action"]["FollowJointTrajectory"]
    trajectory_msgs = ros_fake_msgs.INTERFACE_MODULES["trajectory_msgs.msg"]
    Duration = ros_fake_msgs.INTERFACE_MODULES["builtin_interfaces.msg"]["Duration"]
    ActionClient = __import__("rclpy.action", fromlist=["ActionClient"]).ActionClient

    async def body(transport: RosTransport) -> tuple[Any, list[asyncio.Task[Any]]]:
        clock = transport.clock
        bridge = await start_bridge(NEXTAGE, transport.create_node("nextage_bridge"), clock, real_time=True)
        tool = FakeNode("moveit_simple_controller_manager")
        states: list[Any] = []
        tool.create_subscription(ros_fake_msgs.JointState, "/joint_states", states.append, QoSProfile(depth=10))
        client = ActionClient(tool, action_type, ACTION)
        executor = FakeExecutor()
        executor.add_node(tool)
        threading.Thread(target=executor.spin, daemon=True).start()
        try:
            deadline = clock.now() + BOUND
            while not client.server_is_ready() or not states:
                assert clock.now() < deadline
                await clock.sleep(0.02)
            names = list(NEXTAGE.joints)
            here = dict(zip(states[-1].name, states[-1].position))
            far = [v - 0.3 * (j == 0) for j, v in enumerate(here[n] for n in names)]
            goal = action_type.Goal(trajectory=trajectory_msgs["JointTrajectory"](joint_names=names, points=[
                trajectory_msgs["JointTrajectoryPoint"](positions=far, time_from_start=Duration(sec=5, nanosec=0))]))
            running = await wait_done(clock, client.send_goal_async(goal), BOUND)
            result = running.get_result_async()
            await clock.sleep(0.3)
            ours = asyncio.current_task()
            before = {t for t in asyncio.all_tasks() if t is not ours}
            await bridge.close()
            answer = await wait_done(clock, result, BOUND)
            bridges = ("nextage_bridge", "follow_joint_trajectory")  # the bridge node's tasks, and its action's
            left = [t for t in asyncio.all_tasks() if t is not ours and not t.done() and (t not in before or any(b in repr(t) for b in bridges))]
            return answer, left
        finally:
            executor.shutdown()

    answer, left = run_real(lambda clock: with_transport(clock, body))
    assert answer.status == GoalStatus.STATUS_ABORTED
    assert "shutting down" in answer.result.error_string
    assert left == []
