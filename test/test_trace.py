"""The trace as a record that survives what went wrong: flushed per record, synced, ended, readable back."""
from __future__ import annotations

import errno
import io
import json
from pathlib import Path

from execution_engine.observers import TraceWriter
from execution_engine.trace_report import read_trace
from node_transport.wire import EngineStatus, SmStatus


class Recording(io.StringIO):
    """A stream that remembers what had reached the operating system at each flush."""

    def __init__(self) -> None:
        super().__init__()
        self.flushed: list[str] = []

    def flush(self) -> None:
        self.flushed.append(self.getvalue())


class Full(io.StringIO):
    """/dev/full: every write fails with ENOSPC."""

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")


def status(t: float, to: str) -> SmStatus:
    return SmStatus(group="left_arm", event="transition", state=to, t=t, from_state="Ready", to_state=to, signal="x", operation="1")


def test_every_record_reaches_the_system_as_it_is_written() -> None:
    stream = Recording()
    writer = TraceWriter(stream)
    writer.on_status(status(0.5, "Motion"))
    writer.on_status(status(1.0, "Ready"))
    assert [text.count("\n") for text in stream.flushed] == [1, 2]  # nothing waits in a buffer


def test_a_whole_trace_ends_with_how_the_run_ended(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    with open(path, "w", encoding="utf-8") as stream:
        writer = TraceWriter(stream)
        writer.on_status(status(0.5, "Motion"))
        writer.on_engine(EngineStatus(app="a", state="running", operation_index=1, operation_count=2, t=0.5, operation_id="2"))
        writer.finish(2.0, "finished", 0, 2, 2)
    last = json.loads(path.read_text().splitlines()[-1])
    assert last == {"t": 2.0, "event": "run_end", "group": "engine", "outcome": "finished", "exit_code": 0,
                    "operations_done": 2, "operations_total": 2, "records": 2}
    summary = read_trace(path)
    assert not summary.cut and summary.records == 2
    assert "ended: finished (exit code 0), operations 2/2" in "\n".join(summary.lines())


def test_a_full_disk_loses_the_trace_not_the_run() -> None:
    writer = TraceWriter(Full())
    writer.on_status(status(0.5, "Motion"))
    writer.on_status(status(1.0, "Ready"))
    writer.finish(1.0, "finished", 0, 1, 1)
    assert writer.error is not None and writer.error.errno == errno.ENOSPC
    assert writer.lines == 0 and writer.lost == 3


def test_a_cut_trace_says_so_and_where_it_stops(tmp_path: Path) -> None:
    path = tmp_path / "cut.jsonl"
    lines = [json.dumps({"t": 0.5, "event": "transition", "group": "left_arm", "from": "Ready", "to": "Motion"}),
             json.dumps({"t": 1.25, "event": "transition", "group": "left_arm", "from": "Motion", "to": "Ready"})]
    path.write_text("\n".join(lines) + "\n" + '{"t": 1.3, "event": "tra')  # killed in the middle of a write
    summary = read_trace(path)
    assert summary.cut and summary.incomplete_tail and summary.records == 2
    text = "\n".join(summary.lines())
    assert "CUT: no run_end record" in text and "at 1.250 s (left_arm Motion -> Ready)" in text
    assert "the last line is incomplete" in text


def test_lines_that_are_not_records_are_named_not_fatal(tmp_path: Path) -> None:
    path = tmp_path / "mixed.jsonl"
    path.write_bytes(b'not json\n[1, 2]\n\xff\xfe\n{"t": 1, "event": "run_end", "outcome": "finished"}\n' + b"x" * 50 + b"\n")
    summary = read_trace(path)
    assert not summary.cut and summary.problem_count == 4
    assert summary.problems[0].startswith("line 1: not JSON") and summary.problems[1] == "line 2: not a trace record (needs 'event' and 't')"


def test_an_in_memory_stream_keeps_every_record_across_operation_boundaries() -> None:
    stream = io.StringIO()  # fileno() raises io.UnsupportedOperation, an OSError
    writer = TraceWriter(stream)
    writer.on_engine(EngineStatus(app="a", state="running", operation_index=1, operation_count=2, t=0.5, operation_id="1"))
    writer.on_status(status(0.6, "Motion"))
    assert writer.error is None and writer.lines == 1 and stream.getvalue().count("\n") == 1
