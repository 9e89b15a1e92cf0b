"""``report`` reads any file in bounded time and memory, and shows what the file holds, not what it pretends.

A small file cannot make the reader unpack, parse or draw more than a run's record of its size
would: unpacked bytes and records in proportion to the file, at most 64 groups, times a run can
have; past a bound the file is refused in one line naming it and the bound.  Names from a file
(operation ids, groups, functions, error texts) reach the console and the report with their control
and bidirectional characters escaped, and an application may not hold such characters in its ids.
"""
from __future__ import annotations

import io
import json
import math
import struct
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import zstandard
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from cell_runner.cli import main
from cell_runner.run_report import summarize
from core_functions.printable import is_unsafe, printable, unsafe_character
from execution_engine.record_limits import MAX_GROUPS, OverLimit
from execution_engine.recorder.reading import MAGIC
from execution_engine.recorder.safe_read import MAX_CHUNK, Budget, NotARecording
from execution_engine.recorder.writer import McapSink
from execution_engine.trace_report import read_trace
from node_transport import typed
from node_transport.clock import Clock
from node_transport.qos import EVENTS
from node_transport.wire import SmStatus

RLO, ESC = "\u202e", "\x1b"


def text(value: str) -> bytes:
    return struct.pack("<I", len(value)) + value.encode()


def record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


HEADER = record(0x01, text("ros2") + text("crafted"))


def chunk(data: bytes, uncompressed_size: int) -> bytes:
    body = struct.pack("<QQQI", 0, 0, uncompressed_size, 0) + text("zstd") + struct.pack("<Q", len(data)) + data
    return record(0x06, body)


def zeros_bomb(chunks: int, size: int = 64_000_000, inner: bytes | None = None) -> bytes:
    """What the issue found: chunks of ``size`` unpacked bytes (zeros: empty records; or ``inner``) in a few KB."""
    payload = zstandard.ZstdCompressor(level=19).compress(inner if inner is not None else b"\0" * size)
    return MAGIC + HEADER + b"".join(chunk(payload, size) for _ in range(chunks))


def peak(action: Callable[[], object]) -> tuple[int, object]:
    """The most memory Python held while ``action`` ran, and what it returned or raised."""
    tracemalloc.start()
    try:
        try:
            result: object = action()
        except Exception as error:  # noqa: BLE001 - the outcome is the test's to judge
            result = error
        return tracemalloc.get_traced_memory()[1], result
    finally:
        tracemalloc.stop()


def report(path: Path, *extra: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(["report", str(path), *extra], out, err)
    return code, out.getvalue(), err.getvalue()


# ---------------------------------------------------------------------------------- MCAP
def test_chunks_of_zeros_are_refused_at_the_record_bound_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "bomb.mcap"
    path.write_bytes(zeros_bomb(3))
    assert path.stat().st_size < 10_000
    held, outcome = peak(lambda: summarize(path))
    assert isinstance(outcome, OverLimit), outcome
    limit = Budget(path.stat().st_size).records_limit
    assert str(outcome) == (f"{path}: refused: it holds more than {limit:,} records, the limit for a file of {path.stat().st_size:,} bytes "
                            "(20,000 and one per 4 bytes of the file; a run's recording has one per 130): a crafted or damaged file")
    assert held < MAX_CHUNK + (16 << 20)  # one chunk at a time, never the whole file's claims
    code, out, err = report(path)
    assert (code, out) == (1, "") and err == f"error: {outcome}\n"
    assert not (tmp_path / "bomb.timeline.svg").exists()


def test_chunks_past_the_unpacked_bound_are_refused_before_they_are_unpacked(tmp_path: Path) -> None:
    size = 64_000_000
    inner = struct.pack("<BQ", 0x80, size - 9) + b"\0" * (size - 9)  # one record of a kind no reader knows, the whole chunk long
    path = tmp_path / "bomb.mcap"
    path.write_bytes(zeros_bomb(20, size, inner))
    held, outcome = peak(lambda: summarize(path))
    assert isinstance(outcome, OverLimit) and "refused: its chunks unpack to more than 7" in str(outcome), outcome
    assert str(outcome).startswith(f"{path}: ") and "\n" not in str(outcome)
    assert held < MAX_CHUNK + (16 << 20)


def status_recording(groups: int, times: list[float] | None = None) -> bytes:
    """A recording of machine status messages: one transition per group (or one per time, on left_arm)."""
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign]
    sink = McapSink(stream, "memory", chunk_size=4096)
    clock = Clock(epoch=1_000.0)
    names = [f"g{i}" for i in range(groups)] if times is None else ["left_arm"] * len(times)
    for i, (group, t) in enumerate(zip(names, times or [0.1 * i for i in range(groups)])):
        status = SmStatus(group=group, event="transition", state="Motion", t=t, from_state="Ready", to_state="Motion", signal="motion_request", operation="1")
        sink.put(f"/{group}/sm/status", typed.to_msg(status, clock), (EVENTS,), 1_000_000 + i)
    sink.close()
    return stream.getvalue()


def test_a_recording_naming_more_groups_than_a_robot_has_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "groups.mcap"
    path.write_bytes(status_recording(MAX_GROUPS + 1))
    with pytest.raises(OverLimit) as refused:
        summarize(path)
    assert str(refused.value).startswith(f"{path}: refused: more than {MAX_GROUPS} groups (on /g{MAX_GROUPS}/sm/status), the 65th 'g{MAX_GROUPS}'")
    path.write_bytes(status_recording(MAX_GROUPS))
    assert len(summarize(path).timeline.lanes) == MAX_GROUPS


# --------------------------------------------------------------------------------- traces
def trace_line(**fields: Any) -> str:
    return json.dumps({"event": "function_start", "t": 0.0, "group": "left_arm", "operation": "1", "function": "wait", **fields}) + "\n"


def test_a_trace_naming_more_groups_than_a_robot_has_is_refused_at_its_line(tmp_path: Path) -> None:
    path = tmp_path / "groups.jsonl"
    path.write_text("".join(trace_line(group=f"g{i}", t=0.01 * i) for i in range(20_000)))
    code, out, err = report(path)
    assert (code, out) == (1, "")
    assert err == (f"error: {path}: refused: more than {MAX_GROUPS} groups (line 65), the 65th 'g64'; "
                   "a robot's run has a few, each a lane of the report: a damaged or crafted file\n")


@pytest.mark.parametrize("t", ["1e308", "-1e308", "NaN", "Infinity", "\"soon\"", "true"])
def test_a_record_at_a_time_no_run_has_is_refused_at_its_line(tmp_path: Path, t: str) -> None:
    path = tmp_path / "times.jsonl"
    path.write_text(trace_line(t=1.0) + trace_line(t=2.0).replace('"t": 2.0', f'"t": {t}') + trace_line(event="function_end", t=3.0))
    summary = read_trace(path)
    assert summary.records == 2 and summary.problem_count == 1
    assert summary.problems[0].startswith("line 2: t = ")
    code, out, _ = report(path, "--no-timeline")
    assert code == 0 and "run time 2.000 s" in out  # the other records, read as they are


def test_a_recording_at_a_time_no_run_has_skips_the_event_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "times.mcap"
    path.write_bytes(status_recording(0, times=[1.0, 2e7, 3.0]))
    summary = summarize(path)
    assert "  1 event(s) at a time no run has (not finite, or past ±10000000 s) skipped" in summary.lines()
    assert summary.timeline.t_end - summary.timeline.t_start == pytest.approx(2.0)


# ------------------------------------------------------------------------------ timeline
def test_drawing_a_long_run_makes_one_artist_per_look_not_per_bar(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from matplotlib.axes import Axes  # matplotlib is slow to load (0.4 s): only the drawing tests need it

    lines = []
    for i in range(3000):
        group = f"g{i % 3}"
        lines.append(trace_line(group=group, operation=str(i), t=0.01 * i))
        lines.append(trace_line(event="primitive_start", group=group, t=0.01 * i + 0.001, primitive="p", index=0, state="Motion"))
        lines.append(trace_line(event="primitive_end", group=group, t=0.01 * i + 0.004, outcome="done"))
        lines.append(trace_line(event="function_end", group=group, operation=str(i), t=0.01 * i + 0.005, outcome="succeeded"))
    path = tmp_path / "long.jsonl"
    path.write_text("".join(lines))
    calls = {"text": 0, "barh": 0, "broken_barh": 0}
    for name in calls:
        original = getattr(Axes, name)

        def counted(self: Axes, *args: Any, __name: str = name, __original: Any = original, **kwargs: Any) -> Any:
            calls[__name] += 1
            return __original(self, *args, **kwargs)

        monkeypatch.setattr(Axes, name, counted)
    code, _, err = report(path, "--timeline", str(tmp_path / "long.svg"))
    assert code == 0, err
    assert calls["barh"] == 0 and calls["broken_barh"] <= 3 * 6  # per lane: idle, waits, a bar look or two, a primitive look
    assert calls["text"] <= 4 * 300  # labels capped per lane and for the operations


# ------------------------------------------------------------------------ names escaped
def test_printable_escapes_what_would_move_the_cursor_or_reverse_the_text() -> None:
    assert printable(f"op1{RLO}gnp.exe") == "op1\\u202egnp.exe"
    assert printable(f"{ESC}[2Jcleared\r\n\t\x00\x85") == "\\x1b[2Jcleared\\x0d\\x0a\\x09\\x00\\x85"
    assert printable("Nextage 左腕 ✓ dépôt") == "Nextage 左腕 ✓ dépôt"  # letters of any script stay
    assert printable("\u2066x\u2069\u200f\U000e0001") == "\\u2066x\\u2069\\u200f\\U000e0001"
    assert unsafe_character(f"a{RLO}b") == "RIGHT-TO-LEFT OVERRIDE (U+202E)" and unsafe_character("plain") is None


def test_the_report_shows_names_from_the_file_escaped(tmp_path: Path) -> None:
    path = tmp_path / "spoof.jsonl"
    path.write_text(
        trace_line(group=f"left{RLO}mra", operation=f"1{RLO}gnp.exe", function=f"{ESC}[31mwait")
        + trace_line(event="error", t=1.0, group=f"left{RLO}mra", error=f"drive {ESC}]0;pwned{ESC}\\ fault")
        + json.dumps({"event": "operator", "t": 1.5, "group": "engine", "command": f"stop{RLO}", "source": f"page{ESC}", "accepted": True}) + "\n"
    )
    code, out, err = report(path, "--timeline", str(tmp_path / "spoof.svg"))
    assert code == 0, err
    assert not any(is_unsafe(c) for c in out.replace("\n", "")), out
    assert "left\\u202emra" in out and "drive \\x1b]0;pwned\\x1b\\ fault" in out
    svg = (tmp_path / "spoof.svg").read_text()
    assert RLO not in svg and "\\u202e" in svg


def test_an_operation_id_with_a_bidi_override_is_refused_at_its_line(tmp_path: Path) -> None:
    root = Path(__file__).resolve().parents[1]
    path = tmp_path / "bidi.xml"
    path.write_text(
        f'<?xml version="1.0"?>\n<application name="t" robot="nextage" cell="{root}/apps_xml/cells/rivet_cell.xml">\n'
        f'  <operation id="1{RLO}gnp.exe">\n    <left_arm><function name="gripper_open"/></left_arm>\n  </operation>\n</application>\n',
        encoding="utf-8",
    )
    out, err = io.StringIO(), io.StringIO()
    assert main(["validate", str(path)], out, err) == 1
    assert err.getvalue().splitlines()[0] == (
        f"{path}:3:14: operation id '1\\u202egnp.exe' holds RIGHT-TO-LEFT OVERRIDE (U+202E), which makes an id look like another "
        "on a console or a page; use letters, digits and punctuation")
    assert RLO not in err.getvalue()


# ------------------------------------------------------------------------------ properties
def outcome(path: Path) -> str:
    """What ``report`` makes of a file: a summary whose every line is printable, or one line naming the file."""
    try:
        lines = summarize(path).lines()
    except (NotARecording, OverLimit) as error:
        assert str(error).startswith(f"{path}") and "\n" not in str(error)
        return "refused"
    assert lines and not any(is_unsafe(c) for line in lines for c in line)
    return "summary"


WHOLE = status_recording(0, times=[0.1 * i for i in range(40)])


def bounded(path: Path) -> str:
    held, result = peak(lambda: outcome(path))
    assert held < MAX_CHUNK + (16 << 20), f"{held} bytes held for a {path.stat().st_size}-byte file"
    if isinstance(result, Exception):
        raise result
    return str(result)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, len(WHOLE)), flips=st.lists(st.tuples(st.integers(0, len(WHOLE) - 1), st.integers(1, 255)), max_size=6))
def test_a_recording_cut_or_flipped_anywhere_gives_a_summary_or_one_line(tmp_path: Path, cut: int, flips: list[tuple[int, int]]) -> None:
    path = tmp_path / "flipped.mcap"
    path.write_bytes(flipped(cut, flips))
    bounded(path)


def flipped(cut: int, flips: list[tuple[int, int]]) -> bytes:
    """A whole recording cut at ``cut`` with the bytes at each position xor-ed by its value."""
    data = bytearray(WHOLE[:cut])
    for at, xor in flips:
        if at < len(data):
            data[at] ^= xor
    return bytes(data)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(claims=st.lists(st.integers(0, MAX_CHUNK), min_size=1, max_size=6), records=st.integers(0, 200_000), kind=st.sampled_from([0x00, 0x05, 0x80]))
@example(claims=[64_000_000] * 3, records=7_100_000, kind=0x00)  # the file: chunks of zeros
def test_crafted_chunks_never_pass_the_bounds(tmp_path: Path, claims: list[int], records: int, kind: int) -> None:
    """Chunks that claim anything up to the per-chunk bound, hold runs of tiny records, or lie about either."""
    path = tmp_path / "crafted.mcap"
    path.write_bytes(crafted_chunks(claims, records, kind))
    bounded(path)


def crafted_chunks(claims: list[int], records: int, kind: int) -> bytes:
    """A recording of one zstd chunk per claim, each claiming that many bytes and holding ``records`` empty records of ``kind``."""
    inner = (struct.pack("<BQ", kind, 0) * records)[: max(claims)]
    payload = zstandard.ZstdCompressor().compress(inner)
    return MAGIC + HEADER + b"".join(chunk(payload, claim) for claim in claims)


TRACE_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30), st.text(max_size=8), st.none(), st.booleans())


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(records=st.lists(st.fixed_dictionaries(
    {"event": st.sampled_from(["function_start", "function_end", "primitive_start", "primitive_end", "error", "flag", "operator", "run_end"]), "t": TRACE_VALUES},
    optional={"group": st.text(max_size=6), "operation": st.text(max_size=6), "function": st.text(max_size=6), "index": TRACE_VALUES,
              "error": st.text(max_size=10), "state": st.sampled_from(["waiting", "passed", "set", "Motion"]), "flag": st.text(max_size=3),
              "outcome": st.text(max_size=6), "result": st.dictionaries(st.sampled_from(["kind", "pose", "score"]), TRACE_VALUES, max_size=3)},
), max_size=60), tail=st.binary(max_size=40))
def test_any_trace_gives_a_summary_with_printable_lines_or_one_line(tmp_path: Path, records: list[dict[str, Any]], tail: bytes) -> None:
    path = tmp_path / "crafted.jsonl"
    lines = [json.dumps(r, allow_nan=True) for r in records]
    path.write_bytes(("\n".join(lines) + "\n").encode() + tail)
    result = bounded(path)
    if result == "summary":
        summary = summarize(path)
        assert math.isfinite(summary.timeline.t_end) and abs(summary.timeline.t_end) <= 1e7
