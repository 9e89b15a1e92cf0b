"""The FollowJointTrajectory server every bridge offers takes the speed override like any motion: a goal under way
when it changes goes on along its path at the new share of its speed and still succeeds (its path tolerance is
checked where the arm is on the path, not where the written timing would have it); on the Nextage its joint
velocities from joint_states halve; the V+ legs run at the controller's monitor speed.  The override arrives as the
engine publishes it (EngineStatus.speed_override), from the client's side of the wire (fjt_client.py)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from fjt_client import follows, goal, three_points
from test_follow_joint_trajectory import BOUND, cell

from node_transport.action import GoalStatus
from node_transport.carriage import TypedPublisher
from node_transport.clock import Clock
from node_transport.qos import LATCHED
from node_transport.wire import ENGINE_STATUS, EngineStatus
from speed_override_checks import Samples

STEP = {"nextage": (0.3, 0.0, 0.0, 0.0, 0.3, 0.0), "vplus": (0.3, 0.0, 0.0, 0.0, -0.3, 0.0)}  # 0.15 rad/s for 6 s (points every 2 s)


@pytest.mark.parametrize("kind", ["nextage", "vplus"])
def test_a_goal_under_way_slows_on_its_path_and_succeeds(kind: str, run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        bridge, arm = await cell(clock, kind)
        engine = TypedPublisher(arm.node, EngineStatus, ENGINE_STATUS, LATCHED)
        try:
            points = three_points(arm.joints(), STEP[kind], spacing=2.0)
            began = clock.now()
            handle = await arm.send(goal(arm.kind.joints, points), BOUND)
            await clock.sleep(2.5)
            changed = clock.now() - began
            engine.publish(EngineStatus("", "idle", 0, 0, clock.now(), speed_override=50.0))
            result = await arm.client.result(handle, BOUND)
            took = clock.now() - began
            await clock.sleep(0.2)
            states = [(t - began, [where[n] for n in arm.kind.joints]) for t, where in arm.states if t >= began]
            return result, took, changed, points, Samples(np.array([t for t, _ in states]), np.array([q for _, q in states])), bridge.backend.speed_override
        finally:
            await bridge.close()

    result, took, changed, points, samples, rate = run_sim(main)
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.error_string
    assert rate == 0.5
    rest = 6.0 - changed
    assert took >= changed + rest * 1.5  # the rest of the path, slower (half speed once the rate has come down)
    np.testing.assert_allclose(samples.q[-1], points[-1][1], atol=1e-3)
    if kind == "nextage":
        before = samples.window(0.8, changed).speed()[0]
        after = samples.window(changed + 0.6, changed + 2.6).speed()[0]
        assert before == pytest.approx(0.15, rel=0.05) and after == pytest.approx(0.5 * before, rel=0.05)
        assert follows(samples.q, [samples.q[0]] + [p for _, p in points], 1e-3) is None  # on its path, never back along it
