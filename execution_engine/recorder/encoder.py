"""The recording's encoder process: message objects in, the bytes of an MCAP file out.

Encoding is the costly part of recording (``mcap-ros2-support``'s CDR encoder and ``mcap``'s
record writer are pure Python: some 30 µs a message), and a thread of the run's own process
would take that time from the control loop through the interpreter lock.  So it runs in a
process of its own, started by :class:`~execution_engine.recorder.writer.McapSink`: the run's
process only pickles batches of the message objects it received (about 1.5 µs a message) and
copies the finished bytes to the file.

Protocol, both ways frames of a one-byte kind, a 4-byte little-endian length and a payload:

* in (stdin), kind ``B``: a pickled list of items -- ``("m", topic, ros_type, msg, offered,
  log_time_ns)`` (a message's fields as a dict: :func:`.frames.ros_fields`),
  ``("meta", name, data)``, ``("att", name, media_type, data, log_time_ns)``, ``("tf", topic,
  offered, joint_states_topic, description_topic)`` (work ``tf`` out of the joint states:
  :mod:`.derived_tf`), ``("sync", n)``
  (close the chunk in progress and hand over every byte so far), ``("stop", dropped_by_topic)``
  (store the ``recording_stats`` metadata, write the summary and the index, end);
* out (stdout), kind ``D``: bytes of the file, in order; ``S``: sync ``n`` is done (every byte
  before it was sent); ``E``: the recording failed (a one-line reason); ``T``: the final counts.

The end of stdin without a stop (the run's process was killed) ends the encoder at once: what
the run's process already wrote to the file is the recording, up to its last flushed chunk.
"""
from __future__ import annotations

import os
import pickle
import signal
import sys
from collections import Counter
from typing import IO, Any

from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import EncoderFunction, serialize_dynamic

from execution_engine.recorder.bag_metadata import NOT_STARTED, BagTopic, bag_metadata, qos_yaml
from execution_engine.recorder.definitions import schema_text
from execution_engine.recorder.derived_tf import TF_TYPE, DerivedTf
from execution_engine.recorder.frames import frame, read_frame
from node_transport.idl import InterfaceError, InterfaceRegistry
from node_transport.idl_hash import type_hash
from node_transport.qos import QoS

LIBRARY = "dual_arm_executive recorder (mcap, mcap-ros2-support)"
NICE = 10  # the encoder's niceness above the run's: it takes spare CPU time, not the machines'

class _Output:
    """What ``mcap``'s writer writes to: bytes gathered here go out as ``D`` frames."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.position = 0

    def write(self, data: bytes) -> int:
        self.parts.append(bytes(data))
        self.position += len(data)
        return len(data)

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        pass

    def take(self) -> bytes:
        data, self.parts = b"".join(self.parts), []
        return data


class Encoder:
    """One MCAP file: schemas and CDR encoders made once per type, channels once per topic."""

    def __init__(self, chunk_size: int, compression: CompressionType) -> None:
        self.output = _Output()
        self.writer = Writer(self.output, chunk_size=chunk_size, compression=compression)
        self.writer.start(profile="ros2", library=LIBRARY)
        # rosbag2 writes this record on opening a bag as well: a file cut before its end still names
        # its metadata version and ROS distribution (the summary's figures replace these on reading)
        self.writer.add_metadata("rosbag2", {"serialized_metadata": bag_metadata({}, NOT_STARTED, NOT_STARTED)})
        self.schemas: dict[str, tuple[int, EncoderFunction]] = {}
        self.channels: dict[str, int] = {}
        self.topics: dict[str, BagTopic] = {}
        self.registry = InterfaceRegistry()
        self.derived: DerivedTf | None = None  # tf worked out of joint_states (:mod:`.derived_tf`)
        self.start, self.end = NOT_STARTED, 0  # the first and the last log time

    def _type_hash(self, ros_type: str) -> str:
        """``RIHS01_...`` as rmw announces it (rosbag2 stores it as ``topic_type_hash``); empty when
        the interface files cannot tell (rosbag2 stores an empty hash too)."""
        try:
            return type_hash(self.registry, ros_type)
        except (InterfaceError, KeyError):
            return ""

    def message(self, topic: str, ros_type: str, msg: dict[str, Any], offered: tuple[QoS, ...], log_time: int) -> None:
        schema = self.schemas.get(ros_type)
        if schema is None:
            text = schema_text(ros_type)
            schema_id = self.writer.register_schema(ros_type, SchemaEncoding.ROS2, text.encode())
            schema = self.schemas[ros_type] = (schema_id, serialize_dynamic(ros_type, text)[ros_type])
        channel = self.channels.get(topic)
        if channel is None:
            self.topics[topic] = BagTopic(ros_type, offered, self._type_hash(ros_type))
            channel = self.channels[topic] = self.writer.register_channel(
                topic, MessageEncoding.CDR, schema[0],
                {"offered_qos_profiles": qos_yaml(offered), "topic_type_hash": self.topics[topic].type_hash},
            )
        info = self.topics[topic]
        self.writer.add_message(channel, log_time, schema[1](msg), log_time, info.count)  # sequence: per channel, from 0
        info.count += 1
        self.start, self.end = min(self.start, log_time), max(self.end, log_time)
        if self.derived is not None and (tf := self.derived.follow(topic, msg)) is not None:
            self.message(self.derived.topic, TF_TYPE, tf, self.derived.offered, log_time)

    def written(self) -> dict[str, int]:
        """Messages written, per topic."""
        return {topic: info.count for topic, info in self.topics.items()}

    def item(self, item: tuple[Any, ...]) -> bool:
        """Handle one item; True at the stop."""
        kind = item[0]
        if kind == "m":
            self.message(*item[1:])
        elif kind == "meta":
            self.writer.add_metadata(item[1], item[2])
        elif kind == "att":
            _, name, media_type, data, log_time = item
            self.writer.add_attachment(log_time, log_time, name, media_type, data)
        elif kind == "sync":
            self.writer.flush()
        elif kind == "tf":
            self.derived = DerivedTf(*item[1:])
        elif kind == "stop":
            dropped: Counter[str] = item[1]
            self.writer.add_metadata("recording_stats", {
                "written": str(sum(self.written().values())),
                "dropped": str(sum(dropped.values())),
                "dropped_by_topic": ", ".join(f"{t}={n}" for t, n in sorted(dropped.items())),
            })
            self.writer.add_metadata("rosbag2", {"serialized_metadata": bag_metadata(self.topics, self.start, self.end)})
            self.writer.finish()
            return True
        return False


def serve(inp: IO[bytes], out: IO[bytes], chunk_size: int, compression: CompressionType) -> None:
    """Encode what comes in until the stop (or the end of the input)."""
    encoder = Encoder(chunk_size, compression)
    try:
        while (got := read_frame(inp)) is not None:
            stop = False
            syncs = []
            for item in pickle.loads(got[1]):
                stop = encoder.item(item) or stop
                if item[0] == "sync":
                    syncs.append(item[1])
            data = encoder.output.take()
            if data:
                out.write(frame(b"D", data))
            for number in syncs:
                out.write(frame(b"S", str(number).encode()))
            if stop:
                out.write(frame(b"T", pickle.dumps(encoder.written())))
                out.flush()
                return
            out.flush()
    except BrokenPipeError:  # the run's process is gone: nobody to hand bytes to
        return
    except Exception as error:  # noqa: BLE001 - any failure is reported to the run, which says it
        reason = f"{type(error).__name__}: {error}".splitlines()[0][:300]
        try:
            out.write(frame(b"E", reason.encode()))
            out.flush()
        except OSError:
            pass


def main() -> None:
    # An operator's Ctrl-C reaches the whole process group: the run ends the recording itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:  # on a busy computer the control loop comes first; the queue and the pipes hold what waits
        os.nice(NICE)
    except OSError:
        pass
    out = os.fdopen(os.dup(1), "wb", buffering=1 << 16)
    os.dup2(2, 1)  # a stray print can never break the frames
    chunk_size, compression = int(sys.argv[1]), CompressionType[sys.argv[2]]
    serve(sys.stdin.buffer, out, chunk_size, compression)


if __name__ == "__main__":
    main()
