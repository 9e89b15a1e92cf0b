"""Quality-of-service profiles, named the ROS 2 way, and their mapping to rclpy.

The mapping to rclpy lives here, as plain data, so it is tested on machines without ROS 2 and
the rclpy adapter only looks the names up in ``rclpy.qos``.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Reliability(Enum):
    RELIABLE = "reliable"
    BEST_EFFORT = "best_effort"


class Durability(Enum):
    VOLATILE = "volatile"
    TRANSIENT_LOCAL = "transient_local"


class History(Enum):
    KEEP_LAST = "keep_last"
    KEEP_ALL = "keep_all"


@dataclass(frozen=True)
class QoS:
    """What a publisher offers or a subscriber requests.

    ``depth`` bounds the queue of a KEEP_LAST endpoint; with TRANSIENT_LOCAL, a late subscriber
    receives the last ``depth`` messages (this is how state and structure reach a viewer that
    starts after the machine).
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10

    def __post_init__(self) -> None:
        if self.history is History.KEEP_LAST and self.depth < 1:
            raise ValueError(f"KEEP_LAST QoS needs depth >= 1, got {self.depth}")

    def compatible_with(self, offered: QoS) -> bool:
        """DDS request/offer rule: a subscriber may not request more than the publisher offers."""
        if self.reliability is Reliability.RELIABLE and offered.reliability is Reliability.BEST_EFFORT:
            return False
        if self.durability is Durability.TRANSIENT_LOCAL and offered.durability is Durability.VOLATILE:
            return False
        return True


#: Commands, requests, results: nothing may be lost.
COMMANDS = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 50)
#: Latest state for late joiners (``/<group>/sm/state``, ``structure``): depth 1, latched.
LATCHED = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)
#: Status stream: every transition matters to a trace, so reliable and deep.
EVENTS = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 1000)
#: ``tf``: as tf2_ros's DynamicBroadcasterQoS (reliable, volatile, depth 100), so RViz and tf2 listeners match.
TF = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 100)
#: ``tf_static``: as tf2_ros's StaticBroadcasterQoS; each message holds every static transform of its sender.
TF_STATIC = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)
#: ``robot_description``: as robot_state_publisher offers it, so RViz's RobotModel gets the URDF late.
ROBOT_DESCRIPTION = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)
#: ``diagnostics``: reliable and volatile like diagnostic_updater's publisher; a little depth for bursts.
DIAGNOSTICS = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 10)
#: Periodic sensor data (joint_states, tcp_pose): the newest sample wins.
SENSOR = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_LAST, 5)
#: ``joint_states`` as the bridge offers it: reliable like joint_state_publisher's, so robot_state_publisher
#: (which asks reliable, hence RViz's robot model) matches; best-effort readers match a reliable writer too.
JOINT_STATES = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 10)
#: ``/clock``: only the newest time matters (rclpy's TimeSource and rclcpp's ClockQoS ask this).
CLOCK = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_LAST, 1)


def rclpy_qos_kwargs(qos: QoS) -> dict[str, str | int]:
    """Keyword arguments for ``rclpy.qos.QoSProfile`` as enum *member names*.

    The adapter resolves them with ``getattr(ReliabilityPolicy, name)`` etc.; keeping the table
    here makes the mapping testable without rclpy.
    """
    return {
        "reliability": qos.reliability.name,
        "durability": qos.durability.name,
        "history": qos.history.name,
        "depth": qos.depth,
    }
