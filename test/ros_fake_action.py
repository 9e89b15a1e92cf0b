"""``rclpy.action.ActionClient`` of the fake rclpy: what rclpy 7.1 (Jazzy) does where an action
server's order on the wire decides what its user sees.

rclpy's client is one Waitable over rcl_action's three service clients and two subscriptions.
It makes a goal known only when the goal response arrives (``ClientGoalHandle``, status
``STATUS_UNKNOWN`` until a status array names it) and *drops* status entries of goals it does
not know; ``ros2 action send_goal`` cancels on Ctrl-C only when the handle's status is ACCEPTED
or EXECUTING.  The status topic is transient local with depth 1, so a status dropped once is not
sent again.  Here each arrival is taken as it comes (a client that is quicker than its server's
next write, which is what the real tools showed), so a server that publishes a goal's status
before its goal response loses that status to the client, every time.
"""
from __future__ import annotations

import copy
import os
from collections.abc import Callable
from typing import Any

from ros_fake_callbacks import Entity
from ros_fake_graph import GRAPH
from ros_fake_node import FakeNode
from ros_fake_qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_fake_services import FakeClient, Future
from ros_fake_topics import FakeSubscription

STATUS_UNKNOWN, STATUS_ACCEPTED, STATUS_EXECUTING, STATUS_CANCELING, STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED = range(7)
_TERMINAL = (STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED)


class ClientGoalHandle:
    """rclpy.action.client.ClientGoalHandle: a goal the server accepted (or refused)."""

    def __init__(self, client: ActionClient, goal_id: Any, response: Any) -> None:
        self._client = client
        self.goal_id = goal_id
        self.accepted = bool(response.accepted)
        self.stamp = response.stamp
        self.status = STATUS_UNKNOWN
        self.statuses: list[int] = []  # every status this handle took, in order (fake-only record)

    def cancel_goal_async(self) -> Future:
        return self._client._cancel_goal_async(self)

    def get_result_async(self) -> Future:
        return self._client._get_result_async(self)


class ActionClient(Entity):
    """rclpy.action.ActionClient(node, action_type, action_name)."""

    def __init__(self, node: FakeNode, action_type: Any, action_name: str, *, callback_group: Any = None) -> None:
        super().__init__(node, callback_group)
        self.action_type = action_type
        self.name = action_name
        impl = action_type.Impl
        base = f"{action_name}/_action"
        self._goal = self._part("goal", node.create_client(impl.SendGoalService, f"{base}/send_goal"))
        self._cancel = self._part("cancel", node.create_client(impl.CancelGoalService, f"{base}/cancel_goal"))
        self._result = self._part("result", node.create_client(impl.GetResultService, f"{base}/get_result"))
        status_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._feedback_sub = self._part("feedback", node.create_subscription(impl.FeedbackMessage, f"{base}/feedback", lambda m: None, QoSProfile(depth=10)))
        self._status_sub = self._part("status", node.create_subscription(impl.GoalStatusMessage, f"{base}/status", lambda m: None, status_qos))
        node.entities.append(self)
        self._goal_ids: dict[int, Any] = {}  # goal request sequence number -> the goal's UUID message
        self._goal_handles: dict[bytes, ClientGoalHandle] = {}
        self._feedback_callbacks: dict[bytes, Callable[[Any], None]] = {}
        self.ignored_status: list[tuple[bytes, int]] = []  # status entries of goals it did not know (fake-only record)

    def _part(self, kind: str, entity: FakeClient | FakeSubscription) -> Any:
        """One of rcl_action's entities; its arrivals go to this Waitable's queue, in order."""
        self.node.entities.remove(entity)
        entity.push = lambda item, kind=kind: self.push((kind, item))  # type: ignore[method-assign]
        return entity

    # --------------------------------------------------------------------------- the API
    def server_is_ready(self) -> bool:
        return self._goal.service_is_ready() and self._cancel.service_is_ready() and self._result.service_is_ready()

    def send_goal_async(self, goal: Any, feedback_callback: Callable[[Any], None] | None = None, goal_uuid: Any = None) -> Future:
        uuid_type = type(self.action_type.Impl.SendGoalService.Request().goal_id)
        goal_id = goal_uuid or uuid_type(uuid=list(os.urandom(16)))
        request = self.action_type.Impl.SendGoalService.Request(goal_id=goal_id, goal=goal)
        if feedback_callback is not None:
            self._feedback_callbacks[bytes(goal_id.uuid)] = feedback_callback
        with GRAPH.lock:  # the response is taken under this lock: it finds the id (rclpy: self._lock)
            future = self._goal.call_async(request)
            self._goal_ids[self._goal._sequence] = goal_id
        return future

    def _cancel_goal_async(self, handle: ClientGoalHandle) -> Future:
        request = self.action_type.Impl.CancelGoalService.Request()
        request.goal_info.goal_id = handle.goal_id
        return self._cancel.call_async(request)

    def _get_result_async(self, handle: ClientGoalHandle) -> Future:
        return self._result.call_async(self.action_type.Impl.GetResultService.Request(goal_id=handle.goal_id))

    def destroy(self) -> None:
        for entity in (self._goal, self._cancel, self._result):
            self.node.destroy_client(entity)
        for entity in (self._feedback_sub, self._status_sub):
            self.node.destroy_subscription(entity)
        self.destroyed = True

    # ------------------------------------------------------------------------ execute
    def run(self, item: Any) -> None:
        kind, data = item
        if kind == "goal":
            sequence, response = data
            with GRAPH.lock:
                future = self._goal.pending.pop(sequence, None)
            goal_id = self._goal_ids.pop(sequence, None)
            if future is None or goal_id is None:
                return
            handle = ClientGoalHandle(self, goal_id, response)
            if handle.accepted:
                self._goal_handles[bytes(goal_id.uuid)] = handle
            future.set_result(handle)
        elif kind in ("cancel", "result"):
            sequence, response = data
            client = self._cancel if kind == "cancel" else self._result
            with GRAPH.lock:
                future = client.pending.pop(sequence, None)
            if future is not None:
                future.set_result(response)
        elif kind == "feedback":
            callback = self._feedback_callbacks.get(bytes(data.goal_id.uuid))
            if callback is not None:
                callback(copy.deepcopy(data))
        elif kind == "status":
            for entry in data.status_list:
                uuid = bytes(entry.goal_info.goal_id.uuid)
                handle = self._goal_handles.get(uuid)
                if handle is None:
                    self.ignored_status.append((uuid, entry.status))
                    continue
                handle.status = entry.status
                handle.statuses.append(entry.status)
                if entry.status in _TERMINAL:
                    del self._goal_handles[uuid]
