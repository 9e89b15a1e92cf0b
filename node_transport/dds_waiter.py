"""One thread per DDS transport that takes what its readers received: a WaitSet, no listeners.

Why not Cyclone listeners: cyclonedds-python writes (``dds_write``) holding the GIL, and a write
delivers to the readers of its own process (a node hearing its own topic, ``coordination/sync``,
two nodes of one process, ``ros_discovery_info``) in the writing thread.  There it waits for a
listener of that reader that a receive thread is running at the same moment for a peer's sample,
and that listener, being Python, waits for the GIL: the process hangs for good.  A reader attached
to a waitset is signalled without Python; only this thread, woken while it holds no Cyclone lock,
runs the Python that takes the samples, and takes them in arrival order, one reader at a time.
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

PERIOD = 0.2  # wall seconds a wait lasts when nothing arrives (how soon a stop is seen at the latest)
MIN_WAIT = 0.001  # wall seconds: the shortest wait, so a tick that is due at once cannot spin the thread
JOIN_TIMEOUT = 5.0  # wall seconds close() waits for the thread (a handler takes at most a bounded batch)


class DdsWaiter:
    """Calls ``handler()`` on its own thread whenever a watched reader holds samples."""

    def __init__(self, dds: Any, participant: Any, name: str, on_stop: Callable[[BaseException], None] | None = None) -> None:
        self._dds = dds
        self._on_stop = on_stop  # told when the thread stops by itself: nothing would arrive any more
        self._waitset = dds.core.WaitSet(participant)
        self._guard = dds.core.GuardCondition(participant)  # wakes the thread for close()
        self._waitset.attach(self._guard)
        self._watched: dict[int, tuple[Any, Callable[[], None]]] = {}
        self._lock = threading.Lock()
        self._stopping = False
        self._every: Callable[[], float] | None = None
        self.failures = 0  # handler exceptions, logged (a handler is meant never to raise)
        self._thread = threading.Thread(target=self._run, name=f"dds waiter {name}", daemon=True)
        self._thread.start()

    def watch(self, reader: Any, handler: Callable[[], None]) -> Any:
        """Call ``handler`` whenever ``reader`` holds samples; the returned token un-watches."""
        core = self._dds.core
        condition = core.ReadCondition(reader, core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any)
        with self._lock:
            self._watched[id(condition)] = (condition, handler)
            self._waitset.attach(condition)
        return condition

    def every(self, tick: Callable[[], float]) -> None:
        """Call ``tick`` on this thread at each wake; it answers the seconds until it wants the next
        call (the wait is never longer: what is due is not late because nothing arrived)."""
        self._every = tick

    def forget(self, condition: Any) -> None:
        """Stop calling the handler of ``condition`` (before its reader is deleted)."""
        with self._lock:
            if self._watched.pop(id(condition), None) is not None:
                try:
                    self._waitset.detach(condition)
                except self._dds.core.DDSException:
                    pass  # already gone with its reader

    def _run(self) -> None:
        from cyclonedds.util import duration  # optional: pip extra 'dds', only when a DDS transport runs

        wait = PERIOD
        while not self._stopping:
            try:
                self._waitset.wait(duration(seconds=wait))
            except Exception as error:  # noqa: BLE001 - the waitset is being deleted, or a defect: said, then stop
                if not self._stopping:
                    log.error("dds: the waiter thread stops: %s: %s", type(error).__name__, error)
                    if self._on_stop is not None:
                        self._on_stop(error)
                return
            with self._lock:
                watched = list(self._watched.values())
            for condition, handler in watched:
                try:
                    if condition.triggered:
                        handler()
                except self._dds.core.DDSException:
                    continue  # its reader was deleted meanwhile
                except Exception as error:  # noqa: BLE001 - a defect in a handler: logged, the others go on
                    self.failures += 1
                    log.error("dds: a reader's handler failed: %s: %s", type(error).__name__, error)
            wait = self._tick()

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
