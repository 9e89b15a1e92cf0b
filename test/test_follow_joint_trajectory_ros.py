"""FollowJointTrajectory under rclpy (issue 23, item 1): each bridge (the Nextage simulator's, the V+ simulator's,
the KUKA RSI simulator's, its KR C4 on the wall clock) on the ros transport serves the action with control_msgs' classes (rosidl's ``FollowJointTrajectory.Impl.SendGoalService`` and
the rest), and rclpy's own ActionClient -- what MoveIt 2's simple controller manager uses -- in a node and
executor of its own moves the arm, is refused with the right error codes, and cancels.  On the fake rclpy,
whose control_msgs and trajectory_msgs classes are built from the same interface files as rosidl's."""
from __future__ import annotations

import sys
import threading
from typing import Any

import pytest
import ros_fake_graph
import ros_fake_msgs
from fjt_client import FJT, KINDS, NEXTAGE, start_bridge
from ros_fake_executor import FakeExecutor
from ros_fake_node import FakeNode
from ros_fake_qos import QoSProfile
from rclpy_like import wait_done
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from test_ros_transport import run_real, with_transport

from node_transport.action import GoalStatus
from node_transport.ros import RosTransport
from node_transport.ros_convert import import_ros_type

BOUND = 20.0
ACTION = "/left_arm_controller/follow_joint_trajectory"


@pytest.mark.parametrize("name", sorted(KINDS))
def test_rclpy_moves_each_arm_is_refused_with_error_codes_and_cancels(name: str, fake_rclpy: Any) -> None:
    kind = KINDS[name]
    action = f"/{kind.controller}/follow_joint_trajectory"
    action_type = ros_fake_msgs.INTERFACE_MODULES["control_msgs.action"]["FollowJointTrajectory"]
    trajectory_msgs = ros_fake_msgs.INTERFACE_MODULES["trajectory_msgs.msg"]
    Duration = ros_fake_msgs.INTERFACE_MODULES["builtin_interfaces.msg"]["Duration"]
    ActionClient = __import__("rclpy.action", fromlist=["ActionClient"]).ActionClient

    def goal(names: list[str], points: list[tuple[float, list[float]]]) -> Any:
        return action_type.Goal(trajectory=trajectory_msgs["JointTrajectory"](joint_names=names, points=[
            trajectory_msgs["JointTrajectoryPoint"](positions=p, time_from_start=Duration(sec=int(t), nanosec=int(round(t % 1 * 1e9))))
            for t, p in points
        ]))

    async def body(transport: RosTransport) -> tuple[Any, ...]:
        clock = transport.clock
        bridge = await start_bridge(kind, transport.create_node(f"{name}_bridge"), clock, real_time=True)
        tool = FakeNode("moveit_simple_controller_manager")  # rclpy's side: its own node and executor
        states: list[Any] = []
        tool.create_subscription(ros_fake_msgs.JointState, "/joint_states", states.append, QoSProfile(depth=10))
        client = ActionClient(tool, action_type, action)
        executor = FakeExecutor()
        executor.add_node(tool)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            deadline = clock.now() + BOUND
            while not client.server_is_ready() or not states:
                assert clock.now() < deadline
                await clock.sleep(0.02)
            names = list(kind.joints)
            here = dict(zip(states[-1].name, states[-1].position))
            start = [here[n] for n in names]
            points = [(0.5 * (k + 1), [v + 0.05 * (k + 1) * (j == 0) for j, v in enumerate(start)]) for k in range(3)]
            moved = await wait_done(clock, client.send_goal_async(goal(names, points)), BOUND)
            done = await wait_done(clock, moved.get_result_async(), BOUND)
            await clock.sleep(0.2)
            reached = dict(zip(states[-1].name, states[-1].position))[names[0]]
            unknown = await wait_done(clock, client.send_goal_async(goal([*names[:-1], "not_a_joint"], points[:1])), BOUND)
            refused = await wait_done(clock, unknown.get_result_async(), BOUND)
            far = [(2.0, [v - 0.3 * (j == 0) for j, v in enumerate(start)])]
            running = await wait_done(clock, client.send_goal_async(goal(names, far)), BOUND)
            await clock.sleep(0.8)
            cancelled = await wait_done(clock, running.cancel_goal_async(), BOUND)
            ended = await wait_done(clock, running.get_result_async(), BOUND)
            deadline, stopped, still = clock.now() + BOUND, None, float(states[-1].position[list(states[-1].name).index(names[0])])
            while stopped != still:  # joint_states standing still for 0.2 s (a braking KR C4 on a loaded machine takes a while)
                assert clock.now() < deadline, "the arm never came to rest"
                stopped = still
                await clock.sleep(0.2)
                still = float(states[-1].position[list(states[-1].name).index(names[0])])
            await clock.sleep(0.5)
            still = dict(zip(states[-1].name, states[-1].position))[names[0]]
            served = ros_fake_graph.GRAPH.services[f"{action}/_action/send_goal"][0].srv_type
            return start, points, done, reached, refused, cancelled, ended, (stopped, still), served
        finally:
            executor.shutdown()
            await bridge.close()

    start, points, done, reached, refused, cancelled, ended, (stopped, still), served = run_real(lambda clock: with_transport(clock, body))
    assert served is import_ros_type("control_msgs/action/FollowJointTrajectory_SendGoal")
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.error_code == 0
    assert abs(reached - points[-1][1][0]) < 1e-3
    assert refused.status == GoalStatus.STATUS_ABORTED and refused.result.error_code == FJT.Result.INVALID_JOINTS
    assert "'not_a_joint' is not one of the group's joints" in refused.result.error_string
    assert cancelled.return_code == 0 and ended.status == GoalStatus.STATUS_CANCELED
    assert start[0] - 0.3 + 0.02 < stopped < reached - 0.02 and abs(still - stopped) < 1e-6  # stopped on the way, and stays


def test_without_control_msgs_installed_the_bridge_serves_the_engine_and_says_why_not_the_action(fake_rclpy: Any, monkeypatch: Any, caplog: Any) -> None:
    """A ROS install without control_msgs (ros-base): the bridge starts, takes the machines' commands, and warns
    once per group, naming how to install the packages, instead of failing at its start."""
    for name in [m for m in sys.modules if m == "control_msgs" or m.startswith("control_msgs.")]:
        monkeypatch.delitem(sys.modules, name)

    async def body(transport: RosTransport) -> tuple[Any, Any]:
        bridge = await start_bridge(NEXTAGE, transport.create_node("nextage_sim_bridge"), transport.clock)
        try:
            return bridge.trajectories, ros_fake_graph.GRAPH.services.get(f"{ACTION}/_action/send_goal")
        finally:
            await bridge.close()

    servers, served = run_real(lambda clock: with_transport(clock, body))
    assert servers is not None and servers.groups == {} and not served
    warned = [r.getMessage() for r in caplog.records if "no FollowJointTrajectory action for" in r.getMessage()]
    assert len(warned) == 3 and all("cannot import control_msgs.action" in w and "rosdep install" in w for w in warned)
