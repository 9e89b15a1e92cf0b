"""A primitive that does not move the robot costs no kinematics, and still reports where the robot is.

What a user relies on: ``set_speed`` (and a dwell) answer with the group's joints and TCP as every
motion does -- a skill may read them -- but a run of speed changes does not pay forward kinematics
each time; what the TCP depends on (the joints, the tool) changing gives the new pose at once.
"""
from __future__ import annotations

from typing import Any

import pytest

from core_functions.geometry import Pose
from core_functions.primitives import Dwell, MotionResult, MoveJoints, SetSpeed
from node_transport.clock import Clock
from robot_bridges.nextage_sim.backend import NextageSimBackend


def test_set_speed_and_a_dwell_reuse_the_last_pose_and_a_change_of_joints_or_tool_is_seen(run_sim: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    async def main(clock: Clock) -> tuple[list[MotionResult], list[int]]:
        backend = NextageSimBackend(clock)
        arm = backend.model.arms["left_arm"]
        solved = [0]
        tcp_pose = arm.tcp_pose
        monkeypatch.setattr(arm, "tcp_pose", lambda q: solved.__setitem__(0, solved[0] + 1) or tcp_pose(q))
        results: list[Any] = []
        counts = []
        for primitive in (SetSpeed(0.5), SetSpeed(1.0), MoveJoints((0.1,), joint_names=("LARM_JOINT0",), relative=True),
                          SetSpeed(0.5), Dwell(0.0)):
            results.append(await backend.execute("left_arm", primitive))
            counts.append(solved[0])
        backend.set_tool("left_arm", Pose(0.0, 0.0, 0.1))
        results.append(await backend.execute("left_arm", SetSpeed(1.0)))
        counts.append(solved[0])
        return results, counts

    results, counts = run_sim(main)
    first, again, moved, slow, dwelt, tooled = results
    spent = [b - a for a, b in zip([0, *counts], counts)]  # forward kinematics per primitive
    assert spent[0] == 1 and spent[1] == 0 and spent[2] >= 1 and spent[3] == spent[4] == 0 and spent[5] == 1
    assert again == first and slow == moved and dwelt == moved
    assert moved.positions != first.positions and moved.tcp != first.tcp
    assert tooled.positions == moved.positions and tooled.tcp is not None and moved.tcp is not None
    assert tooled.tcp.distance_to(moved.tcp) == pytest.approx(0.1, abs=1e-9)
