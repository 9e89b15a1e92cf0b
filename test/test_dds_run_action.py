"""RunApplication over Cyclone DDS (issue 20, findings 4 and 5(a)): a cell on the DDS transport on
loopback, and a client that is another DDS participant.

* The goal response goes out before the status array names the goal: read off the wire by plain
  Cyclone readers, by the writers' source timestamps (a ROS 2 client learns of its goal from the
  response and drops status entries of goals it does not know).
* A goal cancelled in the middle, then the same application again: the second run starts from
  where the cancel left the robot, goes back first by the way the dry run proved, and no two
  bodies ever touch on ``joint_states``.
"""
from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from crossing_cell import CROSSING, WAIT_OPERATION, CollisionWatch, start_nextage_cell
from dds_domain import domain_env
from node_transport.clock import Clock, real_clock, run_with_clock
from execution_engine.engine.run_action import ACTION_NAME, RunApplicationGoal
from node_transport import dds_graph
from node_transport.action import CancelGoalRequest, GoalInfo, GoalStatus
from node_transport.dds import DdsTransport
from node_transport.msgs import JointState
from node_transport.port import poll_until
from node_transport.qos import SENSOR
from node_transport.wire import JOINT_STATES
from rclpy_like import RclpyLikeActionClient

BOUND = 20.0  # seconds any one step may take on a loaded machine
BASE = f"{ACTION_NAME}/_action"


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:  # a domain no other test uses meanwhile (dds_domain.py)
        yield claimed


class WireOrder:
    """Plain Cyclone readers on the action's goal replies and status: every sample with the time its writer wrote it."""

    def __init__(self, transport: DdsTransport) -> None:
        # optional: cyclonedds (pip extra 'dds'), plain DDS readers
        from cyclonedds.core import Policy, Qos
        from cyclonedds.sub import DataReader

        registry = transport.registry
        _, reply_type = registry.wire_service("dual_arm_executive_interfaces/action/RunApplication_SendGoal")
        status_type = registry.message("action_msgs/msg/GoalStatusArray")
        replies = transport.topic(f"rr/{BASE}/send_goalReply", reply_type)
        status = transport.topic(f"rt/{BASE}/status", status_type)
        self.reply_reader = DataReader(transport.participant, replies, qos=dds_graph.dds_qos(dds_graph.SERVICES))
        keep_all = Qos(Policy.Reliability.Reliable(0), Policy.History.KeepAll, Policy.Durability.TransientLocal)
        self.status_reader = DataReader(transport.participant, status, qos=keep_all)
        self.replies: list[tuple[int, bool]] = []  # (source time ns, accepted)
        self.statuses: list[tuple[int, tuple[tuple[bytes, int], ...]]] = []  # (source time ns, ((goal id, status), ...))

    def matched(self) -> bool:
        try:  # cyclonedds may raise IndexError when a peer matches between its two internal calls
            return bool(self.reply_reader.get_matched_publications()) and bool(self.status_reader.get_matched_publications())
        except IndexError:
            return False

    def take(self) -> None:
        for sample in self.reply_reader.take(N=100):
            self.replies.append((sample.sample_info.source_timestamp, bool(sample.accepted)))
        for sample in self.status_reader.take(N=100):
            entries = tuple((bytes(e.goal_info.goal_id.uuid), int(e.status)) for e in sample.status_list)
            self.statuses.append((sample.sample_info.source_timestamp, entries))

    def first_status_of(self, uuid: bytes) -> int:
        return min(t for t, entries in self.statuses if any(u == uuid for u, _ in entries))


def test_a_goal_cancelled_mid_run_then_the_next_one_goes_back_safely_first_over_dds(env: dict[str, str], tmp_path: Path,
                                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))  # the machines' (and the check's) default trajectory database

    async def main(clock: Clock) -> tuple[Any, ...]:
        cell, tool = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        tasks: list[asyncio.Task[None]] = []
        try:
            tasks += start_nextage_cell(cell, wait_for_goals=True)
            node = tool.create_node("ros2_action_send_goal")
            client = RclpyLikeActionClient(node)
            watch = CollisionWatch()
            node.create_subscription(JointState, f"/{JOINT_STATES}", watch, SENSOR)
            wire = WireOrder(tool)
            assert await client.send.wait_for_service(BOUND)
            assert await poll_until(clock, wire.matched, BOUND, 0.05), "the goal replies and the status never reached the wire readers"

            first = await client.send_goal(RunApplicationGoal(application_xml=CROSSING), 1, timeout=BOUND)
            assert first is not None
            assert await poll_until(clock, lambda: any(f.operation_index == WAIT_OPERATION for f in first.feedback), 4 * BOUND, 0.02), \
                "the run never reached its wait"
            await clock.sleep(0.1)
            cancelled = await client.cancel_client.call(CancelGoalRequest(GoalInfo(first.goal_id)), timeout=BOUND)
            ended = await client.result(first, 4 * BOUND)
            second = await client.send_goal(RunApplicationGoal(application_xml=CROSSING), 2, timeout=BOUND)
            assert second is not None
            answer = await client.result(second, 8 * BOUND)
            await clock.sleep(0.2)
            wire.take()
            return cancelled, ended, answer, watch, wire, bytes(first.goal_id.uuid), bytes(second.goal_id.uuid)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await tool.shutdown()
            await cell.shutdown()

    cancelled, ended, answer, watch, wire, first, second = run_with_clock(main, real_clock())
    assert cancelled.return_code == 0 and ended.status == GoalStatus.STATUS_CANCELED
    assert answer.status == GoalStatus.STATUS_SUCCEEDED, answer.result.report
    report = answer.result.report
    assert "the robot is not where crossing starts" in report and "the run starts with the way back" in report
    assert "application crossing (way back): FINISHED" in report and "application crossing: FINISHED" in report
    assert watch.samples > 50 and watch.touching == []
    # on the wire: each goal's (accepting) response was written before the first status array naming it
    accepted = [t for t, ok in wire.replies if ok]
    assert len(accepted) == 2
    assert accepted[0] <= wire.first_status_of(first) and accepted[1] <= wire.first_status_of(second)
    states = [s for _, entries in wire.statuses for u, s in entries if u == first]
    assert states[-1] == GoalStatus.STATUS_CANCELED and GoalStatus.STATUS_EXECUTING in states
