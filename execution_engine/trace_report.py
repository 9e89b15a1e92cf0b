"""Reading a run's JSON-lines trace back: what happened, and whether the record is whole.

``python -m execution_engine report run.jsonl`` is what an integrator runs after a night shift
went wrong.  The first question is whether the trace can be trusted: a complete trace ends with
a ``run_end`` record (:class:`execution_engine.observers.TraceWriter`); one without it was cut
(the run was killed, the machine lost power) and the report says so, with the last event the
trace still holds.  Lines that are not trace records (a file edited by hand, another file given
by mistake) are named by line number and skipped, never fatal -- a record at a time no run has
(``1e308``, ``NaN``) or nested deeper than any record among them; the file is read in bounded
memory, line by line, with a size limit per line, and a file naming more groups than a robot has
is refused (OverLimit, one line: :mod:`execution_engine.record_limits`).  Every name and text it shows comes from the file, so it
is shown with its control and bidirectional characters escaped (:func:`printable`).
"""
from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core_functions.printable import printable
from execution_engine.record_limits import MAX_NESTING, GroupCount, nesting_problem, time_problem

MAX_LINE = 1 << 20  # bytes: a trace line is a few hundred bytes; a megabyte is not a trace line
MAX_PROBLEMS = 20  # problem lines listed; the rest are counted


@dataclass
class TraceSummary:
    """What a trace file holds."""

    path: str
    records: int = 0
    by_event: Counter[str] = field(default_factory=Counter)
    by_group: Counter[str] = field(default_factory=Counter)
    errors: list[str] = field(default_factory=list)  # the error texts of error records
    operator: list[str] = field(default_factory=list)  # one line per operator command
    breakpoints: list[str] = field(default_factory=list)  # one line per pause before an operation (engine/breakpoints.py)
    last: dict[str, Any] | None = None  # the last valid record
    end: dict[str, Any] | None = None  # the run_end record, if the trace is whole
    problems: list[str] = field(default_factory=list)  # lines that are not records
    problem_count: int = 0
    incomplete_tail: bool = False  # the file does not end with a newline: its last write was cut
    on_record: Callable[[dict[str, Any]], None] | None = field(default=None, repr=False, compare=False)
    groups: GroupCount | None = field(default=None, repr=False, compare=False)

    @property
    def cut(self) -> bool:
        return self.end is None

    def lines(self) -> list[str]:
        """The report, one line each."""
        out = [f"trace {printable(self.path)}: {self.records} record(s)"]
        if self.end is not None:
            end = {k: printable(self.end.get(k, "?")) for k in ("outcome", "exit_code", "operations_done", "operations_total")}
            out.append(
                f"  ended: {end['outcome']} (exit code {end['exit_code']}), operations "
                f"{end['operations_done']}/{end['operations_total']}, at {self.end['t']:.3f} s"
            )
        else:
            where = f"at {self.last.get('t', 0):.3f} s ({printable(_describe(self.last))})" if self.last else "before any record"
            out.append(f"  CUT: no run_end record; the run was killed or crashed; the last event {where}")
        if self.incomplete_tail:
            out.append("  the last line is incomplete (cut in the middle of a write) and was skipped")
        for group, count in sorted(self.by_group.items()):
            out.append(f"  {printable(group):<12} {count} record(s)")
        out.extend(f"  breakpoint: {printable(line)}" for line in self.breakpoints)
        out.extend(f"  operator: {printable(line)}" for line in self.operator)
        out.extend(f"  error: {printable(text)}" for text in self.errors)
        if self.problem_count:
            out.append(f"  {self.problem_count} line(s) are not trace records:")
            out.extend(f"    {printable(p)}" for p in self.problems)
            if self.problem_count > len(self.problems):
                out.append(f"    and {self.problem_count - len(self.problems)} more")
        return out


def _describe(record: dict[str, Any]) -> str:
    event = record.get("event", "?")
    group = record.get("group", "?")
    if event == "transition":
        return f"{group} {record.get('from')} -> {record.get('to')}"
    return f"{group} {event}"


def read_trace(path: str | Path, on_record: Callable[[dict[str, Any]], None] | None = None) -> TraceSummary:
    """Read ``path`` line by line; raises OSError only when the file cannot be opened or read.
    ``on_record`` sees every valid record in order (the timeline is built from them)."""
    summary = TraceSummary(str(path))
    summary.on_record = on_record
    summary.groups = GroupCount(str(path))
    with open(path, "rb") as stream:
        number = 0
        while True:
            raw = stream.readline(MAX_LINE + 1)
            if not raw:
                break
            number += 1
            if not raw.endswith(b"\n"):
                if len(raw) > MAX_LINE:
                    _problem(summary, f"line {number}: longer than {MAX_LINE} bytes")
                    while raw and not raw.endswith(b"\n"):  # skip the rest of the monster line
                        raw = stream.readline(MAX_LINE + 1)
                    continue
                summary.incomplete_tail = True
                break
            _take(summary, number, raw)
    return summary


def _take(summary: TraceSummary, number: int, raw: bytes) -> None:
    try:
        record = json.loads(raw)
    except RecursionError:  # the parser's own stack: lists or objects thousands deep
        _problem(summary, f"line {number}: nested more than {MAX_NESTING} levels deep: no record of a run is")
        return
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        _problem(summary, f"line {number}: not JSON ({error})")
        return
    if not (isinstance(record, dict) and isinstance(record.get("event"), str) and "t" in record):
        _problem(summary, f"line {number}: not a trace record (needs 'event' and 't')")
        return
    problem = time_problem(record["t"]) or nesting_problem(record)
    if problem is not None:
        _problem(summary, f"line {number}: {problem}")
        return
    if summary.groups is not None:
        summary.groups.see(str(record.get("group", "?")), f"line {number}")
    summary.records += 1
    if summary.on_record is not None:
        summary.on_record(record)
    summary.by_event[record["event"]] += 1
    summary.by_group[str(record.get("group", "?"))] += 1
    summary.last = record
    if record["event"] == "run_end":
        summary.end = record
    elif record["event"] == "error" and isinstance(record.get("error"), str):
        summary.errors.append(f"{record.get('group')} at {record['t']:.3f} s: {record['error']}")
    elif record["event"] == "operator":
        answer = "accepted" if record.get("accepted") else "refused"
        target = f" {record['target']}" if record.get("target") else ""  # the operation a breakpoint or run-to command names
        summary.operator.append(f"{record['t']:.3f} s {record.get('command')}{target} from {record.get('source')}: {answer}")
    elif record["event"] == "breakpoint":  # the run paused before an operation, or passed it (engine/breakpoints.py)
        summary.breakpoints.append(f"{record['t']:.3f} s {record.get('group')}: {record.get('message')}")
    elif record["event"] == "swap":  # a paused run's remainder edited (engine/remainder_swap.py)
        summary.operator.append(f"{record['t']:.3f} s edit from {record.get('source')}: operations from {record.get('from_operation')} on "
                                f"swapped for {record.get('file')}'s, application {str(record.get('from_digest'))[:12]} -> {str(record.get('to_digest'))[:12]}")


def _problem(summary: TraceSummary, text: str) -> None:
    summary.problem_count += 1
    if len(summary.problems) < MAX_PROBLEMS:
        summary.problems.append(text)
