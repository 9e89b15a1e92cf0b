"""Reading a recording back: its messages decoded by ``mcap-ros2-support``, whether it was cut,
and the run's events in the trace's own record shape (so the report and the timeline read a
recording and a JSON-lines trace alike).

The file is read as a stream from the start (never through its summary), so a recording cut by a
crash yields every message up to its last whole chunk and then says it was cut; one without a
footer was cut.  Messages come in file order, which is the order they were received.  The file
is outside input: its sizes are not trusted (:mod:`.safe_read`: no read past the file's end, no
chunk past a bound); whatever the libraries raise on damaged bytes (a bad CRC, a broken zstd
frame, a schema that does not parse) ends the reading there, marked cut, never with a traceback;
a file that is no recording at all (no header after the magic) is refused in one line naming it,
and so is one that asks more than a run's recording can (:class:`OverLimit`: unpacked bytes and
records in proportion to the file's size, groups, :mod:`execution_engine.record_limits`).  Only
the messages the report needs are decoded; events at a time no run has are skipped and counted.
"""
from __future__ import annotations

import contextlib
import io
import math
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Attachment, Channel, Footer, Message, Metadata, Schema
from mcap_ros2.decoder import DecoderFactory

from execution_engine.observers import engine_record, trace_record
from execution_engine.record_limits import GroupCount, OverLimit, time_problem
from execution_engine.run_plan import PlanError, damaged_record, plan_from_fields, plan_records
from execution_engine.recorder.safe_read import DamagedRecord, NotARecording, outer_records, records
from node_transport import codec, typed
from node_transport.wire import EngineEvent, SmStatus

MAGIC = b"\x89MCAP0\r\n"
_STATUS = re.compile(r"^(?:/[A-Za-z0-9_]+)*/([A-Za-z0-9_]+)/sm/status$")
_EVENTS = re.compile(r"^(?:/[A-Za-z0-9_]+)*/execution_engine/events$")
_PLAN = re.compile(r"^(?:/[A-Za-z0-9_]+)*/execution_engine/plan$")


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
    skipped: int = 0  # events at a time no run has (trace_records)


def is_mcap(path: str | Path) -> bool:
    with open(path, "rb") as stream:
        return stream.read(len(MAGIC)) == MAGIC


def iter_messages(path: str | Path, recording: Recording, wanted: Callable[[str, str], bool] | None = None) -> Iterator[DecodedMessage]:
    """Every message of ``path`` decoded (only those ``wanted(topic, type)`` when given: the others
    are counted, not decoded), in file order; fills ``recording`` (metadata, attachments, whether it
    was cut and why) as it goes.  NotARecording, one line naming the file, when it is no MCAP
    recording at all; OverLimit, one line naming the file and the limit, when it asks too much."""
    reading = _Reading(recording, wanted)
    with open(path, "rb") as stream:
        every = records(stream, os.fstat(stream.fileno()).st_size)
        while True:
            try:
                with contextlib.redirect_stderr(io.StringIO()):  # the schema parser prints what it refuses
                    message = reading.take(next(every))
            except StopIteration:
                break
            except NotARecording as error:
                raise NotARecording(f"{path}: not an MCAP recording: {error}") from None
            except OverLimit as error:
                raise OverLimit(f"{path}: {error}") from None
            except Exception as error:  # noqa: BLE001 - a cut or damaged file (any of the libraries' errors): keep what came before
                recording.cut = True
                recording.problem = f"{type(error).__name__}: {error}".rstrip(": ").splitlines()[0][:300]
                break
            if message is not None:
                recording.messages += 1
                if recording.start_ns is None:
                    recording.start_ns = message.log_time_ns
                if message.msg is not _UNDECODED:
                    yield message
    if not reading.footer:
        recording.cut = True


class _Reading:
    """What one pass over a file has seen: schemas, channels and their decoders, the footer."""

    def __init__(self, recording: Recording, wanted: Callable[[str, str], bool] | None = None) -> None:
        self.recording = recording
        self.wanted = wanted
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.decoders: dict[int, Callable[[bytes], Any]] = {}
        self.factory = DecoderFactory()
        self.footer = False

    def take(self, record: Any) -> DecodedMessage | None:
        """One record; the decoded message when it is a message."""
        if isinstance(record, Message):
            channel = self.channels.get(record.channel_id)
            if channel is None:
                raise DamagedRecord(f"a message on channel {record.channel_id}, which no channel record named")
            schema = self.schemas.get(channel.schema_id)
            if self.wanted is not None and not self.wanted(channel.topic, schema.name if schema else ""):
                return DecodedMessage(channel.topic, schema.name if schema else "", record.log_time, _UNDECODED)
            decoder = self.decoders.get(channel.id)
            if decoder is None:
                decoder = self.factory.decoder_for(channel.message_encoding, schema)
                if decoder is None:
                    raise DamagedRecord(f"no decoder for {channel.topic}'s encoding {channel.message_encoding[:40]!r}")
                self.decoders[channel.id] = decoder
            return DecodedMessage(channel.topic, schema.name if schema else "", record.log_time, decoder(record.data))
        if isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            self.channels[record.id] = record
            self.decoders.pop(record.id, None)
        elif isinstance(record, Metadata):
            self.recording.metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Attachment):
            self.recording.attachments[record.name] = bytes(record.data)
        elif isinstance(record, Footer):
            self.footer = True
        return None


#: What a message not asked for holds: it was counted, not decoded.
_UNDECODED = object()


@dataclass(frozen=True)
class _Epoch:
    epoch: float


def trace_records(path: str | Path, recording: Recording) -> Iterator[dict[str, Any]]:
    """The run's machine status and engine events as trace records (:mod:`execution_engine.observers`).

    Their ``t`` is run time: the header stamps less the run clock's epoch, which the metadata at
    the file's end holds (read first, from the records outside chunks: nothing is unpacked for it;
    a cut file: the first message's time).  So the events stream through, none is kept.  An event
    at a time no run has is skipped and counted (``recording.skipped``); OverLimit past
    :data:`~execution_engine.record_limits.MAX_GROUPS` groups."""
    stated = _stated_epoch(path)
    epoch: _Epoch | None = _Epoch(stated) if stated is not None else None
    groups = GroupCount(str(path))
    for message in iter_messages(path, recording, wanted=_is_event):
        if epoch is None:
            epoch = _Epoch((recording.start_ns or 0) * 1e-9)
        if _PLAN.match(message.topic):  # the plan the run was checked against: the trace's plan records
            yield from _plan_records(message, epoch)
            continue
        cls = SmStatus if _STATUS.match(message.topic) else EngineEvent
        try:  # (a damaged schema may lack a field)
            decoded = typed.from_fields(cls, message.msg, epoch, source=message.topic)
        except codec.WireError:
            continue
        record = trace_record(decoded) if isinstance(decoded, SmStatus) else engine_record(decoded)
        if time_problem(record.get("t")) is not None:
            recording.skipped += 1
            continue
        groups.see(str(record.get("group", "?")), f"on {message.topic}")
        yield record


def _plan_records(message: DecodedMessage, epoch: _Epoch) -> list[dict[str, Any]]:
    """A recorded plan as the trace's ``plan`` records; one saying it is damaged when it cannot be taken."""
    try:
        t = typed.run_time(epoch, message.msg.header.stamp)
    except (AttributeError, TypeError, ValueError, OverflowError):
        return [damaged_record(0.0, "its header.stamp is no time")]
    t = t if time_problem(t) is None else 0.0
    try:
        return plan_records(plan_from_fields(message.msg), t)
    except PlanError as error:
        return [damaged_record(round(t, 6), str(error))]


def _is_event(topic: str, ros_type: str) -> bool:
    """A machine's status, the engine's events or the run's plan: what the report reads of a recording."""
    if _STATUS.match(topic):
        return ros_type == str(typed.MachineStatusMsg.ROS_TYPE)  # type: ignore[attr-defined]
    if _PLAN.match(topic):
        return ros_type == str(typed.RunPlanMsg.ROS_TYPE)  # type: ignore[attr-defined]
    return bool(_EVENTS.match(topic)) and ros_type == str(typed.EngineEventMsg.ROS_TYPE)  # type: ignore[attr-defined]


def _stated_epoch(path: str | Path) -> float | None:
    """The run clock's epoch the recording's metadata states (the last one), if finite; None otherwise."""
    found: float | None = None
    try:
        with open(path, "rb") as stream:
            for record in outer_records(stream, os.fstat(stream.fileno()).st_size):
                if isinstance(record, Metadata) and record.name == "dual_arm_executive":
                    try:
                        value = float(record.metadata.get("clock_epoch", ""))
                    except ValueError:
                        continue
                    found = value if math.isfinite(value) and abs(value) < 1e12 else None
    except OverLimit as error:
        raise OverLimit(f"{path}: {error}") from None
    except Exception:  # noqa: BLE001 - a cut or damaged file: what was read before the damage
        pass
    return found
