"""``rclpy.executors.MultiThreadedExecutor`` of the fake rclpy: callbacks on threads, as rclpy 7.1 runs them.

The ros transport's threading is only tested if the fake runs callbacks the way rclpy does: on pool threads,
mutually exclusive groups serialised over take + callback + response, reentrant ones not; an exception out of a
callback re-raised out of ``spin``; a shutdown of the context ending ``spin`` with
:class:`~ros_fake_context.ExternalShutdownException`; and, like rclpy up to 7.1.11, ``shutdown(timeout_sec)``
returning at once without waiting for callbacks still running.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from ros_fake_callbacks import Entity
from ros_fake_context import CONTEXT, ExternalShutdownException
from ros_fake_node import FakeNode


class FakeExecutor:
    """Runs callbacks of its nodes on threads; ``spin`` ends on shutdown or on a callback's exception."""

    def __init__(self, num_threads: int | None = None, *, context: Any = None) -> None:
        self.num_threads = num_threads or 2
        self.cond = threading.Condition()
        self.nodes: list[FakeNode] = []
        self._is_shutdown = False
        self._groups_running: set[int] = set()
        self._in_flight = 0
        self._error: BaseException | None = None
        self.spin_threads: set[int] = set()
        self.callback_threads: set[int] = set()
        CONTEXT.on_shutdown(self.wake)

    @property
    def in_flight(self) -> int:
        return self._in_flight

    def wake(self) -> None:
        with self.cond:
            self.cond.notify_all()

    def add_node(self, node: FakeNode) -> bool:
        with self.cond:
            if node in self.nodes:
                return False
            self.nodes.append(node)
            node.executor = self
            self.cond.notify_all()
        return True

    def remove_node(self, node: FakeNode) -> None:
        with self.cond:
            if node in self.nodes:
                self.nodes.remove(node)
            self.cond.notify_all()

    def _next(self) -> tuple[Entity, Any] | None:
        for node in self.nodes:
            for entity in node.entities:
                group = entity.callback_group
                if not entity.queue or entity.destroyed:
                    continue
                if group.exclusive and id(group) in self._groups_running:
                    continue
                # As in rclpy, only a mutually exclusive group serialises callbacks: a reentrant
                # entity is taken again while its previous callback still runs.
                if group.exclusive:
                    self._groups_running.add(id(group))
                self._in_flight += 1
                return entity, entity.queue.popleft()
        return None

    def _run(self, entity: Entity, item: Any) -> None:
        self.callback_threads.add(threading.get_ident())
        try:
            entity.run(item)
        except BaseException as error:  # rclpy re-raises it out of spin
            with self.cond:
                self._error = self._error or error
        finally:
            with self.cond:
                self._groups_running.discard(id(entity.callback_group))
                self._in_flight -= 1
                self.cond.notify_all()

    def spin(self) -> None:
        self.spin_threads.add(threading.get_ident())
        pool = ThreadPoolExecutor(max_workers=self.num_threads, thread_name_prefix="fake executor")
        try:
            with self.cond:
                while not self._is_shutdown:
                    if not CONTEXT.ok():
                        raise ExternalShutdownException()
                    if self._error is not None:
                        error, self._error = self._error, None
                        raise error
                    work = self._next()
                    if work is None:
                        self.cond.wait()
                        continue
                    pool.submit(self._run, *work)
        finally:
            pool.shutdown(wait=False)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """rclpy <= 7.1.11: stops spinning and returns True at once, whatever is still running
        (the wait it documents is skipped by a bug fixed in 7.1.12)."""
        with self.cond:
            self._is_shutdown = True
            self.nodes = []
            self.cond.notify_all()
        return True


MultiThreadedExecutor = FakeExecutor
