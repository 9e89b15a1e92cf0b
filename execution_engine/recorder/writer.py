"""The MCAP file of a recording, made off the control path so no machine ever waits for it.

Callers (subscription callbacks on the control loop) only :meth:`McapSink.put` a message and its
stamp into a bounded queue; a full queue counts the message as dropped (per topic) and warns once
-- it never blocks.  Everything else happens elsewhere:

* a feeder thread takes what has gathered every ``poll`` wall seconds and hands it, pickled in
  small batches, to the encoder process (:mod:`.encoder`) through a pipe;
* the encoder process converts and serialises to CDR with ``mcap-ros2-support`` (schemas and
  encoders made once per type) and writes through ``mcap``'s chunked, indexed writer, as
  ``ros2 bag record -s mcap`` does: profile ``ros2``, schema encoding ``ros2msg``, message
  encoding ``cdr``, the publishers' QoS in each channel's ``offered_qos_profiles``;
* a reader thread copies the file's bytes the encoder sends back to ``stream``.

Why a process: encoding costs some 30 µs a message in pure Python, and a thread of the run's
process would take it from the control loop through the interpreter lock (a rivet run publishes
about 24 messages a primitive).  Pickling a message costs about 1.5 µs, copying bytes nothing.

A run can be cut at any moment (``kill -9``, a power loss): the chunk in progress is closed and
the file flushed and synced to disk at least every ``flush_period`` wall seconds and on
:meth:`sync` (every operation boundary), so a cut recording reads back up to its last flushed
chunk (``mcap recover`` rebuilds its index).  When the run's process dies, the encoder sees its
input end and stops too.
"""
from __future__ import annotations

import itertools
import logging
import os
import pickle
import subprocess
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import IO, Any


from execution_engine.recorder.frames import frame, pickled, read_frame
from node_transport.qos import QoS

log = logging.getLogger(__name__)

CHUNK_SIZE = 256 * 1024  # bytes before a chunk is closed by size (rosbag2's default is 768 KiB)
QUEUE_SIZE = 20_000  # messages waiting for the feeder before new ones are dropped
FLUSH_PERIOD = 1.0  # wall seconds: the most a crash loses of what was already received
POLL = 0.05  # wall seconds between the feeder's looks at its queue
SYNC_GAP = 0.1  # wall seconds at least between two syncs asked for (each closes a chunk and syncs the disk)
BATCH = 256  # items pickled at once: the feeder holds the interpreter for well under a millisecond
PIPE_SIZE = 1 << 20  # bytes a pipe to or from the encoder holds (Linux), so bursts do not stall it
_STOP = object()


@dataclass
class RecordingStats:
    """What a recording holds and lost; printed at the end of a run and stored in the file."""

    path: str
    written: int = 0
    by_topic: Counter[str] = field(default_factory=Counter)
    dropped: Counter[str] = field(default_factory=Counter)  # queue full: never written
    error: str = ""  # the writer's failure, if any (then later messages are lost)

    def lines(self) -> list[str]:
        out = [f"recording {self.path}: {self.written} message(s) on {len(self.by_topic)} topic(s)"]
        if self.dropped:
            out.append(
                f"  DROPPED {sum(self.dropped.values())} message(s), the writer's queue was full: "
                + ", ".join(f"{t} {n}" for t, n in sorted(self.dropped.items()))
            )
        if self.error:
            out.append(f"  RECORDING FAILED: {self.error}")
        return out


def _reason(error: Exception) -> str:
    """Why a write failed, in the system's words (No space left on device) when it has them."""
    return error.strerror if isinstance(error, OSError) and error.strerror else f"{type(error).__name__}: {error}"


def _encoder_command(chunk_size: int, compression: str) -> list[str]:
    """``compression``: an ``mcap`` ``CompressionType`` name (``ZSTD``, ``LZ4``, ``NONE``)."""
    return [sys.executable, "-m", "execution_engine.recorder.encoder", str(chunk_size), compression]


def _encoder_env() -> dict[str, str]:
    """The encoder imports this process's own modules (the same source tree or install)."""
    paths = [os.path.abspath(p or os.curdir) for p in sys.path]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(dict.fromkeys(paths))}


def _widen(pipe: IO[bytes] | None) -> None:
    try:
        import fcntl  # optional: POSIX only (elsewhere the pipe keeps its default size)

        fcntl.fcntl(pipe.fileno(), getattr(fcntl, "F_SETPIPE_SZ", 1031), PIPE_SIZE)  # type: ignore[union-attr]
    except (ImportError, OSError, AttributeError, ValueError):  # not Linux, or over the system's limit: the default
        pass


class McapSink:
    """One MCAP file, the encoder process that makes it and the two threads that talk to it."""

    def __init__(
        self,
        stream: IO[bytes],
        path: str,
        *,
        queue_size: int = QUEUE_SIZE,
        chunk_size: int = CHUNK_SIZE,
        flush_period: float = FLUSH_PERIOD,
        poll: float = POLL,
        compression: str = "ZSTD",
    ) -> None:
        self.stats = RecordingStats(path)
        self._stream = stream
        self._queue: deque[Any] = deque()
        self._queue_size = queue_size
        self._wake = threading.Event()  # only for sync and close: messages never wake the feeder
        self._flush_period = flush_period
        self._poll = poll
        self._syncs: dict[int, list[threading.Event]] = {}  # sync number -> who waits for it
        self._numbers = itertools.count()
        self._last_sync = time.monotonic()  # when the feeder last sent a sync (written by the feeder only)
        self._sent: Counter[str] = Counter()
        self._warned = False
        self._closed = False
        self._failed = False
        self._finished = False
        self._process = subprocess.Popen(  # noqa: S603 - this interpreter, our own module
            _encoder_command(chunk_size, compression), stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=_encoder_env()
        )
        _widen(self._process.stdin)
        _widen(self._process.stdout)
        self._feeder = threading.Thread(target=self._feed, name=f"mcap feeder {path}", daemon=True)
        self._reader = threading.Thread(target=self._read, name=f"mcap reader {path}", daemon=True)
        self._feeder.start()
        self._reader.start()

    # ---------------------------------------------------------------- the caller's side
    def put(self, topic: str, msg: Any, offered: tuple[QoS, ...], log_time_ns: int) -> None:
        """Hand one message to the writer; never blocks (a full queue drops it and says so once)."""
        if self._closed:
            return
        if len(self._queue) >= self._queue_size or self._failed:
            self.stats.dropped[topic] += 1
            if not self._warned:
                self._warned = True
                log.warning("recording %s: the writer cannot keep up; dropping messages (first on %s)", self.stats.path, topic)
            return
        self._queue.append(("m", topic, msg, offered, log_time_ns))

    def derive_tf(self, topic: str, offered: tuple[QoS, ...], joint_states: str, description: str) -> None:
        """Have the encoder write ``topic`` (``tf``) from the recorded joint states and URDF
        (:mod:`.derived_tf`) instead of receiving it."""
        self._control(("tf", topic, offered, joint_states, description))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        self._control(("meta", name, dict(data)))

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time_ns: int) -> None:
        self._control(("att", name, media_type, data, log_time_ns))

    def sync(self) -> threading.Event:
        """Close the chunk in progress and put the file on disk (operation boundaries); the event
        is set once that is done (or the recording failed).  Syncs asked for within ``SYNC_GAP``
        of the last one wait for the next: a run of short operations must not sync a disk a
        thousand times a second, nor make a chunk of every few messages."""
        done = threading.Event()
        self._control(done)
        if self._closed or self._failed:
            done.set()
        return done

    def close(self, timeout: float = 30.0) -> RecordingStats:
        """Write what is queued, the summary (with ``recording_stats``) and the index; wait
        (bounded) for the encoder and the threads."""
        if not self._closed:
            self._closed = True
            self._queue.append(_STOP)
            self._wake.set()
            deadline = time.monotonic() + timeout
            self._feeder.join(timeout)
            self._reader.join(max(0.0, deadline - time.monotonic()))
            if self._reader.is_alive() or self._feeder.is_alive():
                self.stats.error = self.stats.error or f"the writer did not finish within {timeout:g} s"
                self._process.kill()
            else:
                try:
                    self._stream.close()  # flushes what the reader thread wrote last: a full disk may say so only here
                except OSError as error:
                    self._fail(error.strerror or str(error))
            self._process.wait(max(0.1, deadline - time.monotonic()))
        return self.stats

    def _control(self, item: Any) -> None:
        """Control items are few and never dropped (they may go past the bound).  A sync wakes the
        feeder only once ``SYNC_GAP`` has passed since the last one: before that the feeder would
        only hold it back, and a run of short operations (one sync each) would wake it, and make it
        pickle a small batch, at every operation."""
        if not self._closed:
            self._queue.append(item)
            if isinstance(item, threading.Event) and time.monotonic() - self._last_sync >= SYNC_GAP:
                self._wake.set()

    def _fail(self, reason: str) -> None:
        if not self._failed:
            self._failed = True
            self.stats.error = self.stats.error or reason
            log.error("recording %s failed: %s", self.stats.path, self.stats.error)
        for events in list(self._syncs.values()):
            for event in events:
                event.set()

    # ---------------------------------------------------------------- the feeder thread
    def _feed(self) -> None:
        pending = False  # messages sent since the last sync
        waiting: list[threading.Event] = []  # syncs asked for and not yet sent
        try:
            while True:
                self._wake.wait(self._poll)
                self._wake.clear()
                items: list[tuple[Any, ...]] = []
                stop = False
                while self._queue and not stop:
                    item = self._queue.popleft()
                    if item is _STOP:
                        stop = True
                    elif isinstance(item, threading.Event):  # a sync asked for
                        waiting.append(item)
                    elif item[0] == "m":
                        _, topic, msg, offered, log_time = item
                        items.append(("m", topic, type(msg).ROS_TYPE, msg, offered, log_time))
                        pending = True
                    else:
                        items.append(item)
                    if len(items) >= BATCH:
                        self._send(items)
                        items = []
                since = time.monotonic() - self._last_sync
                if stop or (waiting and since >= SYNC_GAP) or (pending and since >= self._flush_period):
                    items.append(self._sync_item(waiting))
                    waiting, pending, self._last_sync = [], False, time.monotonic()
                if stop:
                    items.append(("stop", Counter(self.stats.dropped)))
                if items:
                    self._send(items)
                if stop:
                    return
        except Exception as error:  # noqa: BLE001 - said, never silent
            self._fail(f"{type(error).__name__}: {error}")
        finally:
            for event in waiting:
                event.set()
            try:
                self._process.stdin.close()  # type: ignore[union-attr]  # the encoder ends at the end of its input
            except OSError:
                pass

    def _sync_item(self, events: list[threading.Event]) -> tuple[str, int]:
        number = next(self._numbers)
        self._syncs[number] = events
        return ("sync", number)

    def _send(self, items: list[tuple[Any, ...]]) -> None:
        messages = [item[1] for item in items if item[0] == "m"]
        if self._failed:
            self.stats.dropped.update(messages)
            return
        data = frame(b"B", pickled(items))
        try:
            self._process.stdin.write(data)  # type: ignore[union-attr]
            self._process.stdin.flush()  # type: ignore[union-attr]
        except OSError:  # the encoder is gone: the reader says why
            self.stats.dropped.update(messages)
            self._fail(f"the encoder process ended (exit code {self._process.poll()})")
            return
        self._sent.update(messages)

    # ---------------------------------------------------------------- the reader thread
    def _read(self) -> None:
        stdout = self._process.stdout
        assert stdout is not None
        try:
            while (got := read_frame(stdout)) is not None:
                kind, payload = got
                if kind == b"D" and not self._failed:
                    self._write(payload)
                elif kind == b"S":
                    if not self._failed:
                        self._stream.flush()
                        self._fsync()
                    for event in self._syncs.pop(int(payload), []):
                        event.set()
                elif kind == b"E":
                    self._fail(payload.decode(errors="replace"))
                elif kind == b"T":
                    self.stats.by_topic = Counter(pickle.loads(payload))
                    self.stats.written = sum(self.stats.by_topic.values())
                    self._finished = True
                    if not self._failed:
                        self._stream.flush()
                        self._fsync()
        except Exception as error:  # noqa: BLE001 - said, never silent
            self._fail(_reason(error))
        if not self._finished:
            self.stats.by_topic = self.stats.by_topic or Counter(self._sent)
            self.stats.written = self.stats.written or sum(self.stats.by_topic.values())
            self._fail(f"the encoder process ended before the recording did (exit code {self._process.wait()})")

    def _write(self, data: bytes) -> None:
        try:
            self._stream.write(data)
        except Exception as error:  # noqa: BLE001 - a full or failing disk stops the recording, not the run
            self._fail(_reason(error))

    def _fsync(self) -> None:
        try:
            os.fsync(self._stream.fileno())
        except (AttributeError, OSError, ValueError):  # an in-memory stream or a pipe: flushed is all there is
            pass
