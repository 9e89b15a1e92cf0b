"""ROS 2 actions over the port: rcl_action's server, made of three services and two topics.

An action ``<name>`` of type ``pkg/action/Name`` is, on the wire, what rcl_action makes of it:
services ``<name>/_action/send_goal``, ``<name>/_action/get_result`` and
``<name>/_action/cancel_goal`` (``action_msgs/srv/CancelGoal``), and topics
``<name>/_action/feedback`` and ``<name>/_action/status`` (``action_msgs/msg/GoalStatusArray``,
reliable and transient local, depth 1).  Built only from the port's services and publishers, the
server works on every transport that can carry the types: over DDS ``ros2 action send_goal``
reaches it, on the local transport the tests drive it.

The owner supplies ``execute(handle) -> result`` (a coroutine; its return ends the goal as
succeeded, or aborted when ``handle.aborted`` is set; cancelled when a cancel was accepted),
``accept(goal) -> reason or None`` and ``cancel(handle)`` (start stopping; ``execute`` returns when
stopped).  ``get_result`` waits for the goal's end, however long the job: its handler is marked
``long_running`` so a transport does not time it out.

The order on the wire is rcl_action's (rclpy's ActionClient depends on it): the goal response
first, then the status array with the goal ACCEPTED, then EXECUTING (:class:`~.port.Reply`); a
cancel's CANCELING before the cancel response; the terminal status before the result response.
An ended goal is forgotten after :data:`RESULT_TIMEOUT`, as rcl_action's ``result_timeout``.
"""
from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from node_transport import mirrors
from node_transport.msgs import Time
from node_transport.port import Node, Reply
from node_transport.qos import COMMANDS, Durability, History, QoS, Reliability

log = logging.getLogger(__name__)

#: Seconds an ended goal (its status and result) is kept, rcl_action's default ``result_timeout``.
RESULT_TIMEOUT = 900.0
#: Seconds :meth:`ActionServer.close` gives goals still running to end as their owner told them to, before cancelling them.
CLOSE_GRACE = 0.5
#: Seconds :meth:`ActionServer.close` takes at most, whatever goals it has served: a node stops on SIGTERM within 2 s.
CLOSE_TIMEOUT = 1.0
#: rcl_action_qos_profile_status_default
STATUS_QOS = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)


UUID = mirrors.mirror("unique_identifier_msgs/msg/UUID")
GoalInfo = mirrors.mirror("action_msgs/msg/GoalInfo")
GoalStatus = mirrors.mirror("action_msgs/msg/GoalStatus")
GoalStatusArray = mirrors.mirror("action_msgs/msg/GoalStatusArray")
CancelGoal = mirrors.service("action_msgs/srv/CancelGoal")
CancelGoalRequest, CancelGoalResponse = CancelGoal.Request, CancelGoal.Response

_ENDED = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)


@dataclass
class GoalHandle:
    """One accepted goal: its id, goal, status, and how it ended."""

    goal_id: Any  # a UUID mirror
    goal: Any
    stamp: Time
    status: int = 1  # GoalStatus.STATUS_ACCEPTED
    result: Any = None
    aborted: bool = False  # execute() sets it for a goal that failed
    cancel_requested: bool = False
    done: asyncio.Event = field(default_factory=asyncio.Event)

    @property
    def info(self) -> Any:
        return GoalInfo(self.goal_id, self.stamp)


class ActionServer:
    """The server side of action ``name`` (mirror bundle ``action``: Goal, Result, Feedback,
    SendGoal, GetResult, FeedbackMessage) on ``node``."""

    def __init__(
        self,
        node: Node,
        action: type,
        name: str,
        *,
        execute: Callable[[GoalHandle], Awaitable[Any]],
        accept: Callable[[Any], str | None],
        cancel: Callable[[GoalHandle], None],
    ) -> None:
        self.node = node
        self.action = action
        self.name = node.resolve(name)
        self._execute, self._accept, self._cancel = execute, accept, cancel
        self.goals: dict[tuple[int, ...], GoalHandle] = {}
        self._tasks: set[asyncio.Task[None]] = set()
        self._expiries: dict[tuple[int, ...], asyncio.TimerHandle] = {}  # ended goals, until forgotten
        self._results_asked = 0  # get_result requests waiting for a goal's end
        self._results_answered = asyncio.Event()  # set whenever none waits
        self._results_answered.set()
        self._closed = False
        base = f"{self.name}/_action"
        node.create_service(action.SendGoal, f"{base}/send_goal", self._on_send_goal)
        get_result = self._on_get_result
        node.create_service(action.GetResult, f"{base}/get_result", get_result)
        node.create_service(CancelGoal, f"{base}/cancel_goal", self._on_cancel_goal)
        self._feedback = node.create_publisher(action.FeedbackMessage, f"{base}/feedback", COMMANDS)
        self._status = node.create_publisher(GoalStatusArray, f"{base}/status", STATUS_QOS)

    # ------------------------------------------------------------------------- services
    async def _on_send_goal(self, request: Any) -> Any:
        """Accept or refuse; an accepted goal's status goes out only after this response.

        rclpy's ActionClient makes a goal known when the goal response arrives and drops status
        entries of unknown goals; a status published first is lost to it (and latched at depth 1,
        never sent again), so ``ros2 action send_goal`` would never see the goal run and its
        Ctrl-C would not cancel.  rcl_action's order, kept here: response, then ACCEPTED and
        EXECUTING, then the terminal status, then the result."""
        stamp = self.node.now_stamp()
        reason = "the server is shutting down" if self._closed else "its id is in use" if request.goal_id.uuid in self.goals else self._accept(request.goal)
        if reason is not None:
            self.node.logger.warning("%s: goal refused: %s", self.name, reason)
            return self.action.SendGoal.Response(False, stamp)
        handle = GoalHandle(request.goal_id, request.goal, stamp)
        self.goals[request.goal_id.uuid] = handle
        return Reply(self.action.SendGoal.Response(True, stamp), lambda: self._start(handle))

    def _start(self, handle: GoalHandle) -> None:
        """The goal response is on its way: announce the goal, then execute it."""
        self._publish_status()  # ACCEPTED
        if self._closed:  # accepted as the server closed: it ends here, and whoever asks for its result hears so
            self._ended(handle, self.action.Result(), GoalStatus.STATUS_ABORTED)
            return
        task = asyncio.get_running_loop().create_task(self._run(handle), name=f"{self.name} goal")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _run(self, handle: GoalHandle) -> None:
        if handle.status == GoalStatus.STATUS_ACCEPTED:  # a cancel may have come first: it stays CANCELING
            handle.status = GoalStatus.STATUS_EXECUTING
            self._publish_status()
        try:
            handle.result = await self._execute(handle)
            if handle.cancel_requested:
                handle.status = GoalStatus.STATUS_CANCELED
            else:
                handle.status = GoalStatus.STATUS_ABORTED if handle.aborted else GoalStatus.STATUS_SUCCEEDED
        except asyncio.CancelledError:  # the server closes: the goal ends here, and whoever waits for its result hears so
            self._ended(handle, self.action.Result(), GoalStatus.STATUS_CANCELED if handle.cancel_requested else GoalStatus.STATUS_ABORTED)
            raise
        except Exception as error:  # noqa: BLE001 - the goal ends aborted; the node hears why
            self.node.report_fault(f"action {self.name}", error)
            handle.result = self.action.Result()
            handle.status = GoalStatus.STATUS_ABORTED
        self._ended(handle, handle.result, handle.status)
        uuid = handle.goal_id.uuid
        self._expiries[uuid] = self.node.clock.call_later(RESULT_TIMEOUT, self._expire, uuid)

    def _ended(self, handle: GoalHandle, result: Any, status: int) -> None:
        handle.result, handle.status = result, status
        handle.done.set()
        self._publish_status()

    def _expire(self, uuid: tuple[int, ...]) -> None:
        """rcl_action forgets an ended goal after its result timeout: the status array stays bounded."""
        self._expiries.pop(uuid, None)
        if self.goals.pop(uuid, None) is not None:
            self._publish_status()

    async def _on_get_result(self, request: Any) -> Any:
        handle = self.goals.get(request.goal_id.uuid)
        if handle is None:
            return self.action.GetResult.Response(GoalStatus.STATUS_UNKNOWN, self.action.Result())
        self._results_asked += 1
        self._results_answered.clear()
        try:
            await handle.done.wait()
        finally:
            self._results_asked -= 1
            if not self._results_asked:
                self._results_answered.set()
        return self.action.GetResult.Response(handle.status, handle.result)

    _on_get_result.long_running = True  # type: ignore[attr-defined]

    async def _on_cancel_goal(self, request: Any) -> Any:
        wanted = request.goal_info.goal_id.uuid
        everything = not any(wanted)
        chosen = [h for h in self.goals.values() if everything or h.goal_id.uuid == wanted]
        if not chosen:
            return CancelGoalResponse(CancelGoalResponse.ERROR_UNKNOWN_GOAL_ID, ())
        active = [h for h in chosen if h.status not in _ENDED]
        if not active:
            return CancelGoalResponse(CancelGoalResponse.ERROR_GOAL_TERMINATED, ())
        for handle in active:
            handle.cancel_requested = True
            handle.status = GoalStatus.STATUS_CANCELING
            self._cancel(handle)
        self._publish_status()
        return CancelGoalResponse(CancelGoalResponse.ERROR_NONE, tuple(h.info for h in active))

    # --------------------------------------------------------------------------- topics
    def publish_feedback(self, handle: GoalHandle, feedback: Any) -> None:
        self._feedback.publish(self.action.FeedbackMessage(handle.goal_id, feedback))

    def _publish_status(self) -> None:
        self._status.publish(GoalStatusArray(tuple(GoalStatus(h.info, h.status) for h in self.goals.values())))

    async def close(self) -> None:
        """Stop within :data:`CLOSE_TIMEOUT` of the node's clock, whatever goals were served: the ended goals'
        timers go; a goal still running gets :data:`CLOSE_GRACE` to end as its owner told it to (its own
        result), then is cancelled and ends ABORTED; every get_result waiting for a goal is answered before
        the node's services go.  Only a goal that ignores its cancellation is left, and said so."""
        self._closed = True
        for timer in self._expiries.values():
            timer.cancel()
        self._expiries.clear()
        clock = self.node.clock
        deadline = clock.now() + CLOSE_TIMEOUT
        if self._tasks:
            running = asyncio.gather(*self._tasks, return_exceptions=True)
            try:
                await clock.wait_for(asyncio.shield(running), CLOSE_GRACE)
            except asyncio.TimeoutError:
                for task in list(self._tasks):
                    task.cancel()
                try:
                    await clock.wait_for(asyncio.shield(running), max(0.0, deadline - clock.now()))
                except asyncio.TimeoutError:
                    log.warning("%s: %d goal(s) did not end within %g s of the server's close", self.name, len(self._tasks), CLOSE_TIMEOUT)
        for handle in self.goals.values():
            if not handle.done.is_set():  # cancelled before it ran, or deaf to its cancellation: its client hears it end
                self._ended(handle, self.action.Result(), GoalStatus.STATUS_ABORTED)
        try:  # answered as soon as the goals have ended: a turn of the loop, bounded all the same
            await clock.wait_for(self._results_answered.wait(), max(0.0, deadline - clock.now()))
        except asyncio.TimeoutError:
            log.warning("%s: %d result request(s) unanswered at the server's close", self.name, self._results_asked)
