"""The recording's layout as rosbag2 (Jazzy, rosbag2_storage_mcap) reads it back.

rosbag2's MCAP reader takes each channel's ``offered_qos_profiles`` (a YAML sequence: the QoS
``ros2 bag play`` offers) and ``topic_type_hash``, and the ``rosbag2`` metadata record's
``serialized_metadata`` (the bag's metadata version, ROS distribution and per topic type hash).
The layouts asserted here are what ``ros2 bag record -s mcap`` writes (checked against the real
rosbag2 in docs/recording.md); the type hashes are the ones Jazzy's own interface packages carry.
"""
from __future__ import annotations

from pathlib import Path

import yaml
from mcap.reader import make_reader
from mcap.writer import CompressionType

from execution_engine.recorder.bag_metadata import qos_yaml
from execution_engine.recorder.encoder import Encoder
from execution_engine.recorder.reading import Recording, iter_messages
from execution_engine.recorder.writer import McapSink
from node_transport import msgs
from node_transport.qos import EVENTS, LATCHED, SENSOR

#: from Jazzy's installed share/<pkg>/msg/<Name>.json (``type_hashes``)
JAZZY_HASHES = {
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "sensor_msgs/msg/JointState": "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
}
INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE as rosbag2 writes it


def _record(tmp_path: Path) -> Path:
    path = tmp_path / "bag.mcap"
    stream = open(path, "wb")
    sink = McapSink(stream, str(path))
    sink.put("/robot_description", msgs.String("<robot/>"), (LATCHED,), 5)
    sink.put("/mixed", msgs.String("a"), (LATCHED, SENSOR), 6)
    sink.put("/nobody", msgs.String("b"), (), 7)
    for i in range(3):
        joints = msgs.JointState(header=msgs.Header(stamp=msgs.Time(sec=i)), name=["j"], position=[0.1 * i])
        sink.put("/joint_states", joints, (EVENTS,), 10 + i)
    stats = sink.close()
    assert not stats.error and stats.written == 6
    return path


def _summary(path: Path):  # noqa: ANN202 - mcap's Summary
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        return reader.get_summary(), {m.name: m.metadata for m in reader.iter_metadata()}


def test_offered_qos_profiles_are_rosbag2s_yaml_sequence() -> None:
    latched, sensor = yaml.safe_load(qos_yaml((LATCHED, SENSOR)))
    assert latched == {
        "history": "keep_last", "depth": 1, "reliability": "reliable", "durability": "transient_local",
        "deadline": INFINITE, "lifespan": INFINITE, "liveliness": "automatic",
        "liveliness_lease_duration": INFINITE, "avoid_ros_namespace_conventions": False,
    }
    assert sensor["reliability"] == "best_effort" and sensor["durability"] == "volatile" and sensor["depth"] == 5
    # no publisher seen: an empty sequence, as rosbag2 writes it
    assert yaml.safe_load(qos_yaml(())) == []


def test_channels_carry_qos_and_jazzys_type_hash(tmp_path: Path) -> None:
    summary, _ = _summary(_record(tmp_path))
    channels = {c.topic: c for c in summary.channels.values()}
    for topic, channel in channels.items():
        assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}, topic
        assert isinstance(yaml.safe_load(channel.metadata["offered_qos_profiles"]), list), topic
    assert channels["/joint_states"].metadata["topic_type_hash"] == JAZZY_HASHES["sensor_msgs/msg/JointState"]
    assert channels["/robot_description"].metadata["topic_type_hash"] == JAZZY_HASHES["std_msgs/msg/String"]
    assert yaml.safe_load(channels["/robot_description"].metadata["offered_qos_profiles"])[0]["durability"] == "transient_local"
    assert yaml.safe_load(channels["/nobody"].metadata["offered_qos_profiles"]) == []


def test_the_rosbag2_metadata_record_matches_the_summary(tmp_path: Path) -> None:
    summary, metadata = _summary(_record(tmp_path))
    assert set(metadata["rosbag2"]) == {"serialized_metadata"}
    bag = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    assert bag["version"] == 9 and bag["storage_identifier"] == "mcap" and bag["ros_distro"] == "jazzy"
    assert bag["compression_format"] == "" and bag["compression_mode"] == "" and bag["custom_data"] == {}
    stats = summary.statistics
    assert bag["message_count"] == stats.message_count == 6
    assert bag["starting_time"] == {"nanoseconds_since_epoch": stats.message_start_time} == {"nanoseconds_since_epoch": 5}
    assert bag["duration"] == {"nanoseconds": stats.message_end_time - stats.message_start_time}
    by_topic = {t["topic_metadata"]["name"]: t for t in bag["topics_with_message_count"]}
    for channel_id, channel in summary.channels.items():
        entry = by_topic[channel.topic]
        assert entry["message_count"] == stats.channel_message_counts[channel_id]
        topic = entry["topic_metadata"]
        assert topic["type"] == summary.schemas[channel.schema_id].name and topic["serialization_format"] == "cdr"
        assert topic["type_description_hash"] == channel.metadata["topic_type_hash"]
        assert topic["offered_qos_profiles"] == yaml.safe_load(channel.metadata["offered_qos_profiles"])
    assert len(by_topic) == len(summary.channels) == 4


def test_a_type_without_interface_file_gets_an_empty_hash() -> None:
    encoder = Encoder(1024, CompressionType.NONE)
    assert encoder._type_hash("nowhere_msgs/msg/Nothing") == ""  # noqa: SLF001
    assert encoder._type_hash("std_msgs/msg/String") == JAZZY_HASHES["std_msgs/msg/String"]  # noqa: SLF001


def test_a_cut_recording_still_names_its_rosbag2_metadata(tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    stream = open(path, "wb")
    sink = McapSink(stream, str(path), flush_period=3600)
    sink.put("/a", msgs.String("x"), (EVENTS,), 1)
    assert sink.sync().wait(10)
    cut = path.read_bytes()  # what a kill -9 now leaves: no summary, no end
    sink.close()
    with open(path, "wb") as out:
        out.write(cut)
    recording = Recording(str(path))
    assert [m.msg.data for m in iter_messages(path, recording)] == ["x"] and recording.cut
    assert list(recording.metadata) == ["rosbag2"]  # written on opening, as rosbag2 does
    bag = yaml.safe_load(recording.metadata["rosbag2"]["serialized_metadata"])
    assert bag["version"] == 9 and bag["ros_distro"] == "jazzy" and bag["topics_with_message_count"] == []
