"""FollowJointTrajectory over Cyclone DDS (issue 23, item 1): each bridge -- the Nextage simulator's, the V+
simulator's, the KUKA RSI simulator's -- on the DDS transport on loopback, and a client that is another DDS
participant knowing only the wire (control_msgs' types built from their interface files, rcl_action's
names).  A 3-point goal succeeds and ``joint_states`` follows it; a goal beyond a limit and one with an
unknown joint end with INVALID_GOAL and INVALID_JOINTS naming the joint; a cancel stops the arm on its path.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from dds_domain import domain_env
from fjt_client import FJT, KINDS, Arm, distance_to_path, follows, goal, start_bridge, three_points

from node_transport import mirrors
from node_transport.action import GoalStatus
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.idl_hash import type_hash
from node_transport.port import poll_until

BOUND = 20.0  # seconds any one step may take on a loaded machine
R = FJT.Result
STEP = {"nextage": (0.1, -0.1, 0.0, 0.0, 0.1, 0.0), "vplus": (0.1, 0.05, -0.1, 0.0, -0.1, 0.0), "rsi": (0.1, 0.05, -0.05, 0.0, 0.1, 0.0)}


@pytest.fixture
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:  # a domain no other test uses meanwhile (dds_domain.py)
        yield claimed


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_dds_client_moves_each_bridge_and_is_refused_and_stopped(kind: str, env: dict[str, str]) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        cell, tool = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        bridge = None
        try:
            bridge = await start_bridge(KINDS[kind], cell.create_node(f"{kind}_bridge"), clock, real_time=True)
            arm = Arm(tool.create_node("moveit_simple_controller_manager"), KINDS[kind], clock)
            await arm.ready(BOUND)
            names, start = arm.kind.joints, arm.joints()
            points = three_points(start, STEP[kind], spacing=1.0)  # V+ reports the arm at the end of each motion: a leg per point
            began = clock.now()
            done = await arm.run(goal(names, points), BOUND)
            await clock.sleep(0.2)  # the next joint_states
            trail, reached = arm.trail(began), arm.joints()
            beyond = reached.copy()
            beyond[1] = 4.0
            over_limit = await arm.run(goal(names, [(1.0, beyond)]), BOUND)
            unknown = await arm.run(goal((*names[:-1], "not_a_joint"), [(1.0, reached)]), BOUND)
            far = three_points(reached, [-2 * v for v in STEP[kind]], spacing=1.0)
            handle = await arm.send(goal(names, far), BOUND)
            moved = await poll_until(clock, lambda: float(np.max(np.abs(arm.joints() - reached))) > 0.08, BOUND, 0.01)
            cancel = await arm.cancel(handle, BOUND)
            cancelled = await arm.client.result(handle, BOUND)
            stopped = await arm.at_rest(BOUND)
            await clock.sleep(0.5)
            return dict(points=points, done=done, trail=trail, reached=reached, over_limit=over_limit, unknown=unknown, moved=moved,
                        far=[reached] + [p for _, p in far], cancel=cancel, cancelled=cancelled, stopped=stopped, still=arm.joints())
        finally:
            if bridge is not None:
                await bridge.close()
            await tool.shutdown()
            await cell.shutdown()

    out = run_with_clock(main, real_clock())
    assert out["done"].status == GoalStatus.STATUS_SUCCEEDED, out["done"].result.error_string
    np.testing.assert_allclose(out["reached"], out["points"][-1][1], atol=1e-3)
    assert follows(out["trail"], [out["trail"][0]] + [p for _, p in out["points"]]) is None, "joint_states follow the path"
    assert (out["over_limit"].status, out["over_limit"].result.error_code) == (GoalStatus.STATUS_ABORTED, R.INVALID_GOAL)
    assert f"{KINDS[kind].joints[1]} at 4.0000 rad is outside its limits" in out["over_limit"].result.error_string
    assert (out["unknown"].status, out["unknown"].result.error_code) == (GoalStatus.STATUS_ABORTED, R.INVALID_JOINTS)
    assert "'not_a_joint'" in out["unknown"].result.error_string
    assert out["moved"] and out["cancel"].return_code == 0 and out["cancelled"].status == GoalStatus.STATUS_CANCELED
    far = out["far"]
    assert np.max(np.abs(out["stopped"] - far[-1])) > 0.05 and distance_to_path(out["stopped"], far) < 0.01
    np.testing.assert_allclose(out["still"], out["stopped"], atol=1e-4)


def test_the_types_on_the_wire_are_control_msgs_as_jazzy_hashes_them() -> None:
    """What a ROS 2 peer checks before it matches an endpoint: the type hash of the controller's state
    (the same as ``ros2 topic info -v`` shows for joint_trajectory_controller's on Jazzy) and the action's parts."""
    registry = mirrors.registry()
    assert type_hash(registry, "control_msgs/msg/JointTrajectoryControllerState") == (
        "RIHS01_51d8dd89cc624cbe9daaeeb4d80d6de9b86168ffdc3be41fefc0953e3c26e480"
    )
    assert type_hash(registry, "trajectory_msgs/msg/JointTrajectory") == "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e"
    wire = registry.wire_action("control_msgs/action/FollowJointTrajectory")
    assert "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_Request_" in repr(wire["SendGoal_Request"])
