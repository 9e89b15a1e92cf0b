"""Each group machine on ``diagnostics``: levels that follow Table 2, on every change and at 1 Hz."""
from __future__ import annotations

from typing import Any

from machine_harness import Harness

from node_transport.clock import Clock
from node_transport.msgs import DiagnosticArray, DiagnosticStatus
from node_transport.qos import DIAGNOSTICS
from node_transport.wire import DIAGNOSTICS_TOPIC
from robot_bridges.backend import FaultKind

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
KEYS = ["state", "operation", "function", "primitive_index", "last_error"]


class Monitor:
    """What rqt_robot_monitor would receive: (status, time received, epoch seconds) per message."""

    def __init__(self, h: Harness) -> None:
        self.clock = h.clock
        self.seen: list[tuple[DiagnosticStatus, float, float]] = []
        self.arrays: list[DiagnosticArray] = []
        node = h.transport.create_node("monitor")
        node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_array, DIAGNOSTICS)

    def _on_array(self, array: DiagnosticArray) -> None:
        self.arrays.append(array)
        for status in array.status:
            self.seen.append((status, self.clock.now(), self.clock.epoch_now()))

    def of(self, group: str) -> list[tuple[DiagnosticStatus, float]]:
        return [(s, t) for s, t, _ in self.seen if s.hardware_id == group]


def values(status: DiagnosticStatus) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def test_levels_follow_the_machine_through_ready_working_pause_stop_and_error_handling(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Monitor, dict[str, tuple[float, float]]]:
        h = await Harness(clock, durations={"default": 3.0}).start()
        monitor = Monitor(h)
        spans: dict[str, tuple[float, float]] = {}
        try:
            await clock.sleep(1.5)
            first = h.send("left_arm", "move_to_joint_pose", "initial")
            await h.until_state("left_arm", "Motion")
            await clock.sleep(1.0)
            assert (await h.service("left_arm", "pause")).success
            await h.until_state("left_arm", "Pause")
            t0 = clock.now()
            await clock.sleep(3.0)
            spans["pause"] = (t0, clock.now())
            assert (await h.service("left_arm", "resume")).success
            assert (await h.result(first)).outcome == "succeeded"
            h.backend.fail_next("left_arm", FaultKind.JOINT_LIMIT, message="injected joint limit")
            failed = h.send("left_arm", "move_to_joint_pose", "initial", operation="2")
            assert (await h.result(failed)).outcome == "aborted"
            await h.until_state("left_arm", "ErrorHandling")
            await clock.sleep(2.0)
            assert (await h.service("left_arm", "reset")).success
            await h.until_state("left_arm", "Ready")
            await clock.sleep(1.5)
            stopped = h.send("left_arm", "move_to_joint_pose", "initial", operation="3")
            await h.until_state("left_arm", "Motion")
            assert (await h.service("left_arm", "stop")).success
            assert (await h.result(stopped)).outcome == "preempted"
            await clock.sleep(1.0)
            return monitor, spans
        finally:
            await h.close()

    monitor, spans = run_sim(main)
    left = monitor.of("left_arm")
    by_state: dict[str, set[bytes]] = {}
    for status, _ in left:
        by_state.setdefault(values(status)["state"], set()).add(status.level)
        assert status.name == "left_arm_machine: left_arm" and [kv.key for kv in status.values] == KEYS
    assert by_state == {"Ready": {OK}, "Motion": {OK}, "Pause": {WARN}, "Stop": {WARN}, "ErrorHandling": {ERROR}}
    assert all(s.level != DiagnosticStatus.STALE for s, _, _ in monitor.seen)

    motion = next(s for s, _ in left if values(s)["state"] == "Motion")
    assert values(motion)["function"] == "move_to_joint_pose" and values(motion)["operation"] == "1"
    assert values(motion)["primitive_index"] == "1" and "move_to_joint_pose (operation 1)" in motion.message
    failed = [s for s, _ in left if values(s)["state"] == "ErrorHandling"]
    assert "injected joint limit" in values(failed[0])["last_error"] and "injected joint limit" in failed[0].message
    assert all(values(s)["function"] == "move_to_joint_pose" and values(s)["operation"] in ("2", "3") for s in failed)
    first_error = next(i for i, (s, _) in enumerate(left) if values(s)["state"] == "ErrorHandling")
    reset = [s for s, _ in left[first_error:] if values(s)["state"] == "Ready"]
    assert reset and all(values(s)["function"] == "" for s in reset)
    assert "injected joint limit" in values(reset[0])["last_error"]  # the last error stays readable after a reset

    held = [t for s, t in left if values(s)["state"] == "Pause" and spans["pause"][0] < t <= spans["pause"][1]]
    assert 3 <= len(held) <= 4  # nothing changes while paused: the 1 Hz report alone
    times = [t for _, t in left]
    assert max(b - a for a, b in zip(times, times[1:])) <= 1.0 + 1e-9  # never a second without a report
    assert {s.hardware_id for s, _, _ in monitor.seen} == {"left_arm", "right_arm", "torso_head"}
    assert all(len(array.status) == 1 for array in monitor.arrays)


def test_stamps_are_the_nodes_ros_time_and_close_ends_the_reports(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[float, float]], int, int]:
        h = await Harness(clock).start()
        monitor = Monitor(h)
        try:
            await clock.sleep(2.5)
            stamps = [(a.header.stamp.to_seconds(), e) for a, (_, _, e) in zip(monitor.arrays, monitor.seen)]
            h.machines["left_arm"].close()
            before = len(monitor.of("left_arm"))
            await clock.sleep(3.0)
            return stamps, before, len(monitor.of("left_arm"))
        finally:
            await h.close()

    stamps, before, after = run_sim(main)
    assert stamps and all(abs(stamp - received) < 1e-6 for stamp, received in stamps)
    assert before >= 2 and after == before
