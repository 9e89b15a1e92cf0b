"""The records of an MCAP file that may be cut, damaged or crafted, read without trusting its sizes.

A recording handed to ``report`` is outside input.  ``mcap``'s readers take every length in the
file at its word: a record, a field or a chunk that claims 4 GB makes them ask for 4 GB (the file
read, the zstd output buffer) even when the file holds 1 KB.  Here every read is capped at what
the file still holds, a record at the file's size, and a chunk is decompressed by our own bounded
loop -- never more than it claims, and never a claim past :data:`MAX_CHUNK` -- and split into its
records one at a time (``mcap`` makes a list of a chunk's records).  The parsing of each record
stays ``mcap``'s.

A small file can still hold a great deal once unpacked: 20 chunks of zeros, 64 MB each, are 111 KB
of zstd, and 7 million empty records each.  So the whole file has a :class:`Budget`, in proportion
to its size, as a run's recording needs it (a recording unpacks to about 4 times its size, a record
takes some 130 bytes of it): :data:`BYTES_FLOOR` plus :data:`BYTES_PER_BYTE` bytes unpacked per byte
of file, :data:`RECORDS_FLOOR` plus one record per :data:`BYTES_PER_RECORD` bytes of file.  Past
either the reading stops with :class:`OverLimit`, one line naming the limit; reading a file costs
time and memory in proportion to its size, whatever it holds.
"""
from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header, McapRecord, Message, Schema
from mcap.stream_reader import StreamReader

from execution_engine.record_limits import OverLimit

MAX_CHUNK = 64 * 1024 * 1024  # bytes a chunk may hold uncompressed (ours are 256 KiB, rosbag2's 768 KiB; one huge image may pass 25 MB)
BYTES_FLOOR = 64 * 1024 * 1024  # bytes any file may unpack to
BYTES_PER_BYTE = 100  # and per byte of the file (a run's recording: about 4)
RECORDS_FLOOR = 20_000  # records any file may hold
BYTES_PER_RECORD = 4  # and one per this many bytes of the file (a run's recording: one per 130)
_PIECE = 1 << 20  # bytes decompressed at a time


class NotARecording(ValueError):
    """The file is no MCAP recording at all: its first record is not a header."""


class DamagedRecord(ValueError):
    """A record's sizes or contents cannot be right; reading stops there."""


@dataclass
class Budget:
    """What one file may make the reader do: bytes unpacked and records parsed, in all."""

    size: int
    unpacked: int = 0
    records: int = 0

    @property
    def bytes_limit(self) -> int:
        return BYTES_FLOOR + BYTES_PER_BYTE * self.size

    @property
    def records_limit(self) -> int:
        return RECORDS_FLOOR + self.size // BYTES_PER_RECORD

    def unpack(self, claimed: int) -> None:
        """Before a chunk is decompressed: OverLimit when its claim would pass the file's bound."""
        if self.unpacked + claimed > self.bytes_limit:
            raise OverLimit(
                f"refused: its chunks unpack to more than {self.bytes_limit:,} bytes in all, the limit for a file of {self.size:,} bytes "
                f"({BYTES_FLOOR >> 20} MiB and {BYTES_PER_BYTE} per byte of the file; a run's recording unpacks to some 4): a crafted or damaged file"
            )
        self.unpacked += claimed

    def record(self) -> None:
        self.records += 1
        if self.records > self.records_limit:
            raise OverLimit(
                f"refused: it holds more than {self.records_limit:,} records, the limit for a file of {self.size:,} bytes "
                f"({RECORDS_FLOOR:,} and one per {BYTES_PER_RECORD} bytes of the file; a run's recording has one per 130): a crafted or damaged file"
            )


class _Bounded:
    """A file that never reads past its end, whatever size is asked for."""

    def __init__(self, raw: IO[bytes], size: int) -> None:
        self._raw = raw
        self._left = size - raw.tell()

    def read(self, size: int = -1) -> bytes:
        size = self._left if size < 0 else min(size, self._left)
        data = self._raw.read(max(0, size))
        self._left -= len(data)
        return data


def decompressed(chunk: Chunk, budget: Budget | None = None) -> bytes | bytearray:
    """A chunk's records, uncompressed in bounded pieces; DamagedRecord when its claim is too
    large or is not what the data holds, OverLimit when it would pass the file's ``budget``."""
    claimed = chunk.uncompressed_size
    if claimed > MAX_CHUNK:
        raise DamagedRecord(f"a chunk claims {claimed} bytes uncompressed (at most {MAX_CHUNK} are read)")
    if budget is not None:
        budget.unpack(claimed)
    if chunk.compression == "":
        data = bytes(chunk.data)
    elif chunk.compression == "zstd":
        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as reader:
            data = _bounded_read(reader, claimed)
    elif chunk.compression == "lz4":
        decompressor = lz4.frame.LZ4FrameDecompressor()
        data = decompressor.decompress(bytes(chunk.data), max_length=claimed + 1)
    else:
        raise DamagedRecord(f"a chunk is compressed with {chunk.compression[:40]!r}, which no reader knows")
    if len(data) != claimed:
        raise DamagedRecord(f"a chunk claims {claimed} bytes uncompressed but holds {'more' if len(data) > claimed else len(data)}")
    return data


def _bounded_read(reader: IO[bytes], claimed: int) -> bytearray:
    """At most ``claimed + 1`` bytes, read in pieces into one growing buffer: as much memory as the
    data holds, never what it claims (a large buffer grows in place; joined pieces would hold the chunk twice)."""
    data = bytearray()
    while len(data) <= claimed:
        piece = reader.read(min(_PIECE, claimed + 1 - len(data)))
        if not piece:
            break
        data += piece
    return data


def records(stream: IO[bytes], size: int, budget: Budget | None = None) -> Iterator[McapRecord]:
    """Every record of the file in order, the records of each chunk in place of the chunk.

    NotARecording when the first record is not a header; whatever ``mcap`` raises (or
    DamagedRecord) where the file is cut or damaged, after the records before it; OverLimit past
    the file's :class:`Budget`."""
    budget = budget if budget is not None else Budget(size)
    reader = StreamReader(_Bounded(stream, size), skip_magic=False, emit_chunks=True, record_size_limit=size)
    every = iter(reader.records)
    try:
        first = next(every)
    except StopIteration:
        raise NotARecording("it ends before its header") from None
    except Exception as error:  # noqa: BLE001 - whatever the library makes of garbage: said in one line
        raise NotARecording(f"no header after the magic ({_said(error)})") from None
    if not isinstance(first, Header):
        raise NotARecording(f"its first record is a {type(first).__name__}, not a header")
    yield first
    for record in every:
        budget.record()
        if isinstance(record, Chunk):
            yield from chunk_records(decompressed(record, budget), budget)
        else:
            yield record


def outer_records(stream: IO[bytes], size: int) -> Iterator[McapRecord]:
    """The records outside chunks (header, metadata, attachments, summary; chunks as they are,
    not unpacked): what a file says of itself, read at the cost of its size alone."""
    budget = Budget(size)
    for record in StreamReader(_Bounded(stream, size), skip_magic=False, emit_chunks=True, record_size_limit=size).records:
        budget.record()
        yield record


def chunk_records(data: bytes | bytearray, budget: Budget) -> Iterator[McapRecord]:
    """The channels, schemas and messages of an unpacked chunk, one at a time (each counted)."""
    raw = _View(data)
    stream = ReadDataStream(raw)  # type: ignore[arg-type] # read() is all it uses
    end = len(data)
    while raw.tell() < end:
        budget.record()
        opcode = stream.read1()
        length = stream.read8()
        if length > end - raw.tell():
            raise DamagedRecord(f"a record in a chunk claims {length} bytes, {end - raw.tell()} are left")
        if opcode == Opcode.CHANNEL:
            yield Channel.read(stream)
        elif opcode == Opcode.MESSAGE:
            yield Message.read(stream, length)
        elif opcode == Opcode.SCHEMA:
            yield Schema.read(stream)
        else:  # an unknown record: skipped (not read: it may be the whole chunk), as mcap skips it
            raw.skip(length)


class _View:
    """The bytes of an unpacked chunk read without copying the chunk (``io.BytesIO`` copies a bytearray)."""

    def __init__(self, data: bytes | bytearray) -> None:
        self._data = memoryview(data)
        self._at = 0

    def read(self, size: int) -> bytes:
        piece = self._data[self._at:self._at + max(0, size)].tobytes()
        self._at += len(piece)
        return piece

    def tell(self) -> int:
        return self._at

    def skip(self, size: int) -> None:
        self._at = min(len(self._data), self._at + size)


def _said(error: Exception) -> str:
    return (f"{type(error).__name__}: {error}".rstrip(": ").splitlines() or [""])[0][:200]
