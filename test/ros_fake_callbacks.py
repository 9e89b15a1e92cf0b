"""What an executor of the fake rclpy takes work from: callback groups, entities with a queue, guard conditions.

rclpy runs a subscription's, service's or guard condition's callback on an executor thread, one queued item at a
time, and only a mutually exclusive group serialises callbacks; the ros transport relies on both (a service's
response goes out from its own exclusive group).  :class:`Entity` is the queue every fake endpoint with a callback
shares; the executor (``ros_fake_executor``) takes from it, a node (``ros_fake_node``) owns it.
"""
from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from ros_fake_args import InvalidHandle
from ros_fake_graph import GRAPH


class MutuallyExclusiveCallbackGroup:
    exclusive = True


class ReentrantCallbackGroup:
    exclusive = False


class Waker(Protocol):
    """The executor as an entity sees it: a condition to notify when work arrives."""

    cond: threading.Condition


class Owner(Protocol):
    """The node as an entity sees it: its executor (None until added to one) and its default group."""

    executor: Waker | None
    default_callback_group: Any


class Entity:
    """Something with an rmw queue the executor takes work from, one item at a time."""

    def __init__(self, node: Owner, callback_group: Any) -> None:
        self.node = node
        self.callback_group = callback_group or node.default_callback_group
        self.queue: deque[Any] = deque()
        self.destroyed = False

    def push(self, item: Any) -> None:
        executor = self.node.executor
        if executor is None:
            with GRAPH.lock:
                self.queue.append(item)
            return
        with executor.cond:
            self.queue.append(item)
            executor.cond.notify_all()

    def run(self, item: Any) -> None:
        raise NotImplementedError


class FakeGuardCondition(Entity):
    def __init__(self, node: Owner, callback: Callable[[], Any], callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.callback = callback

    def trigger(self) -> None:
        if self.destroyed:
            raise InvalidHandle("cannot use Destroyable because destruction was requested (guard condition)")
        self.push(None)

    def run(self, item: Any) -> None:
        self.callback()
