"""What rosbag2 (Jazzy's ``rosbag2_storage_mcap``) reads from an MCAP file besides the messages.

Each channel's ``offered_qos_profiles`` (the QoS ``ros2 bag play`` offers again) and the
``rosbag2`` metadata record's ``serialized_metadata`` (rosbag2's ``BagMetadata``, version 9: the
metadata version, the ROS distribution, each topic's type and type hash; counts and times it
takes from the MCAP summary) are YAML documents; they are made here with PyYAML from the same
keys and values ``ros2 bag record -s mcap`` writes (checked against the real rosbag2 in
docs/recording.md), not written out by hand.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import yaml

from node_transport.qos import Durability, QoS, Reliability

#: RMW_DURATION_INFINITE as rosbag2 writes an infinite deadline, lifespan or liveliness lease
INFINITE = {"sec": 9223372036, "nsec": 854775807}
NOT_STARTED = 2**63 - 1  # the starting time rosbag2 writes before the first message (its time_point's maximum)
VERSION = 9  # rosbag2 Jazzy's metadata version
DISTRO = "jazzy"


def qos_profile(qos: QoS) -> dict[str, Any]:
    """One publisher's QoS with rosbag2's keys and values."""
    return {
        "history": "keep_last",
        "depth": qos.depth,
        "reliability": "best_effort" if qos.reliability is Reliability.BEST_EFFORT else "reliable",
        "durability": "transient_local" if qos.durability is Durability.TRANSIENT_LOCAL else "volatile",
        "deadline": dict(INFINITE),
        "lifespan": dict(INFINITE),
        "liveliness": "automatic",
        "liveliness_lease_duration": dict(INFINITE),
        "avoid_ros_namespace_conventions": False,
    }


def qos_yaml(offered: tuple[QoS, ...]) -> str:
    """A channel's ``offered_qos_profiles``: one entry per publisher; ``[]`` when none was seen."""
    return _dump([qos_profile(q) for q in offered])


@dataclass
class BagTopic:
    """What the ``rosbag2`` metadata record says of one channel."""

    ros_type: str
    offered: tuple[QoS, ...]
    type_hash: str
    count: int = 0


def bag_metadata(topics: dict[str, BagTopic], start: int, end: int) -> str:
    """The ``serialized_metadata`` of the ``rosbag2`` record (written at the start of a file, with no
    topics yet, and again at its end)."""
    return _dump({
        "version": VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": max(0, end - start)},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(t.count for t in topics.values()),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": name,
                    "type": topic.ros_type,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": [qos_profile(q) for q in topic.offered],
                    "type_description_hash": topic.type_hash,
                },
                "message_count": topic.count,
            }
            for name, topic in topics.items()
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [],
        "files": [],
        "custom_data": {},
        "ros_distro": DISTRO,
    })


def _dump(data: Any) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False).rstrip("\n")
