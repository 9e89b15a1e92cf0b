"""The records of an MCAP file that may be cut, damaged or crafted, read without trusting its sizes.

A recording handed to ``report`` is outside input.  ``mcap``'s readers take every length in the
file at its word: a record, a field or a chunk that claims 4 GB makes them ask for 4 GB (the file
read, the zstd output buffer) even when the file holds 1 KB.  Here every read is capped at what
the file still holds, a record at the file's size, and a chunk is decompressed by our own bounded
loop -- never more than it claims, and never a claim past :data:`MAX_CHUNK` -- before ``mcap``
splits it into its records.  The parsing itself stays ``mcap``'s.
"""
from __future__ import annotations

import dataclasses
import io
from collections.abc import Iterator
from typing import IO

from mcap.records import Chunk, Header, McapRecord
from mcap.stream_reader import StreamReader, breakup_chunk

MAX_CHUNK = 256 * 1024 * 1024  # bytes a chunk may hold uncompressed (ours are 256 KiB, rosbag2's 768 KiB; one huge image may pass 25 MB)
_PIECE = 1 << 20  # bytes decompressed at a time


class NotARecording(ValueError):
    """The file is no MCAP recording at all: its first record is not a header."""


class DamagedRecord(ValueError):
    """A record's sizes or contents cannot be right; reading stops there."""


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


def decompressed(chunk: Chunk) -> bytes:
    """A chunk's records, uncompressed in bounded pieces; DamagedRecord when its claim is too
    large or is not what the data holds."""
    claimed = chunk.uncompressed_size
    if claimed > MAX_CHUNK:
        raise DamagedRecord(f"a chunk claims {claimed} bytes uncompressed (at most {MAX_CHUNK} are read)")
    if chunk.compression == "":
        data = bytes(chunk.data)
    elif chunk.compression == "zstd":
        import zstandard

        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as reader:
            data = _bounded_read(reader, claimed)
    elif chunk.compression == "lz4":
        import lz4.frame

        decompressor = lz4.frame.LZ4FrameDecompressor()
        data = decompressor.decompress(bytes(chunk.data), max_length=claimed + 1)
    else:
        raise DamagedRecord(f"a chunk is compressed with {chunk.compression[:40]!r}, which no reader knows")
    if len(data) != claimed:
        raise DamagedRecord(f"a chunk claims {claimed} bytes uncompressed but holds {'more' if len(data) > claimed else len(data)}")
    return data


def _bounded_read(reader: IO[bytes], claimed: int) -> bytes:
    pieces, total = [], 0
    while total <= claimed:
        piece = reader.read(min(_PIECE, claimed + 1 - total))
        if not piece:
            break
        pieces.append(piece)
        total += len(piece)
    return b"".join(pieces)


def records(stream: IO[bytes], size: int) -> Iterator[McapRecord]:
    """Every record of the file in order, the records of each chunk in place of the chunk.

    NotARecording when the first record is not a header; whatever ``mcap`` raises (or
    DamagedRecord) where the file is cut or damaged, after the records before it."""
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
        if isinstance(record, Chunk):
            yield from breakup_chunk(dataclasses.replace(record, compression="", data=decompressed(record)))
        else:
            yield record


def _said(error: Exception) -> str:
    return (f"{type(error).__name__}: {error}".rstrip(": ").splitlines() or [""])[0][:200]
