"""``rclpy.qos`` of the fake rclpy, and the DDS request/offer rule that decides which endpoints match.

The rule lives here, beside the profiles, because it is what the ros transport got wrong on a real Jazzy: a
reader asking for more reliability or durability than its writer offers never hears from it.
"""
from __future__ import annotations

import enum
from typing import Any


class ReliabilityPolicy(enum.Enum):
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.Enum):
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.Enum):
    KEEP_LAST = 1
    KEEP_ALL = 2


class QoSProfile:
    def __init__(self, **kwargs: Any) -> None:
        if "history" not in kwargs and "depth" not in kwargs:
            raise TypeError("A QoSProfile must either have a history or depth setting")
        self.history = kwargs.pop("history", HistoryPolicy.KEEP_LAST)
        self.depth = kwargs.pop("depth", 10)
        self.reliability = kwargs.pop("reliability", ReliabilityPolicy.RELIABLE)
        self.durability = kwargs.pop("durability", DurabilityPolicy.VOLATILE)
        if kwargs:
            raise TypeError(f"unknown QoS settings {sorted(kwargs)}")


def compatible(offered: QoSProfile, requested: QoSProfile) -> bool:
    """DDS request/offer: a reader may not ask more reliability or durability than the writer gives."""
    if requested.reliability is ReliabilityPolicy.RELIABLE and offered.reliability is ReliabilityPolicy.BEST_EFFORT:
        return False
    if requested.durability is DurabilityPolicy.TRANSIENT_LOCAL and offered.durability is DurabilityPolicy.VOLATILE:
        return False
    return True
