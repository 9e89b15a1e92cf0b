"""node_transport.action_client: the client side of a ROS 2 action, against the port's rcl_action-conformant server.

What the ros2-control back end relies on when it drives someone else's controller: an accepted goal
runs to its result, a refused one is None, feedback and status reach the goal's handle, a cancel ends the
goal CANCELED and a second cancel says it already ended, and a server that is not there is a bounded
wait and a one-line ActionError naming the action -- never a wait for ever.
"""
from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

import pytest

from node_transport import mirrors
from node_transport.action import ActionServer, CancelGoalResponse, GoalHandle, GoalStatus
from node_transport.action_client import ActionClient, ActionError
from node_transport.clock import Clock
from node_transport.local import LocalTransport

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
Gripper = mirrors.action("control_msgs/action/GripperCommand")
NAME = "/gripper_controller/gripper_cmd"


def goal(position: float) -> Any:
    return Gripper.Goal(command=mirrors.mirror("control_msgs/msg/GripperCommand")(position=position, max_effort=10.0))


def serve(transport: LocalTransport, clock: Clock) -> ActionServer:
    """A gripper that refuses a negative gap and takes 1 s to move, with feedback every 0.1 s."""
    server: ActionServer

    async def execute(handle: GoalHandle) -> Any:
        target = handle.goal.command.position
        for step in range(10):
            if handle.cancel_requested:
                return Gripper.Result(position=target * step / 10)
            server.publish_feedback(handle, Gripper.Feedback(position=target * step / 10))
            await clock.sleep(0.1)
        return Gripper.Result(position=target, reached_goal=True)

    server = ActionServer(transport.create_node("gripper"), Gripper, NAME, execute=execute,
                          accept=lambda g: "negative gap" if g.command.position < 0 else None, cancel=lambda h: None)
    return server


def test_goal_result_feedback_refusal_and_cancel(run_sim: Run) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        transport = LocalTransport(clock)
        server = serve(transport, clock)
        seen: list[float] = []
        client = ActionClient(transport.create_node("client"), Gripper, NAME, on_feedback=lambda g, f: seen.append(f.position))
        try:
            assert await client.wait_for_server(5.0)
            done = await client.send_goal(goal(0.05), 5.0)
            assert done is not None
            status, result = await client.result(done, 5.0)
            refused = await client.send_goal(goal(-0.01), 5.0)
            running = await client.send_goal(goal(0.08), 5.0)
            assert running is not None
            await clock.sleep(0.35)
            executing = running.status
            code = await client.cancel(running, 5.0)
            cancelled_status, cancelled = await client.result(running, 5.0)
            again = await client.cancel(running, 5.0)
            return dict(status=status, result=result, refused=refused, executing=executing, code=code, cancelled_status=cancelled_status,
                        cancelled=cancelled, again=again, seen=seen, goals=dict(client.goals))
        finally:
            await server.close()
            await transport.shutdown()

    out = run_sim(main)
    assert out["status"] == GoalStatus.STATUS_SUCCEEDED and out["result"].reached_goal and out["result"].position == pytest.approx(0.05)
    assert out["refused"] is None
    assert out["executing"] == GoalStatus.STATUS_EXECUTING, "the status topic reached the handle"
    assert out["code"] == CancelGoalResponse.ERROR_NONE and out["cancelled_status"] == GoalStatus.STATUS_CANCELED
    assert out["cancelled"].position < 0.08 and not out["cancelled"].reached_goal
    assert out["again"] == CancelGoalResponse.ERROR_GOAL_TERMINATED
    assert out["seen"][:3] == pytest.approx([0.0, 0.005, 0.01]), "feedback of the first goal, in order"
    assert out["goals"] == {}, "ended goals are forgotten, as rclpy does"


def test_no_server_is_a_bounded_wait_and_one_line_naming_the_action(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[bool, str, float]:
        transport = LocalTransport(clock)
        client = ActionClient(transport.create_node("client"), Gripper, NAME)
        try:
            began = clock.now()
            there = await client.wait_for_server(2.0)
            with pytest.raises(ActionError) as caught:
                await client.send_goal(goal(0.01), 2.0)
            return there, str(caught.value), clock.now() - began
        finally:
            await transport.shutdown()

    there, message, took = run_sim(main)
    assert not there and message.startswith(f"{NAME}: the goal was not answered") and "\n" not in message
    assert took <= 4.0 + 1e-6


def test_ids_are_fresh_uuids(run_sim: Run) -> None:
    async def main(clock: Clock) -> set[tuple[int, ...]]:
        transport = LocalTransport(clock)
        server = serve(transport, clock)
        client = ActionClient(transport.create_node("client"), Gripper, NAME)
        try:
            ids = set()
            for _ in range(5):
                handle = await client.send_goal(goal(0.01), 5.0)
                assert handle is not None
                ids.add(handle.goal_id.uuid)
                await client.result(handle, 5.0)
            return ids
        finally:
            await server.close()
            await transport.shutdown()

    ids = run_sim(main)
    assert len(ids) == 5 and all(len(i) == 16 and (i[6] >> 4) == 4 for i in ids)  # RFC 4122 version 4
