"""The flight recorder: a run recorded as MCAP that the mcap reader and mcap-ros2-support decode to ROS types."""
from __future__ import annotations

import dataclasses
import io
import json
import math
import random
import shutil
import tempfile
import threading
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from cell_runner.cli import main
from execution_engine.recorder.definitions import SEPARATOR, schema_text
from execution_engine.recorder.reading import Recording, iter_messages, trace_records
from execution_engine.recorder.recorder import Recorder, reader_qos
from execution_engine.recorder.writer import McapSink
from node_transport import msgs, typed
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.qos import EVENTS, LATCHED, SENSOR, Durability, Reliability
from node_transport.wire import EngineEvent, EngineStatus, GroupProgress, SmStatus, SmStructure, TransitionSpec

RIVET = "apps_xml/rivet_installation.xml"


@pytest.fixture(scope="module")
def rivet_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("rec")
    record, trace = folder / "run.mcap", folder / "run.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", RIVET, "--speed", "max", "-q", "--record", str(record), "--trace", str(trace)], out, err)
    assert code == 0, err.getvalue()
    assert f"recording {record}:" in out.getvalue()
    return record, trace


def _trace(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_every_message_decodes_to_its_ros_type_with_ros2_schemas(rivet_run: tuple[Path, Path]) -> None:
    record, _ = rivet_run
    with open(record, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        assert summary is not None and summary.chunk_indexes, "chunked and indexed"
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        count = 0
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            count += 1
            assert type(decoded).__name__ == schema.name.split("/")[-1]
        assert count == summary.statistics.message_count > 1000
    assert types["/joint_states"] == "sensor_msgs/msg/JointState"
    assert types["/left_arm/tcp_pose"] == "geometry_msgs/msg/PoseStamped"
    ours = "dual_arm_executive_interfaces/msg/"
    assert types["/left_arm/sm/status"] == ours + "MachineStatus"
    assert types["/left_arm/sm/state"] == ours + "MachineState" and types["/left_arm/sm/structure"] == ours + "MachineStructure"
    assert types["/execution_engine/status"] == ours + "EngineStatus" and types["/execution_engine/events"] == ours + "EngineEvent"
    assert types["/right_arm/bridge/command"] == ours + "BridgeCommand" and types["/right_arm/bridge/feedback"] == ours + "BridgeFeedback"
    assert types["/execution_engine/cell"] == ours + "CellSnapshot" and types["/coordination/sync"] == ours + "SyncMessage"
    assert types["/left_arm/sm/located"] == ours + "LocatedFrames"
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    for topic in ("/execution_engine/status", "/execution_engine/events", "/right_arm/bridge/command",
                  "/right_arm/bridge/feedback", "/right_arm/sm/structure", "/execution_engine/cell"):
        assert topic in types


def test_state_transitions_match_the_trace_and_joint_states_cover_the_run(rivet_run: tuple[Path, Path]) -> None:
    record, trace = rivet_run
    recording = Recording(str(record))
    recorded = [r for r in trace_records(record, recording) if r["event"] == "transition"]
    traced = [r for r in _trace(trace) if r["event"] == "transition"]
    assert not recording.cut
    assert len(recorded) == len(traced) > 50
    assert sorted((r["group"], r["from"], r["to"], r["t"]) for r in recorded) == sorted((r["group"], r["from"], r["to"], r["t"]) for r in traced)
    stamps = [m.log_time_ns * 1e-9 for m in iter_messages(record, Recording(str(record))) if m.topic == "/joint_states"]
    statuses = [m.log_time_ns * 1e-9 for m in iter_messages(record, Recording(str(record))) if m.topic.endswith("/sm/status")]
    assert stamps[0] <= min(statuses) + 0.2 and stamps[-1] >= max(statuses) - 0.2
    assert max(b - a for a, b in zip(stamps, stamps[1:])) < 0.5  # no hole in the arm's record


def test_every_request_is_recorded_from_the_first_one(rivet_run: tuple[Path, Path]) -> None:
    """The engine makes a group's request publisher when the run starts and sends the first
    request at once: the recorder subscribes the moment the publisher is made, not at its next
    look at the graph, so each group's requests are its functions and the end, all of them."""
    record, trace = rivet_run
    functions: dict[str, int] = {}
    for r in _trace(trace):
        if r["event"] == "function_start":
            functions[r["group"]] = functions.get(r["group"], 0) + 1
    requests: dict[str, list[str]] = {}
    for m in iter_messages(record, Recording(str(record))):
        if m.topic.endswith("/sm/request"):
            requests.setdefault(m.topic.split("/")[1], []).append(m.msg.kind)
    assert {g: len(kinds) for g, kinds in requests.items()} == {g: n + 1 for g, n in functions.items()}
    assert all(kinds[-1] == "end" and "end" not in kinds[:-1] for kinds in requests.values())


def test_what_ran_is_in_the_recording(rivet_run: tuple[Path, Path]) -> None:
    record, _ = rivet_run
    recording = Recording(str(record))
    for _ in iter_messages(record, recording):
        pass
    meta = recording.metadata["dual_arm_executive"]
    assert meta["application"] == "rivet_installation" and meta["robot"] == "nextage_open"
    assert meta["backend"] == "nextage-sim" and meta["software_version"]
    assert len(meta["application_sha256"]) == 64 and len(meta["cell_sha256"]) == 64
    assert recording.attachments["application/rivet_installation.xml"] == Path(RIVET).read_bytes()
    assert recording.attachments["cell/rivet_cell.xml"] == Path("apps_xml/cells/rivet_cell.xml").read_bytes()
    assert recording.metadata["recording_stats"]["dropped"] == "0"


def test_schemas_carry_their_dependencies_as_rosbag2_writes_them() -> None:
    text = schema_text("sensor_msgs/msg/JointState")
    parts = text.split(SEPARATOR + "\n")
    assert parts[0].startswith("std_msgs/Header header\n")
    assert [p.splitlines()[0] for p in parts[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    pose = schema_text("geometry_msgs/msg/PoseStamped")
    assert [line for line in pose.splitlines() if line.startswith("MSG:")] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion",
    ]


SAMPLES: list[Any] = [
    msgs.String("{\"v\":1}"),
    msgs.Bool(True),
    msgs.ClockMessage(msgs.Time(12, 500)),
    msgs.JointState(msgs.Header(msgs.Time(3, 4), "base"), ("a", "b"), (0.1, -0.2), (1.0, 2.0), ()),
    msgs.PoseStamped(msgs.Header(msgs.Time(5, 6), "world"), msgs.Pose(msgs.Point(1, 2, 3), msgs.Quaternion(0, 0, 0.6, 0.8))),
    msgs.TFMessage((msgs.TransformStamped(msgs.Header(msgs.Time(7, 8), "world"), "tool",
                                          msgs.Transform(msgs.Vector3(0.1, 0.2, 0.3), msgs.Quaternion(0, 1, 0, 0))),)),
    msgs.DiagnosticArray(msgs.Header(msgs.Time(9, 10)), (msgs.DiagnosticStatus(b"\x02", "left", "ErrorHandling", "hw",
                                                                                (msgs.KeyValue("state", "x"),)),)),
    msgs.Image(msgs.Header(msgs.Time(11, 12), "head_camera"), 2, 3, "mono8", 0, 3, msgs.ByteBuffer(bytes([0, 9, 255, 1, 2, 3]))),
    msgs.CameraInfo(msgs.Header(msgs.Time(13, 14), "head_camera"), 480, 640, "plumb_bob", (0.1, 0.0, 0.0, 0.0, 0.0),
                    (500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0), (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0),
                    (500.0, 0, 320.0, 0, 0, 500.0, 240.0, 0, 0, 0, 1.0, 0), 1, 1, msgs.RegionOfInterest(1, 2, 3, 4, True)),
    # the project's own types: their schemas come from the interface package's .msg files
    typed.to_msg(SmStatus("left_arm", "primitive_end", "Motion", 2.5, primitive="move_joints", index=3, count=12,
                          result={"kind": "motion", "joints": [0.1]}), Clock(epoch=1_700_000_000.0)),
    typed.to_msg(EngineStatus("rivet", "running", 2, 10, 1.0, "op2", {"left_arm": GroupProgress("Motion", "op2", "move_to")}),
                 Clock(epoch=1_700_000_000.0)),
    typed.to_msg(EngineEvent("operator", 3.0, "running", command="pause", source="/execution_engine/pause", accepted=True, answer="ok"),
                 Clock(epoch=1_700_000_000.0)),
    typed.to_msg(SmStructure("left_arm", "Ready", ("Ready", "Motion"), (TransitionSpec("Ready", "motion_request", "Motion"),)),
                 Clock(epoch=1_700_000_000.0)),
]


def _same(mirror: Any, decoded: Any) -> None:
    for name in (f.name for f in dataclasses.fields(mirror)):
        want, got = getattr(mirror, name), getattr(decoded, name)
        if isinstance(want, tuple) and want and hasattr(want[0], "__dataclass_fields__"):
            assert len(got) == len(want)
            for w, g in zip(want, got):
                _same(w, g)
        elif hasattr(want, "__dataclass_fields__"):
            _same(want, got)
        elif isinstance(want, msgs.ByteBuffer):
            assert bytes(got) == want, name
        elif isinstance(want, bytes):
            assert got == want[0], name
        elif isinstance(want, tuple):
            assert list(got) == pytest.approx(list(want)), name
        else:
            assert got == pytest.approx(want) if isinstance(want, float) else got == want, name


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_type_decodes_to_the_right_fields(sample: Any) -> None:
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign] # keep the bytes for reading
    sink = McapSink(stream, "memory")
    sink.put("/topic", sample, (SENSOR,), 1_000)
    assert not sink.close().error
    stream.seek(0)
    reader = make_reader(stream, decoder_factories=[DecoderFactory()])
    [(schema, _, message, decoded)] = list(reader.iter_decoded_messages())
    assert schema.name == type(sample).ROS_TYPE and message.log_time == 1_000
    _same(sample, decoded)


class Stalled(io.BytesIO):
    """A disk that hangs until released: the writer thread is stuck in a write."""

    def __init__(self) -> None:
        super().__init__()
        self.release = threading.Event()
        self.entered = threading.Event()
        self.armed = False

    def write(self, data: Any) -> int:
        if self.armed:  # the file's start goes through; the first chunk hangs
            self.entered.set()
            self.release.wait(30)
        return super().write(data)

    def close(self) -> None:
        pass


def test_a_full_queue_drops_and_reports_never_blocks() -> None:
    stream = Stalled()
    sink = McapSink(stream, "stalled.mcap", queue_size=10, flush_period=0.01)
    stream.armed = True
    sink.put("/a", msgs.String("first"), (EVENTS,), 0)
    assert stream.entered.wait(10)  # the file's first bytes reached the disk, which hangs from now on
    noise = random.Random(7)
    for i in range(1000):  # 4 MB: more than the queue, the pipes and the encoder hold while the disk hangs
        sink.put("/a", msgs.String(noise.randbytes(2048).hex()), (EVENTS,), 1 + i)  # returns at once every time
    dropped = sink.stats.dropped["/a"]
    assert dropped > 0
    stream.release.set()
    stats = sink.close()
    assert not stats.error and stats.written + dropped == 1001
    assert f"DROPPED {dropped} message(s)" in "\n".join(stats.lines())
    recording = Recording("memory")
    path = Path(tempfile.mkdtemp()) / "stalled.mcap"
    path.write_bytes(stream.getvalue())
    times = [m.log_time_ns for m in iter_messages(path, recording)]
    assert len(times) == stats.written and times == sorted(times) and not recording.cut
    assert recording.metadata["recording_stats"]["dropped"] == str(dropped)


def test_an_encoder_that_dies_is_said_and_never_blocks_the_run() -> None:
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign]
    sink = McapSink(stream, "dying.mcap")
    sink.put("/a", msgs.String("before"), (EVENTS,), 1)
    assert sink.sync().wait(10)
    sink._process.kill()  # noqa: SLF001 - what an out-of-memory kill does to it
    sink._process.wait(10)  # noqa: SLF001
    assert sink.sync().wait(10)  # a sync after the death is released, not left hanging
    for i in range(100):
        sink.put("/a", msgs.String(str(i)), (EVENTS,), 2 + i)
    stats = sink.close()
    assert "the encoder process ended" in stats.error
    assert "RECORDING FAILED: the encoder process ended" in "\n".join(stats.lines())


def test_a_cut_recording_reads_back_to_its_last_flushed_chunk(tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    stream = open(path, "wb")
    sink = McapSink(stream, str(path), flush_period=3600)
    for i in range(50):
        sink.put("/a", msgs.String(str(i)), (EVENTS,), i)
    assert sink.sync().wait(10)  # the first chunk is on disk
    sink.put("/a", msgs.String("after the last flush"), (EVENTS,), 99)
    snapshot = tmp_path / "killed.mcap"
    shutil.copy(path, snapshot)  # what a kill -9 now leaves
    sink.close()
    with open(snapshot, "ab") as tail:
        tail.write(b"\x05\x00\x00")  # and a record cut in the middle
    recording = Recording(str(snapshot))
    got = [m.msg.data for m in iter_messages(snapshot, recording)]
    assert got == [str(i) for i in range(50)]
    assert recording.cut


def test_the_recorder_asks_no_more_than_publishers_offer() -> None:
    assert reader_qos((SENSOR,)).reliability is Reliability.BEST_EFFORT
    assert reader_qos((LATCHED,)).durability is Durability.TRANSIENT_LOCAL
    mixed = reader_qos((LATCHED, EVENTS))
    assert mixed.durability is Durability.VOLATILE and mixed.reliability is Reliability.RELIABLE
    assert all(q.compatible_with(o) for q, o in ((reader_qos((SENSOR,)), SENSOR), (reader_qos((LATCHED,)), LATCHED)))
    assert not math.isnan(reader_qos((EVENTS,)).depth)


@dataclasses.dataclass(frozen=True)
class Unknown:
    ROS_TYPE = "foo_msgs/msg/Bar"
    value: int = 0


def test_a_topic_of_a_type_without_definition_is_skipped_and_said(run_sim: Any, caplog: pytest.LogCaptureFixture) -> None:
    stream = io.BytesIO()
    stream.close = lambda: None  # type: ignore[method-assign]

    async def main(clock: Any) -> Any:
        transport = LocalTransport(clock)
        talker = transport.create_node("talker")
        known, odd = talker.create_publisher(msgs.String, "a", EVENTS), talker.create_publisher(Unknown, "b", EVENTS)
        recorder = Recorder(transport.create_node("recorder"), McapSink(stream, "memory"))
        recorder.start()
        known.publish(msgs.String("kept"))
        odd.publish(Unknown(3))
        await clock.sleep(0.1)
        return await recorder.close()

    stats = run_sim(main)
    assert dict(stats.by_topic) == {"/a": 1} and not stats.error
    assert "/b is not recorded: no message definition of foo_msgs/msg/Bar" in caplog.text
