"""Operation boundaries ask the recording for a sync; a run of short operations asks hundreds a second.

What a user relies on: every sync asked for is done (the chunk so far is on disk) within a bounded
time, yet the file is not cut into a chunk per operation and the writer's thread is not woken for
each one (that cost the control loop more than the recording itself in a run of one-primitive
operations): syncs are held back to one per ``SYNC_GAP``.
"""
from __future__ import annotations

import io
import threading
import time

from mcap.reader import make_reader

from execution_engine.recorder.writer import SYNC_GAP, McapSink
from node_transport import msgs
from node_transport.qos import EVENTS


class Memory(io.BytesIO):
    def close(self) -> None:  # the sink closes its stream; the test still reads it
        pass


class CountingEvent(threading.Event):
    def __init__(self) -> None:
        super().__init__()
        self.sets = 0

    def set(self) -> None:
        self.sets += 1
        super().set()


def test_a_burst_of_syncs_is_all_done_with_few_chunks_and_few_wake_ups() -> None:
    stream = Memory()
    sink = McapSink(stream, "memory")
    wake = sink._wake = CountingEvent()  # noqa: SLF001 - the feeder reads the attribute at every wait
    started = time.monotonic()
    done = []
    for i in range(500):  # 500 one-message operations, as fast as the loop goes
        sink.put("/chatter", msgs.String(str(i)), (EVENTS,), 1_000_000_000 + i)
        done.append(sink.sync())
    assert all(event.wait(10) for event in done)
    elapsed = time.monotonic() - started
    stats = sink.close()
    assert stats.written == 500 and not stats.dropped and not stats.error
    assert wake.sets <= 2 + elapsed / SYNC_GAP  # not once per sync asked for
    summary = make_reader(io.BytesIO(stream.getvalue())).get_summary()
    assert summary is not None and summary.statistics.message_count == 500
    assert len(summary.chunk_indexes) <= 3 + elapsed / SYNC_GAP
