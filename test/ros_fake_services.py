"""Services, clients and ``rclpy.task.Future`` of the fake rclpy: a request and its response as DDS carries them.

What the ros transport depends on: a client sees a service only once discovery has matched them
(``service_is_ready``), a request written before the match is lost, the response comes back on the client's own
callback group, a future's done-callbacks run on the thread that sets it (an executor thread), and a service
destroyed while its callback runs cannot send its response (``InvalidHandle``, as rclpy's ``send_response``).
"""
from __future__ import annotations

import copy
import threading
from collections.abc import Callable
from typing import Any

from ros_fake_args import InvalidHandle
from ros_fake_callbacks import Entity, Owner
from ros_fake_graph import GRAPH


class Future:
    """rclpy.task.Future: done-callbacks run when the result is set (on the setting thread here)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._done = False
        self._cancelled = False
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[[Future], None]] = []

    def done(self) -> bool:
        return self._done

    def cancelled(self) -> bool:
        return self._cancelled

    def result(self) -> Any:
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception

    def set_result(self, result: Any) -> None:
        self._finish(result=result)

    def set_exception(self, error: BaseException) -> None:
        self._finish(exception=error)

    def cancel(self) -> None:
        self._finish(cancelled=True)

    def _finish(self, result: Any = None, exception: BaseException | None = None, cancelled: bool = False) -> None:
        with self._lock:
            if self._done:
                return
            self._result, self._exception, self._cancelled, self._done = result, exception, cancelled, True
            callbacks, self._callbacks = self._callbacks, []
        for callback in callbacks:
            callback(self)

    def add_done_callback(self, callback: Callable[[Future], None]) -> None:
        with self._lock:
            if not self._done:
                self._callbacks.append(callback)
                return
        callback(self)


class FakeService(Entity):
    def __init__(self, node: Owner, srv_type: Any, name: str, callback: Callable[[Any, Any], Any], callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.srv_type, self.name, self.callback = srv_type, name, callback

    def run(self, item: Any) -> None:
        request, client, sequence = item
        response = self.callback(request, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):  # rclpy's send_response does the same
            raise TypeError(f"service {self.name} callback returned {type(response).__name__}")
        if self.destroyed:  # rclpy: `with self.handle:` in send_response on a destroyed service
            raise InvalidHandle(f"cannot use Destroyable because destruction was requested (service {self.name})")
        if not client.destroyed:
            client.push((sequence, copy.deepcopy(response)))


class FakeClient(Entity):
    def __init__(self, node: Owner, srv_type: Any, name: str, callback_group: Any) -> None:
        super().__init__(node, callback_group)
        self.srv_type, self.name = srv_type, name
        self.pending: dict[int, Future] = {}
        self.removed: list[Future] = []
        self._sequence = 0

    def _servers(self) -> list[FakeService]:
        with GRAPH.lock:
            return [s for s in GRAPH.services.get(self.name, []) if not s.destroyed and GRAPH.is_matched(self, s)]

    def service_is_ready(self) -> bool:
        return bool(self._servers())

    def call_async(self, request: Any) -> Future:
        if not isinstance(request, self.srv_type.Request):
            raise TypeError()
        future = Future()
        with GRAPH.lock:
            self._sequence += 1
            self.pending[self._sequence] = future
            servers = self._servers()
        for server in servers[:1]:  # a request written before the match is lost, as over DDS
            server.push((copy.deepcopy(request), self, self._sequence))
        return future

    def remove_pending_request(self, future: Future) -> None:
        with GRAPH.lock:
            for sequence, pending in list(self.pending.items()):
                if pending is future:
                    del self.pending[sequence]
                    self.removed.append(future)

    def run(self, item: Any) -> None:
        sequence, response = item
        with GRAPH.lock:
            future = self.pending.pop(sequence, None)
        if future is not None:
            future.set_result(response)
