"""A disk that fills as the recording ends: the file's last buffered bytes are written only when it is closed, and
that is where a full disk says so.  The recording is reported incomplete (its error) and the run's own outcome
stands: the close does not raise into the run (which ``run`` would report as "cannot run", exit 2, after a run that
finished)."""
from __future__ import annotations

import errno
import io

from execution_engine.recorder.writer import McapSink
from node_transport import msgs
from node_transport.qos import EVENTS


class FillsOnClose(io.BytesIO):
    """A file whose writes are buffered and whose close finds the disk full, as /dev/full behind a buffered file."""

    def close(self) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_found_at_close_is_the_recordings_error_not_an_exception() -> None:
    sink = McapSink(FillsOnClose(), "full.mcap")
    sink.put("/chatter", msgs.String("hello"), (EVENTS,), 1_000_000_000)
    stats = sink.close()
    assert stats.error == "No space left on device"
    assert "  RECORDING FAILED: No space left on device" in stats.lines()  # what run prints under its summary
