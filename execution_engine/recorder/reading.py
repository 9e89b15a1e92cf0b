"""Reading a recording back: its messages decoded by ``mcap-ros2-support``, whether it was cut,
and the run's events in the trace's own record shape (so the report and the timeline read a
recording and a JSON-lines trace alike).

The file is read as a stream from the start (never through its summary), so a recording cut by a
crash yields every message up to its last whole chunk and then says it was cut; one without a
footer was cut.  Messages come in file order, which is the order they were received.  The file
is outside input: whatever the libraries raise on damaged bytes (a bad CRC, a broken zstd frame,
a schema that does not parse) ends the reading there, marked cut, never with a traceback.
"""
from __future__ import annotations

import contextlib
import io
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import NonSeekingReader
from mcap.records import Footer
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

from execution_engine.observers import engine_record, trace_record
from execution_engine.transport import codec
from execution_engine.transport.wire import EngineEvent, SmStatus

MAGIC = b"\x89MCAP0\r\n"
_STATUS = re.compile(r"^(?:/[A-Za-z0-9_]+)*/([A-Za-z0-9_]+)/sm/status$")
_EVENTS = re.compile(r"^(?:/[A-Za-z0-9_]+)*/execution_engine/events$")


@dataclass
class DecodedMessage:
    topic: str
    ros_type: str
    log_time_ns: int
    msg: Any  # the decoded ROS message (attributes named as the .msg fields)


@dataclass
class Recording:
    """What a read of a recording found besides its messages."""

    path: str
    cut: bool = False
    problem: str = ""  # why reading stopped early
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    messages: int = 0
    start_ns: int | None = None  # the first message's log time


def is_mcap(path: str | Path) -> bool:
    with open(path, "rb") as stream:
        return stream.read(len(MAGIC)) == MAGIC


def iter_messages(path: str | Path, recording: Recording) -> Iterator[DecodedMessage]:
    """Every message of ``path`` decoded, in file order; fills ``recording`` as it goes."""
    with open(path, "rb") as stream:
        reader = NonSeekingReader(stream, decoder_factories=[DecoderFactory()])
        messages = reader.iter_decoded_messages(log_time_order=False)
        while True:
            try:
                with contextlib.redirect_stderr(io.StringIO()):  # the schema parser prints what it refuses
                    schema, channel, message, decoded = next(messages)
            except StopIteration:
                break
            except Exception as error:  # noqa: BLE001 - a cut or damaged file (any of the libraries' errors): keep what came before
                recording.cut = True
                recording.problem = f"{type(error).__name__}: {error}".rstrip(": ")[:300]
                break
            recording.messages += 1
            if recording.start_ns is None:
                recording.start_ns = message.log_time
            yield DecodedMessage(channel.topic, schema.name if schema else "", message.log_time, decoded)
    _read_extras(path, recording)


def _read_extras(path: str | Path, recording: Recording) -> None:
    """Metadata, attachments and the footer (present only in a whole file)."""
    footer = False
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                name = type(record).__name__
                if name == "Metadata":
                    recording.metadata[record.name] = dict(record.metadata)
                elif name == "Attachment":
                    recording.attachments[record.name] = bytes(record.data)
                elif isinstance(record, Footer):
                    footer = True
        except Exception:  # noqa: BLE001 - damaged: what was read so far stands, and the file counts as cut
            pass
    if not footer:
        recording.cut = True


def trace_records(path: str | Path, recording: Recording) -> Iterator[dict[str, Any]]:
    """The run's machine status and engine events as trace records (:mod:`execution_engine.observers`)."""
    for message in iter_messages(path, recording):
        data = getattr(message.msg, "data", None)
        if message.ros_type != "std_msgs/msg/String" or not isinstance(data, str):  # (a damaged schema may lack the field)
            continue
        match = _STATUS.match(message.topic)
        try:
            if match is not None:
                yield trace_record(codec.decode(SmStatus, data, source=message.topic))
            elif _EVENTS.match(message.topic):
                yield engine_record(codec.decode(EngineEvent, data, source=message.topic))
        except codec.WireError:
            continue
