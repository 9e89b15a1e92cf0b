"""One thread per DDS transport that takes what its readers received: a WaitSet, no listeners.

Why not Cyclone listeners: cyclonedds-python writes (``dds_write``) holding the GIL, and a write
delivers to the readers of its own process (a node hearing its own topic, ``coordination/sync``,
two nodes of one process, ``ros_discovery_info``) in the writing thread.  There it waits for a
listener of that reader that a receive thread is running at the same moment for a peer's sample,
and that listener, being Python, waits for the GIL: the process hangs for good.  A reader attached
to a waitset is signalled without Python; only this thread, woken while it holds no Cyclone lock,
runs the Python that takes the samples, and takes them in arrival order, one reader at a time.

Cost per wake (issue 22): the wait names the readers that hold samples (each condition is attached
with a key of its own), so a wake costs one call into Cyclone, not one per watched reader -- each
such call gives the GIL up and has to win it back from the loop's thread; and what a wake took
reaches the loop in one hand-over (:meth:`DdsWaiter.after_each`), one wake-up of the loop per batch
rather than one per sample.
"""
from __future__ import annotations

import asyncio
import collections
import ctypes
import itertools
import logging
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

PERIOD = 0.2  # wall seconds a wait lasts when nothing arrives (how soon a stop is seen at the latest)
MIN_WAIT = 0.001  # wall seconds: the shortest wait, so a tick that is due at once cannot spin the thread
JOIN_TIMEOUT = 5.0  # wall seconds close() waits for the thread (a handler takes at most a bounded batch)


class Triggers:
    """A Cyclone waitset whose wait answers *which* attached conditions triggered (their keys)."""

    ROOM = 64  # keys one wait reports; more triggered at once: the rest are checked one by one

    def __init__(self, dds: Any, participant: Any) -> None:
        self._dds = dds
        self._waitset = dds.core.WaitSet(participant)
        self._keys = (ctypes.c_void_p * self.ROOM)()
        self._pointer = ctypes.cast(self._keys, ctypes.POINTER(ctypes.c_void_p))

    def attach(self, condition: Any, key: int) -> None:
        ret = self._waitset._waitset_attach(self._waitset._ref, condition._ref, key)
        if ret < 0:
            raise self._dds.core.DDSException(ret, f"cannot attach {condition!r} to the waiter's waitset")

    def detach(self, condition: Any) -> None:
        ret = self._waitset._waitset_detach(self._waitset._ref, condition._ref)
        if ret < 0:
            raise self._dds.core.DDSException(ret, f"cannot detach {condition!r} from the waiter's waitset")

    def wait(self, timeout_ns: int) -> list[int] | None:
        """Keys of the triggered conditions ([] on timeout); None when more triggered than reported."""
        count = self._waitset._waitset_wait(self._waitset._ref, self._pointer, self.ROOM, timeout_ns)
        if count < 0:
            raise self._dds.core.DDSException(count, "the waiter's wait failed")
        if count > self.ROOM:
            return None
        return [int(self._keys[i] or 0) for i in range(count)]


GUARD = 1  # the key of the guard condition that wakes the thread for close()


class DdsWaiter:
    """Calls ``handler()`` on its own thread whenever a watched reader holds samples."""

    def __init__(self, dds: Any, participant: Any, name: str, on_stop: Callable[[BaseException], None] | None = None) -> None:
        self._dds = dds
        self._on_stop = on_stop  # told when the thread stops by itself: nothing would arrive any more
        self._waitset = Triggers(dds, participant)
        self._guard = dds.core.GuardCondition(participant)  # wakes the thread for close()
        self._waitset.attach(self._guard, GUARD)
        self._watched: dict[int, tuple[Any, Callable[[], None]]] = {}
        self._keys = itertools.count(GUARD + 1)
        self._lock = threading.Lock()
        self._stopping = False
        self._every: Callable[[], float] | None = None
        self._after: Callable[[], None] | None = None
        self.failures = 0  # handler exceptions, logged (a handler is meant never to raise)
        self._thread = threading.Thread(target=self._run, name=f"dds waiter {name}", daemon=True)
        self._thread.start()

    def watch(self, reader: Any, handler: Callable[[], None]) -> tuple[int, Any]:
        """Call ``handler`` whenever ``reader`` holds samples; the returned token un-watches."""
        core = self._dds.core
        condition = core.ReadCondition(reader, core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any)
        with self._lock:
            key = next(self._keys)
            self._watched[key] = (condition, handler)
            self._waitset.attach(condition, key)
        return key, condition

    def every(self, tick: Callable[[], float]) -> None:
        """Call ``tick`` on this thread at each wake; it answers the seconds until it wants the next
        call (the wait is never longer: what is due is not late because nothing arrived)."""
        self._every = tick

    def after_each(self, done: Callable[[], None]) -> None:
        """Call ``done`` on this thread after the handlers of each wake (to hand their work over at once)."""
        self._after = done

    def forget(self, token: tuple[int, Any]) -> None:
        """Stop calling the handler of ``token`` (before its reader is deleted)."""
        key, condition = token
        with self._lock:
            if self._watched.pop(key, None) is not None:
                try:
                    self._waitset.detach(condition)
                except self._dds.core.DDSException:
                    pass  # already gone with its reader

    def _run(self) -> None:
        wait = PERIOD
        while not self._stopping:
            try:
                keys = self._waitset.wait(int(wait * 1e9))
            except Exception as error:  # noqa: BLE001 - the waitset is being deleted, or a defect: said, then stop
                if not self._stopping:
                    log.error("dds: the waiter thread stops: %s: %s", type(error).__name__, error)
                    if self._on_stop is not None:
                        self._on_stop(error)
                return
            with self._lock:
                if keys is None:  # more than one wait reports: every watched reader is looked at
                    due = [(condition, handler, True) for condition, handler in self._watched.values()]
                else:
                    due = [(*self._watched[k], False) for k in keys if k in self._watched]
            for condition, handler, check in due:
                try:
                    if not check or condition.triggered:
                        handler()
                except self._dds.core.DDSException:
                    continue  # its reader was deleted meanwhile
                except Exception as error:  # noqa: BLE001 - a defect in a handler: logged, the others go on
                    self.failures += 1
                    log.error("dds: a reader's handler failed: %s: %s", type(error).__name__, error)
            self._hand_over()
            wait = self._tick()

    def _hand_over(self) -> None:
        if self._after is not None and not self._stopping:
            try:
                self._after()
            except Exception as error:  # noqa: BLE001 - a defect: logged, the thread goes on
                self.failures += 1
                log.error("dds: the waiter's hand-over failed: %s: %s", type(error).__name__, error)

    def _tick(self) -> float:
        """The periodic call, if any; how long the next wait may last."""
        tick = self._every
        if tick is None or self._stopping:
            return PERIOD
        try:
            return min(PERIOD, max(MIN_WAIT, tick()))
        except self._dds.core.DDSException:
            return PERIOD  # its writer is being deleted
        except Exception as error:  # noqa: BLE001 - a defect: logged, the readers go on
            self.failures += 1
            log.error("dds: the waiter's periodic call failed: %s: %s", type(error).__name__, error)
            return PERIOD

    def close(self) -> None:
        """Stop the thread (waits for a handler under way)."""
        self._stopping = True
        try:
            self._guard.set(True)
        except self._dds.core.DDSException:
            pass
        if threading.current_thread() is not self._thread:
            self._thread.join(JOIN_TIMEOUT)


class Inbox:
    """What the waiter's handlers give the loop, handed over once per wake, and not at all while a
    hand-over is still waiting for the loop: a loop that is woken per sample (``call_soon_threadsafe``
    writes its wake-up pipe each time) spends more on waking than on the sample, and the waiter waits
    for the GIL behind it each time."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._queue: collections.deque[tuple[Callable[..., Any], tuple[Any, ...]]] = collections.deque()
        self._scheduled = False  # a drain is on the loop's ready list and has not started

    def put(self, callback: Callable[..., Any], *args: Any) -> None:
        """The waiter's thread: run ``callback(*args)`` on the loop, in this order."""
        self._queue.append((callback, args))

    def hand_over(self) -> None:
        """The waiter's thread, after a wake's handlers: wake the loop unless a drain is already due
        (it takes what was put before it starts: the flag is cleared before the queue is read)."""
        if self._queue and not self._scheduled:
            self._scheduled = True
            try:
                self._loop.call_soon_threadsafe(self._drain)
            except RuntimeError:
                self._queue.clear()  # the loop is closed: nobody is left to hear it

    def _drain(self) -> None:
        self._scheduled = False
        queue = self._queue
        for _ in range(len(queue)):  # what came meanwhile has its own drain: other callbacks run between
            callback, args = queue.popleft()
            try:
                callback(*args)
            except Exception as error:  # noqa: BLE001 - one delivery's defect must not drop the others
                self._loop.call_exception_handler({"message": "dds: a delivery failed", "exception": error})
