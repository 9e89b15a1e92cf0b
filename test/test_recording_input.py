"""A recording is outside input to ``report``: damaged, cut or random bytes never end in a traceback."""
from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cell_runner.run_report import summarize
from execution_engine.recorder.reading import MAGIC
from execution_engine.recorder.safe_read import NotARecording
from execution_engine.recorder.writer import McapSink
from node_transport import msgs, typed
from node_transport.clock import Clock
from node_transport.qos import EVENTS, SENSOR
from node_transport.wire import SmStatus


def small_recording() -> bytes:
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign]
    sink = McapSink(stream, "memory", chunk_size=512)
    clock = Clock(epoch=1_000.0)
    for i in range(40):
        status = SmStatus(group="left_arm", event="transition", state="Motion", t=0.1 * i, from_state="Ready", to_state="Motion", signal="motion_request", operation="1")
        sink.put("/left_arm/sm/status", typed.to_msg(status, clock), (EVENTS,), 1_000_000 + i)
        sink.put("/joint_states", msgs.JointState(msgs.Header(msgs.Time(1, i)), ("a",), (0.1 * i,)), (SENSOR,), 1_000_000 + i)
    sink.close()
    return stream.getvalue()


WHOLE = small_recording()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("mcap_input")


def test_the_whole_recording_reads(folder: Path) -> None:
    path = folder / "whole.mcap"
    path.write_bytes(WHOLE)
    summary = summarize(path)
    assert not summary.cut and len(summary.timeline.lanes["left_arm"].bars) == 0  # transitions only: no function bars


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(min_value=0, max_value=len(WHOLE) - 1))
def test_a_cut_recording_reads_up_to_the_cut_and_says_so(folder: Path, cut: int) -> None:
    path = folder / "cut.mcap"
    path.write_bytes(WHOLE[:cut])
    header_end = len(MAGIC) + 9 + int.from_bytes(WHOLE[len(MAGIC) + 1:len(MAGIC) + 9], "little")
    if cut < header_end:  # no whole header: no recording (nor a trace), refused in one line naming the file
        with pytest.raises(NotARecording, match=f"^{re.escape(str(path))}: [^\n]*$"):
            summarize(path)
        return
    assert summarize(path).cut


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=4096), at=st.integers(min_value=0, max_value=len(WHOLE) - 1), prefix=st.booleans())
def test_damaged_or_random_bytes_never_raise(folder: Path, data: bytes, at: int, prefix: bool) -> None:
    path = folder / "damaged.mcap"
    path.write_bytes(MAGIC + data if prefix else WHOLE[:at] + data + WHOLE[at + len(data):])
    try:
        summary = summarize(path)  # a summary, whatever the bytes ...
    except NotARecording as error:  # ... or, for bytes that are no record at all, one line naming the file
        assert str(error).startswith(f"{path}: ") and "\n" not in str(error)
        return
    assert summary.lines()
