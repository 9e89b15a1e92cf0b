"""An action client over the transport port that sees the server the way rclpy's ActionClient does.

rclpy makes a goal known when its goal response arrives and drops every status entry of a goal it
does not know (``rclpy/action/client.py``); ``ros2 action send_goal`` cancels on Ctrl-C only when
that goal's status is ACCEPTED or EXECUTING.  This client keeps both rules -- the goal is
registered in the same step that takes the response -- and records what it dropped, so a test
can tell a server that publishes a status before its answer (the status is lost to a real client).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from execution_engine.engine.run_action import ACTION_NAME, RunApplication
from node_transport.action import UUID, CancelGoal, CancelGoalRequest, GoalInfo, GoalStatus, GoalStatusArray, STATUS_QOS
from node_transport.port import Node
from node_transport.qos import COMMANDS

ACTIVE = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING)
TERMINAL = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)


@dataclass
class Handle:
    goal_id: Any
    status: int = GoalStatus.STATUS_UNKNOWN
    statuses: list[int] = field(default_factory=list)  # every status taken for it, in order
    feedback: list[Any] = field(default_factory=list)


async def wait_done(clock: Any, future: Any, bound: float) -> Any:
    """The result of an rclpy future (``send_goal_async``, ``get_result_async``), polled on the loop's clock within ``bound`` s."""
    deadline = clock.now() + bound
    while not future.done():
        assert clock.now() < deadline, "no answer in time"
        await clock.sleep(0.01)
    return future.result()


class RclpyLikeActionClient:
    """``action``: the mirror bundle of the action's type (node_transport.mirrors.action), RunApplication by default."""

    def __init__(self, node: Node, name: str = f"/{ACTION_NAME}", action: Any = RunApplication) -> None:
        base = f"{name}/_action"
        self.action = action
        self.send = node.create_client(action.SendGoal, f"{base}/send_goal")
        self.result_client = node.create_client(action.GetResult, f"{base}/get_result")
        self.cancel_client = node.create_client(CancelGoal, f"{base}/cancel_goal")
        self.handles: dict[tuple[int, ...], Handle] = {}
        self.dropped: list[tuple[tuple[int, ...], int]] = []  # status entries of goals it did not know yet
        self.feedback_dropped = 0
        node.create_subscription(GoalStatusArray, f"{base}/status", self._on_status, STATUS_QOS)
        node.create_subscription(action.FeedbackMessage, f"{base}/feedback", self._on_feedback, COMMANDS)

    async def send_goal(self, goal: Any, number: int, timeout: float = 10.0) -> Handle | None:
        goal_id = UUID(tuple([number] * 16))
        response = await self.send.call(self.action.SendGoal.Request(goal_id, goal), timeout=timeout)
        if not response.accepted:
            return None
        handle = self.handles[goal_id.uuid] = Handle(goal_id)  # known from its goal response on
        return handle

    def _on_status(self, msg: Any) -> None:
        for entry in msg.status_list:
            uuid = entry.goal_info.goal_id.uuid
            handle = self.handles.get(uuid)
            if handle is None:
                self.dropped.append((uuid, entry.status))
                continue
            if handle.status in TERMINAL:  # rclpy forgets a goal once it ended
                continue
            handle.status = entry.status
            if not handle.statuses or handle.statuses[-1] != entry.status:
                handle.statuses.append(entry.status)

    def _on_feedback(self, msg: Any) -> None:
        handle = self.handles.get(msg.goal_id.uuid)
        if handle is None:
            self.feedback_dropped += 1
        else:
            handle.feedback.append(msg.feedback)

    async def cancel_if_active(self, handle: Handle, timeout: float = 10.0) -> Any:
        """What ``ros2 action send_goal`` does on Ctrl-C: cancel only a goal it sees running."""
        if handle.status not in ACTIVE:
            return None
        return await self.cancel_client.call(CancelGoalRequest(GoalInfo(handle.goal_id)), timeout=timeout)

    async def result(self, handle: Handle, timeout: float = 120.0) -> Any:
        return await self.result_client.call(self.action.GetResult.Request(handle.goal_id), timeout=timeout)
