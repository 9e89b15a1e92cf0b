"""The MCAP file of a recording, written by its own thread so no machine ever waits for a disk.

Callers (subscription callbacks on the control loop) only :meth:`McapSink.put` a message into a
bounded queue; a full queue counts the message as dropped (per topic) and warns once -- it never
blocks.  The writer thread serialises to CDR with ``mcap-ros2-support``'s encoder (the schema
texts of :mod:`.definitions`) and writes through ``mcap``'s chunked, indexed writer, as
``ros2 bag record -s mcap`` does: profile ``ros2``, schema encoding ``ros2msg``, message
encoding ``cdr``, the publishers' QoS in each channel's ``offered_qos_profiles``.

A run can be cut at any moment (``kill -9``, a power loss): the thread closes the chunk in
progress and flushes it to the operating system at least every ``flush_period`` wall seconds
and on :meth:`sync` (every operation boundary), and syncs the file to disk then, so a cut
recording reads back up to its last flushed chunk (``mcap recover`` rebuilds its index).
"""
from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import IO, Any

from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import EncoderFunction, serialize_dynamic

from execution_engine.recorder.definitions import schema_text
from execution_engine.transport.msgs import ByteBuffer
from execution_engine.transport.qos import Durability, QoS, Reliability

log = logging.getLogger(__name__)

CHUNK_SIZE = 256 * 1024  # bytes before a chunk is closed by size (rosbag2's default is 768 KiB)
QUEUE_SIZE = 20_000  # messages waiting for the writer thread before new ones are dropped
FLUSH_PERIOD = 1.0  # wall seconds: the most a crash loses of what was already received
POLL = 0.05  # wall seconds between the writer's looks at its queue
YIELD_AFTER = 0.002  # wall seconds of writing before the writer lets the control loop take the interpreter
_STOP = object()


@dataclass
class RecordingStats:
    """What a recording holds and lost; printed at the end of a run and stored in the file."""

    path: str
    written: int = 0
    by_topic: Counter[str] = field(default_factory=Counter)
    dropped: Counter[str] = field(default_factory=Counter)  # queue full: never written
    error: str = ""  # the writer thread's failure, if any (then later messages are lost)

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


def qos_yaml(offered: tuple[QoS, ...]) -> str:
    """A channel's ``offered_qos_profiles`` as rosbag2 (Jazzy) writes it: one YAML entry per publisher."""
    infinite = "    sec: 2147483647\n    nsec: 4294967295\n"
    entries = []
    for qos in offered:
        entries.append(
            f"- history: keep_last\n  depth: {qos.depth}\n"
            f"  reliability: {'best_effort' if qos.reliability is Reliability.BEST_EFFORT else 'reliable'}\n"
            f"  durability: {'transient_local' if qos.durability is Durability.TRANSIENT_LOCAL else 'volatile'}\n"
            f"  deadline:\n{infinite}  lifespan:\n{infinite}  liveliness: automatic\n"
            f"  liveliness_lease_duration:\n{infinite}  avoid_ros_namespace_conventions: false"
        )
    return "\n".join(entries)


_FIELDS: dict[type, tuple[str, ...]] = {}


def to_ros_dict(value: Any) -> Any:
    """A message mirror as the CDR encoder takes it: nested dicts, lists, a ``byte`` as an int."""
    cls = type(value)
    if cls in (str, float, int, bool):
        return value
    if cls is tuple or cls is list:
        return [to_ros_dict(v) for v in value]
    if cls is ByteBuffer:  # uint8[] (image data): the encoder takes bytes whole
        return value
    if cls is bytes:  # a ROS ``byte`` (DiagnosticStatus.level) is bytes of length 1 in the mirrors
        return value[0] if len(value) == 1 else value
    names = _FIELDS.get(cls)
    if names is None:
        names = _FIELDS[cls] = tuple(f.name for f in dataclasses.fields(value))
    return {name: to_ros_dict(getattr(value, name)) for name in names}


class McapSink:
    """One MCAP file and the thread that writes it.

    The queue is a deque the callers append to (atomic under the GIL, no lock, no wake-up): the
    writer thread looks every ``poll`` wall seconds and writes what has gathered, handing the
    interpreter back after at most ``YIELD_AFTER`` of work, so a control loop waits neither for a
    lock nor long for the writer's turn on the GIL.
    """

    def __init__(
        self,
        stream: IO[bytes],
        path: str,
        *,
        queue_size: int = QUEUE_SIZE,
        chunk_size: int = CHUNK_SIZE,
        flush_period: float = FLUSH_PERIOD,
        poll: float = POLL,
        compression: CompressionType = CompressionType.ZSTD,
    ) -> None:
        self.stats = RecordingStats(path)
        self._stream = stream
        self._queue: deque[Any] = deque()
        self._queue_size = queue_size
        self._wake = threading.Event()  # only for sync and close: messages never wake the writer
        self._flush_period = flush_period
        self._poll = poll
        self._writer = Writer(stream, chunk_size=chunk_size, compression=compression)
        self._writer.start(profile="ros2", library="dual_arm_executive recorder (mcap, mcap-ros2-support)")
        self._schemas: dict[str, tuple[int, EncoderFunction]] = {}
        self._channels: dict[str, int] = {}
        self._sequence: Counter[str] = Counter()
        self._warned = False
        self._closed = False
        self._failed = False
        self._thread = threading.Thread(target=self._work, name=f"mcap writer {path}", daemon=True)
        self._thread.start()

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
        self._queue.append((topic, msg, offered, log_time_ns))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        self._control(("metadata", name, dict(data)))

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time_ns: int) -> None:
        self._control(("attachment", name, media_type, data, log_time_ns))

    def sync(self) -> threading.Event:
        """Close the chunk in progress and put the file on disk (operation boundaries); the event
        is set once that is done."""
        done = threading.Event()
        self._control(done)
        return done

    def close(self, timeout: float = 30.0) -> RecordingStats:
        """Write what is queued, the summary and the index; wait (bounded) for the thread."""
        if not self._closed:
            self._closed = True
            self._queue.append(_STOP)
            self._wake.set()
            self._thread.join(timeout)
            if self._thread.is_alive():
                self.stats.error = self.stats.error or f"the writer did not finish within {timeout:g} s"
            else:
                self._stream.close()
        return self.stats

    def _control(self, item: Any) -> None:
        """Control items are few and never dropped (they may go past the bound)."""
        if not self._closed:
            self._queue.append(item)
            if isinstance(item, threading.Event):
                self._wake.set()

    # ---------------------------------------------------------------- the writer thread
    def _work(self) -> None:
        last_flush = time.monotonic()
        pending = False
        try:
            while True:
                self._wake.wait(self._poll)
                self._wake.clear()
                burst = time.perf_counter()
                while self._queue:
                    item = self._queue.popleft()
                    if item is _STOP:
                        self._writer.finish()
                        self._stream.flush()
                        self._fsync()
                        return
                    if isinstance(item, threading.Event):  # a sync
                        self._flush(sync=True)
                        item.set()
                        pending, last_flush = False, time.monotonic()
                        continue
                    self._write(item)
                    pending = True
                    if time.perf_counter() - burst > YIELD_AFTER:  # let a waiting control loop have the interpreter
                        time.sleep(0)
                        burst = time.perf_counter()
                if pending and time.monotonic() - last_flush >= self._flush_period:
                    self._flush(sync=True)
                    pending, last_flush = False, time.monotonic()
        except Exception as error:  # noqa: BLE001 - a full disk, a bad message: said, never silent
            self.stats.error = f"{type(error).__name__}: {error}"
            self._failed = True
            log.error("recording %s failed: %s", self.stats.path, self.stats.error)
            self._drain()

    def _drain(self) -> None:
        """After a failure: count what could not be written, release waiters, let ``close`` return."""
        while True:
            while self._queue:
                item = self._queue.popleft()
                if item is _STOP:
                    return
                if isinstance(item, threading.Event):
                    item.set()
                elif isinstance(item, tuple) and len(item) == 4:
                    self.stats.dropped[item[0]] += 1
            self._wake.wait(self._poll)
            self._wake.clear()

    def _write(self, item: tuple[Any, ...]) -> None:
        if item[0] == "metadata":
            self._writer.add_metadata(item[1], item[2])
            return
        if item[0] == "attachment":
            _, name, media_type, data, log_time = item
            self._writer.add_attachment(log_time, log_time, name, media_type, data)
            return
        topic, msg, offered, log_time = item
        ros_type: str = type(msg).ROS_TYPE
        schema = self._schemas.get(ros_type)
        if schema is None:
            text = schema_text(ros_type)
            schema_id = self._writer.register_schema(ros_type, SchemaEncoding.ROS2, text.encode())
            schema = self._schemas[ros_type] = (schema_id, serialize_dynamic(ros_type, text)[ros_type])
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = self._writer.register_channel(
                topic, MessageEncoding.CDR, schema[0], {"offered_qos_profiles": qos_yaml(offered)}
            )
        data = schema[1](to_ros_dict(msg))
        self._writer.add_message(channel, log_time, data, log_time, self._sequence[topic])
        self._sequence[topic] += 1
        self.stats.written += 1
        self.stats.by_topic[topic] += 1

    def _flush(self, sync: bool) -> None:
        self._writer.flush()
        if sync:
            self._fsync()

    def _fsync(self) -> None:
        try:
            os.fsync(self._stream.fileno())
        except (AttributeError, OSError, ValueError):  # an in-memory stream or a pipe: flushed is all there is
            pass
