"""ROS 2 actions over the port, the client side: what rclpy's ActionClient does, on every transport.

The wire is rcl_action's (see :mod:`node_transport.action` for the server): the goal goes out on
``<name>/_action/send_goal``, the result is asked for on ``get_result``, a cancel on ``cancel_goal``;
``status`` (reliable, transient local) and ``feedback`` come back as topics.  The rules kept from
rclpy, which servers written for it (ros2_control's controllers, MoveIt) rely on: a goal is known
from its goal response on, status entries of unknown goals are dropped, a goal that ended is
forgotten, and every goal id is a fresh random UUID (RFC 4122 version 4).

Every wait is bounded by the caller's timeout; a server that vanishes is a :class:`ActionError`
naming the action, never a wait for ever.
"""
from __future__ import annotations

import asyncio
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from node_transport.action import UUID, CancelGoal, CancelGoalRequest, CancelGoalResponse, GoalInfo, GoalStatus, GoalStatusArray, STATUS_QOS
from node_transport.port import Node, ServiceUnavailable
from node_transport.qos import COMMANDS

__all__ = ["ActionClient", "ActionError", "ClientGoal", "ACTIVE", "TERMINAL"]

ACTIVE = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)
TERMINAL = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)
STATUS_NAMES = {
    GoalStatus.STATUS_UNKNOWN: "unknown", GoalStatus.STATUS_ACCEPTED: "accepted", GoalStatus.STATUS_EXECUTING: "executing",
    GoalStatus.STATUS_CANCELING: "canceling", GoalStatus.STATUS_SUCCEEDED: "succeeded", GoalStatus.STATUS_CANCELED: "canceled",
    GoalStatus.STATUS_ABORTED: "aborted",
}


class ActionError(Exception):
    """The action's server is not there, did not answer in time, or answered what the protocol does not allow."""


@dataclass
class ClientGoal:
    """One goal the server accepted: its id, the latest status the server published, its feedback."""

    goal_id: Any  # a UUID mirror
    status: int = GoalStatus.STATUS_ACCEPTED
    feedback: Any = None  # the latest feedback message's feedback
    feedback_count: int = 0
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    @property
    def ended(self) -> bool:
        return self.status in TERMINAL


class ActionClient:
    """The client side of action ``name`` (mirror bundle ``action``: Goal, Result, Feedback, SendGoal,
    GetResult, FeedbackMessage) on ``node``.  ``on_feedback(goal, feedback)`` is called for each feedback
    message of a known goal."""

    def __init__(self, node: Node, action: type, name: str, on_feedback: Callable[[ClientGoal, Any], None] | None = None) -> None:
        self.node = node
        self.action = action
        self.name = node.resolve(name)
        base = f"{self.name}/_action"
        self._send = node.create_client(action.SendGoal, f"{base}/send_goal")  # type: ignore[attr-defined]
        self._result = node.create_client(action.GetResult, f"{base}/get_result")  # type: ignore[attr-defined]
        self._cancel = node.create_client(CancelGoal, f"{base}/cancel_goal")
        self._on_feedback = on_feedback
        self.goals: dict[tuple[int, ...], ClientGoal] = {}
        node.create_subscription(GoalStatusArray, f"{base}/status", self._on_status, STATUS_QOS)
        node.create_subscription(action.FeedbackMessage, f"{base}/feedback", self._on_feedback_message, COMMANDS)  # type: ignore[attr-defined]

    async def wait_for_server(self, timeout: float) -> bool:
        """True once the goal, result and cancel services are all served (within ``timeout`` s in all)."""
        deadline = self.node.clock.now() + timeout
        for client in (self._send, self._result, self._cancel):
            if not await client.wait_for_service(max(0.0, deadline - self.node.clock.now())):
                return False
        return True

    async def send_goal(self, goal: Any, timeout: float) -> ClientGoal | None:
        """Send ``goal``; the accepted goal, or None when the server refused it."""
        goal_id = UUID(tuple(uuid.uuid4().bytes))
        try:
            response = await self._send.call(self.action.SendGoal.Request(goal_id, goal), timeout=timeout)  # type: ignore[attr-defined]
        except (ServiceUnavailable, TimeoutError) as error:
            raise ActionError(f"{self.name}: the goal was not answered ({error or 'no answer in time'})") from None
        if not response.accepted:
            return None
        handle = self.goals.setdefault(goal_id.uuid, ClientGoal(goal_id))
        return handle

    async def result(self, goal: ClientGoal, timeout: float) -> tuple[int, Any]:
        """(terminal status, result) of ``goal``, waited for at most ``timeout`` s."""
        try:
            response = await self._result.call(self.action.GetResult.Request(goal.goal_id), timeout=timeout)  # type: ignore[attr-defined]
        except (ServiceUnavailable, TimeoutError) as error:
            raise ActionError(f"{self.name}: no result in {timeout:g} s ({error or 'no answer'})") from None
        if response.status not in TERMINAL:
            raise ActionError(f"{self.name}: a result with status {STATUS_NAMES.get(response.status, response.status)}, not an ended goal")
        self._end(goal, response.status)
        return response.status, response.result

    async def cancel(self, goal: ClientGoal, timeout: float) -> int:
        """Ask the server to cancel ``goal``; its answer's return code (0: accepted, 2: unknown goal,
        3: already ended).  The goal ends by itself afterwards: wait for it with :meth:`result`."""
        try:
            response = await self._cancel.call(CancelGoalRequest(GoalInfo(goal.goal_id)), timeout=timeout)
        except (ServiceUnavailable, TimeoutError) as error:
            raise ActionError(f"{self.name}: the cancel was not answered ({error or 'no answer in time'})") from None
        code: int = response.return_code
        if code not in (CancelGoalResponse.ERROR_NONE, CancelGoalResponse.ERROR_UNKNOWN_GOAL_ID, CancelGoalResponse.ERROR_GOAL_TERMINATED):
            raise ActionError(f"{self.name}: the cancel was refused (return code {code})")
        return code

    def _end(self, goal: ClientGoal, status: int) -> None:
        goal.status = status
        goal.changed.set()
        self.goals.pop(goal.goal_id.uuid, None)  # rclpy forgets a goal once it ended

    def _on_status(self, msg: Any) -> None:
        for entry in msg.status_list:
            goal = self.goals.get(entry.goal_info.goal_id.uuid)
            if goal is None or goal.ended:
                continue  # a goal not (or no longer) known: another client's, or one that ended
            if entry.status != goal.status:
                goal.status = entry.status
                goal.changed.set()

    def _on_feedback_message(self, msg: Any) -> None:
        goal = self.goals.get(msg.goal_id.uuid)
        if goal is None:
            return
        goal.feedback = msg.feedback
        goal.feedback_count += 1
        if self._on_feedback is not None:
            self._on_feedback(goal, msg.feedback)
