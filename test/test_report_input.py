"""``report`` takes a file from outside: crafted sizes never make it allocate what they claim, and a
file that is no record at all is refused in one line naming it."""
from __future__ import annotations

import io
import struct
import tracemalloc
from pathlib import Path

import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cell_runner.cli import main
from cell_runner.run_report import summarize
from execution_engine.recorder.reading import MAGIC, Recording, iter_messages
from execution_engine.recorder.safe_read import MAX_CHUNK, NotARecording
from execution_engine.recorder.writer import McapSink
from node_transport import msgs
from node_transport.qos import SENSOR

FOUR_GB = 4 * 1024**3


def text(value: str) -> bytes:
    return struct.pack("<I", len(value)) + value.encode()


def record(opcode: int, body: bytes, length: int | None = None) -> bytes:
    return struct.pack("<BQ", opcode, len(body) if length is None else length) + body


HEADER = record(0x01, text("ros2") + text("crafted"))


def chunk(data: bytes, uncompressed_size: int, compression: str = "zstd", records_length: int | None = None) -> bytes:
    body = struct.pack("<QQQI", 0, 0, uncompressed_size, 0) + text(compression)
    body += struct.pack("<Q", len(data) if records_length is None else records_length) + data
    return record(0x06, body)


def peak_while(action: object) -> int:
    """The most memory Python held while ``action`` ran (bytes objects and buffers included)."""
    tracemalloc.start()
    try:
        action()  # type: ignore[operator]
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def read(path: Path) -> Recording:
    recording = Recording(str(path))
    for _ in iter_messages(path, recording):
        pass
    return recording


CRAFTED = {
    # a 1 KB file whose one chunk claims 4 GB uncompressed, in a zstd frame that does not say its size
    # (zstandard.decompress(data, 4 GB), as mcap calls it, would make a 4 GB buffer for it)
    "chunk claims 4 GB": MAGIC + HEADER + chunk(zstandard.ZstdCompressor(write_content_size=False).compress(b"\0" * 900), FOUR_GB),
    "chunk claims more than the bound": MAGIC + HEADER + chunk(b"\0" * 100, MAX_CHUNK + 1, compression=""),
    "lz4 chunk claims 4 GB": MAGIC + HEADER + chunk(b"\x04\x22\x4d\x18" + b"\0" * 60, FOUR_GB, compression="lz4"),
    # a record whose length says 4 GB
    "record claims 4 GB": MAGIC + HEADER + record(0x09, b"\0" * 200, length=FOUR_GB),
    # a chunk record of honest length whose records field says 4 GB
    "chunk field claims 4 GB": MAGIC + HEADER + chunk(b"\0" * 200, 200, compression="", records_length=FOUR_GB),
    # an attachment (outside chunks) whose data length says 4 GB
    "attachment claims 4 GB": MAGIC + HEADER + record(
        0x09, struct.pack("<QQ", 0, 0) + text("a") + text("b") + struct.pack("<Q", FOUR_GB) + b"\0" * 300
    ),
    # a message inside a chunk whose record length says 4 GB
    "message in a chunk claims 4 GB": MAGIC + HEADER + chunk(record(0x05, b"\0" * 40, length=FOUR_GB), 49, compression=""),
}


@pytest.mark.parametrize("name", sorted(CRAFTED))
def test_crafted_sizes_are_never_allocated(tmp_path: Path, name: str) -> None:
    path = tmp_path / "crafted.mcap"
    path.write_bytes(CRAFTED[name])
    assert path.stat().st_size < 2048
    recording = Recording(str(path))
    peak = peak_while(lambda: list(iter_messages(path, recording)))
    assert peak < 8 * 1024 * 1024, f"{name}: {peak} bytes held for a {path.stat().st_size}-byte file"
    assert recording.cut and recording.problem  # read up to the lie, said, and kept what came before
    code = main(["report", str(path), "--no-timeline"], io.StringIO(), err := io.StringIO())
    assert code == 0 and not err.getvalue()


def test_a_chunk_claim_past_the_bound_is_named(tmp_path: Path) -> None:
    path = tmp_path / "big.mcap"
    path.write_bytes(CRAFTED["chunk claims 4 GB"])
    assert f"a chunk claims {FOUR_GB} bytes uncompressed" in read(path).problem


@pytest.mark.parametrize("content, says", [
    (b"\x00\x01garbage\xff" * 100, "neither an MCAP recording nor a JSON-lines trace"),
    (b"", "neither an MCAP recording nor a JSON-lines trace: it is empty"),
    (b"just some words\nand more words\n", "neither an MCAP recording nor a JSON-lines trace: line 1: not JSON"),
    (MAGIC + b"\xff" * 64, "not an MCAP recording: no header after the magic"),
    (MAGIC + record(0x02, b"\0" * 20), "not an MCAP recording: its first record is a Footer, not a header"),
])
def test_garbage_is_refused_in_one_line_naming_the_file(tmp_path: Path, content: bytes, says: str) -> None:
    path = tmp_path / "garbage.mcap"
    path.write_bytes(content)
    out, err = io.StringIO(), io.StringIO()
    code = main(["report", str(path)], out, err)
    assert code == 1 and not out.getvalue()
    assert err.getvalue().count("\n") == 1 and err.getvalue().startswith(f"error: {path}: ") and says in err.getvalue()
    assert not (tmp_path / "garbage.timeline.svg").exists(), "nothing written for a refused file"


def small_recording(tmp_path: Path) -> bytes:
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign]
    sink = McapSink(stream, "memory", chunk_size=400)
    for i in range(30):
        sink.put("/joint_states", msgs.JointState(msgs.Header(msgs.Time(1, i)), ("a", "b"), (0.1 * i, 0.2)), (SENSOR,), 1_000 + i)
    sink.close()
    return stream.getvalue()


WHOLE = small_recording(Path("."))


def _outcome(path: Path) -> str:
    """What ``report`` makes of a file: a summary, or the one-line refusal naming it; anything else fails the test."""
    try:
        lines = summarize(path).lines()
    except NotARecording as error:
        message = str(error)
        assert message.startswith(f"{path}: ") and "\n" not in message
        return "refused"
    assert lines and all(isinstance(line, str) for line in lines)
    return "summary"


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=3000), magic=st.booleans())
def test_random_bytes_give_a_summary_or_a_one_line_refusal(tmp_path: Path, data: bytes, magic: bool) -> None:
    path = tmp_path / "random.mcap"
    path.write_bytes((MAGIC if magic else b"") + data)
    _outcome(path)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(min_value=0, max_value=len(WHOLE)), flips=st.lists(st.tuples(st.integers(0, len(WHOLE) - 1), st.integers(1, 255)), max_size=4))
def test_a_recording_cut_or_damaged_anywhere_is_read_up_to_the_damage(tmp_path: Path, cut: int, flips: list[tuple[int, int]]) -> None:
    data = bytearray(WHOLE[:cut])
    for at, xor in flips:
        if at < len(data):
            data[at] ^= xor
    path = tmp_path / "cut.mcap"
    path.write_bytes(bytes(data))
    header_end = len(MAGIC) + 9 + int.from_bytes(WHOLE[len(MAGIC) + 1:len(MAGIC) + 9], "little")
    outcome = _outcome(path)
    if not flips:  # cut only: a recording exactly when its header is whole, cut unless the whole file is there
        assert outcome == ("summary" if cut >= header_end else "refused")
        if outcome == "summary":
            assert summarize(path).cut == (cut < len(WHOLE))
