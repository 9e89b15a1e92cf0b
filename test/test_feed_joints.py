"""The page's joint samples: JSON numbers whatever the back end's types, and the pose the robot came to rest in is the
last one even when it comes within the sampling period of the one before."""
from __future__ import annotations

import numpy as np
import orjson

from core_functions.robots import NEXTAGE_OPEN
from operator_station.feed import JOINT_SAMPLE_PERIOD, Feed
from operator_station.session import final_joint_sample


class Resting:
    """A back end as the Nextage simulator is after a motion: numpy positions, its joints in its own order."""

    def __init__(self, positions: dict[str, float]) -> None:
        self.positions = positions

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names = tuple(reversed(list(self.positions)))
        return names, tuple(np.float64(self.positions[n]) for n in names)


def test_a_back_ends_numpy_positions_reach_the_page_as_json_numbers() -> None:
    feed = Feed()
    feed.joint_sample(np.float64(0.25), list(np.linspace(0.0, 1.0, 3)))
    _, _, samples, total = feed.read(0, 0)
    assert total == 1 and orjson.loads(orjson.dumps(samples))  # as the page's socket sends them == [[0.25, 0.0, 0.5, 1.0]]


def test_the_pose_the_robot_ends_in_is_the_last_sample_even_within_the_period() -> None:
    feed = Feed()
    names = NEXTAGE_OPEN.joint_names
    moving = [0.0] * len(names)
    feed.joint_sample(10.0, moving)
    rest = {name: 0.01 * k for k, name in enumerate(names)}
    final_joint_sample(feed, NEXTAGE_OPEN, Resting(rest), 10.0 + JOINT_SAMPLE_PERIOD / 4)
    feed.joint_sample(10.0 + JOINT_SAMPLE_PERIOD / 2, moving)  # a plain sample that soon is still dropped
    _, _, samples, _ = feed.read(0, 0)
    assert samples == [[10.0, *moving], [10.0 + JOINT_SAMPLE_PERIOD / 4, *(rest[n] for n in names)]]


def test_a_back_end_without_every_joint_of_the_robot_adds_no_sample() -> None:
    feed = Feed()
    names = NEXTAGE_OPEN.joint_names
    final_joint_sample(feed, NEXTAGE_OPEN, Resting({name: 0.0 for name in names[1:]}), 1.0)
    assert feed.read(0, 0)[3] == 0
