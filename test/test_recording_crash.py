"""A recording cut by ``kill -9`` of the run: readable up to its last flushed chunk, no encoder left behind.

The real ``mcap`` CLI (``mcap doctor``, ``mcap recover``) is not on a CI machine; docs/recording.md
records its verdict on such a file.  Here the ``mcap`` library reads the cut file record by record
as ``mcap recover`` does, and ``mcap-ros2-support`` decodes every message in it.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader
from mcap.records import Chunk, DataEnd, Footer, MessageIndex
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

from execution_engine.recorder.reading import MAGIC, Recording, iter_messages

pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds the encoder process through /proc (Linux)")

REPO = Path(__file__).resolve().parent.parent


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:  # gone meanwhile
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def record_ends(data: bytes) -> list[int]:
    """Where each record of an MCAP file ends (opcode, 8-byte length, content), from the magic on."""
    ends, at = [len(MAGIC)], len(MAGIC)
    while at + 9 <= len(data):
        at += 9 + int.from_bytes(data[at + 1:at + 9], "little")
        ends.append(at)
    return ends


def wait_until(condition: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return bool(condition())  # type: ignore[operator]


def test_a_killed_run_leaves_a_recording_readable_to_its_last_chunk_and_no_encoder(tmp_path: Path) -> None:
    record = tmp_path / "killed.mcap"
    run = subprocess.Popen(  # noqa: S603 - our own CLI
        [sys.executable, "-m", "execution_engine", "run", "apps_xml/rivet_installation.xml", "--speed", "5", "-q",
         "--no-check", "--record", str(record)],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        assert wait_until(lambda: len(children(run.pid)) == 1, 60), "the run starts one encoder process"
        [encoder] = children(run.pid)
        # chunks are flushed at least every second: wait for a few of them, then kill in the middle of the run
        assert wait_until(lambda: record.exists() and record.stat().st_size > 100_000, 120)
        assert run.poll() is None, "still running when killed"
        os.kill(run.pid, signal.SIGKILL)
        run.wait(10)
        assert wait_until(lambda: not alive(encoder), 10), "the encoder ends with the run it served"
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)

    data = record.read_bytes()
    assert record_ends(data)[-1] == len(data), "cut between two records: what was flushed is whole"
    kinds = []
    with open(record, "rb") as stream:  # record by record, as `mcap recover` reads it
        try:
            for item in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
                kinds.append(type(item))
        except EndOfFile:  # no footer: the stream just ends
            pass
    assert Chunk in kinds and Footer not in kinds and DataEnd not in kinds
    assert kinds[-1] is MessageIndex, "the last thing flushed: a whole chunk and its message indexes"

    decoded = []
    with open(record, "rb") as stream:
        reader = NonSeekingReader(stream, decoder_factories=[DecoderFactory()])
        try:
            for _, channel, _, msg in reader.iter_decoded_messages(log_time_order=False):
                decoded.append((channel.topic, msg))
        except EndOfFile:
            pass
    topics = {topic for topic, _ in decoded}
    assert len(decoded) > 100 and {"/joint_states", "/left_arm/sm/status", "/execution_engine/status"} <= topics

    recording = Recording(str(record))
    assert sum(1 for _ in iter_messages(record, recording)) == len(decoded)
    assert recording.cut and "dual_arm_executive" in recording.metadata
