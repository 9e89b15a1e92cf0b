"""A run's record read back -- an MCAP recording or a JSON-lines trace -- the one way every reader reads it.

``report`` and ``studio --replay`` read files from outside: a recording or a trace from another
computer, cut by a crash, or crafted.  Both read it through :func:`read_record`, so both have the
same bounds and say the same thing about the same file (``run --resume`` reads the traces of the
runs it continues through the same trace reader, :func:`~execution_engine.trace_report.read_trace`):

* a recording is read without trusting its sizes, its chunks unpacked within a budget in proportion
  to the file's size (:mod:`execution_engine.recorder.safe_read`); a trace line by line, each line
  at most :data:`~execution_engine.trace_report.MAX_LINE` bytes;
* at most :data:`~execution_engine.record_limits.MAX_GROUPS` groups, times a run can have
  (:mod:`execution_engine.record_limits`): a record at another time is skipped and counted;
* a file that asks more than a run's record can is refused with :class:`OverLimit`, one that is
  neither a recording nor a trace with :class:`NotARecording`: one line each, naming the file.

The records come in the trace's own shape whatever the file (:mod:`execution_engine.observers`), one
at a time, so a reader keeps only what it needs.  Names and texts in them are the file's, as they
are: a reader that shows them escapes them (:func:`printable_record`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core_functions.printable import printable
from execution_engine.record_limits import TIME_BOUND, OverLimit
from execution_engine.recorder.reading import Recording, is_mcap, trace_records
from execution_engine.recorder.safe_read import NotARecording
from execution_engine.trace_report import TraceSummary, read_trace

__all__ = ["NotARecording", "OverLimit", "RecordRead", "printable_record", "read_record"]


@dataclass
class RecordRead:
    """What reading a record found besides its records: which kind of file, whether it is whole."""

    path: str
    records: int  # records handed to the reader
    trace: TraceSummary | None = None  # a trace: its summary (problem lines, the run_end record)
    recording: Recording | None = None  # a recording: its metadata, messages, where it was cut

    @property
    def cut(self) -> bool:
        """No end: the run was killed or crashed while it wrote this."""
        return self.recording.cut if self.recording is not None else self.trace is None or self.trace.cut

    def notes(self) -> list[str]:
        """What a reader should tell its user about the file besides its records: one line each, escaped."""
        shown = printable(self.path)
        notes: list[str] = []
        if self.trace is not None:
            if self.trace.problem_count:
                first = f" (first: {printable(self.trace.problems[0])})" if self.trace.problems else ""
                notes.append(f"{shown}: {self.trace.problem_count} line(s) are not trace records and were skipped{first}")
            if self.trace.incomplete_tail:
                notes.append(f"{shown}: the last line is incomplete (cut in the middle of a write) and was skipped")
        if self.recording is not None and self.recording.skipped:
            notes.append(f"{shown}: {self.recording.skipped} event(s) at a time no run has (not finite, or past ±{TIME_BOUND:.0f} s) skipped")
        if self.cut:
            problem = self.recording.problem if self.recording is not None else ""
            where = f"; reading stopped at damaged data: {printable(problem)}" if problem else ""
            notes.append(f"{shown}: no end: the run was cut (killed or crashed){where}")
        return notes


def read_record(path: str | Path, on_record: Callable[[dict[str, Any]], None]) -> RecordRead:
    """Hand every record of the recording or trace at ``path`` to ``on_record``, in order.

    OSError when the file cannot be opened or read; NotARecording when it is neither a recording
    nor a trace (an empty file too); OverLimit when it asks more than a run's record can -- each
    one line naming the file, the rest of the file unread."""
    count = 0

    def take(record: dict[str, Any]) -> None:
        nonlocal count
        count += 1
        on_record(record)

    if is_mcap(path):
        recording = Recording(str(path))
        for record in trace_records(path, recording):
            take(record)
        return RecordRead(str(path), count, recording=recording)
    trace = read_trace(path, take)
    if trace.records == 0:  # not one line of a trace: garbage, or nothing at all
        why = trace.problems[0] if trace.problems else "it is empty" if Path(path).stat().st_size == 0 else "no whole line"
        raise NotARecording(f"{path}: neither an MCAP recording nor a JSON-lines trace: {why}")
    return RecordRead(str(path), count, trace=trace)


def printable_record(value: Any) -> Any:
    """``value`` (a record, or any part of one) with every text in it -- keys too -- escaped by
    :func:`printable`: what a page or a console shows of a file is what the file holds."""
    if isinstance(value, str):
        return printable(value)
    if isinstance(value, dict):
        return {printable(k) if isinstance(k, str) else k: printable_record(v) for k, v in value.items()}
    if isinstance(value, list):
        return [printable_record(v) for v in value]
    return value
