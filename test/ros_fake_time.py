"""``rclpy.time.Time`` and a node's clock in the fake rclpy: system time, or ``/clock`` under ``use_sim_time``.

With ``use_sim_time`` a real node's clock stands at 0 until the first ``/clock`` message and then follows it; the
ros transport's stamps and timeouts depend on that, so the fake does the same (the node feeds the clock from its
own ``/clock`` subscription).
"""
from __future__ import annotations

import time


class FakeTime:
    """rclpy.time.Time, as far as the adapter reads it."""

    def __init__(self, nanoseconds: int) -> None:
        self.nanoseconds = nanoseconds

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return divmod(self.nanoseconds, 1_000_000_000)


class FakeClock:
    """A node's ROS clock: system time, or the last ``/clock`` (0 before one) with use_sim_time."""

    def __init__(self) -> None:
        self.ros_time_is_active = False
        self.sim_nanoseconds = 0

    def now(self) -> FakeTime:
        return FakeTime(self.sim_nanoseconds if self.ros_time_is_active else time.time_ns())
