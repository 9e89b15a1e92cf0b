"""A bridge stops promptly whatever FollowJointTrajectory goals it has served (anything that listens stops on SIGTERM within 2 s).

A client sends the Nextage bridge goals of every ending -- one that succeeds, two refused, one cancelled -- and
leaves one running with its result asked for; then the bridge node stops as a SIGTERM stops it (its close).  On
the simulated clock a wait on a timer (an ended goal kept for RESULT_TIMEOUT, a goal's path time) would show as
simulated time passing, and a wait on something that never comes as the bound expiring: the stop must take no
simulated time beyond its own bound, leave no task of the bridge behind, and answer the running goal's result.
"""
from __future__ import annotations

import asyncio
from typing import Any

from fjt_client import FJT, NEXTAGE, Arm, goal, start_bridge, three_points
from rclpy_like import RclpyLikeActionClient

from node_transport.action import CLOSE_TIMEOUT, ActionServer, GoalHandle, GoalStatus
from node_transport.clock import Clock
from node_transport.local import LocalTransport

BOUND = 30.0
STEP = (0.1, -0.1, 0.0, 0.0, 0.1, 0.0)


def test_the_bridge_stops_promptly_after_goals_of_every_ending(run_sim: Any) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        bus = LocalTransport(clock)
        bridge = await start_bridge(NEXTAGE, bus.create_node("nextage_bridge"), clock)
        arm = Arm(bus.create_node("independent_client"), NEXTAGE, clock)
        await arm.ready(BOUND)
        names, start = arm.kind.joints, arm.joints()
        out: dict[str, Any] = {"done": await arm.run(goal(names, three_points(start, STEP)), BOUND)}
        beyond = arm.joints().copy()
        beyond[1] = 4.0
        out["over_limit"] = await arm.run(goal(names, [(1.0, beyond)]), BOUND)
        out["unknown"] = await arm.run(goal((*names[:-1], "not_a_joint"), [(1.0, arm.joints())]), BOUND)
        far = three_points(arm.joints(), [-2 * v for v in STEP], spacing=2.0)
        cancelled = await arm.send(goal(names, far), BOUND)
        await clock.sleep(0.5)
        await arm.cancel(cancelled, BOUND)
        out["cancelled"] = await arm.client.result(cancelled, BOUND)
        running = await arm.send(goal(names, three_points(arm.joints(), STEP, spacing=3.0)), BOUND)
        await clock.sleep(0.5)
        result = asyncio.ensure_future(arm.client.result(running, BOUND))  # asked for while the goal runs
        await clock.sleep(0.1)
        ours = {asyncio.current_task(), result}
        client = {t for t in asyncio.all_tasks() if t not in ours and "independent_client" in repr(t)}
        began = clock.now()
        await clock.wait_for(bridge.close(), CLOSE_TIMEOUT + 1.0)
        out["took"] = clock.now() - began
        out["left"] = [t for t in asyncio.all_tasks() if t not in ours and t not in client and not t.done()]
        try:
            out["running"] = await clock.wait_for(result, 1.0)
        except TimeoutError:
            out["running"] = None  # never answered
        return out

    out = run_sim(main)
    assert out["done"].status == GoalStatus.STATUS_SUCCEEDED
    assert [out[k].status for k in ("over_limit", "unknown")] == [GoalStatus.STATUS_ABORTED] * 2
    assert out["cancelled"].status == GoalStatus.STATUS_CANCELED
    assert out["took"] <= CLOSE_TIMEOUT, f"the stop took {out['took']:.3f} s of the simulated clock"
    assert out["left"] == [], f"tasks left after the stop: {out['left']}"
    assert out["running"] is not None, "the running goal's result was never answered"
    assert out["running"].status == GoalStatus.STATUS_ABORTED  # the client hears the goal's end, not silence
    assert "shutting down" in out["running"].result.error_string


def test_a_goal_that_does_not_end_when_told_is_cancelled_and_its_client_answered(run_sim: Any) -> None:
    """An owner whose goal goes on past the close's grace (a back end that does not stop): cancelled, ABORTED, answered."""
    async def main(clock: Clock) -> tuple[float, Any, int]:
        bus = LocalTransport(clock)
        forever = asyncio.Event()

        async def execute(handle: GoalHandle) -> Any:
            await forever.wait()  # never set: only a cancellation ends it
            return FJT.Result()

        server = ActionServer(bus.create_node("server"), FJT, "/arm_controller/follow_joint_trajectory", execute=execute,
                              accept=lambda goal: None, cancel=lambda handle: None)
        client = RclpyLikeActionClient(bus.create_node("client"), "/arm_controller/follow_joint_trajectory", FJT)
        handle = await client.send_goal(goal(("a",), [(1.0, (0.0,))]), 1, timeout=BOUND)
        assert handle is not None
        result = asyncio.ensure_future(client.result(handle, BOUND))
        await clock.sleep(0.1)
        began = clock.now()
        await clock.wait_for(server.close(), CLOSE_TIMEOUT + 1.0)
        took = clock.now() - began
        answer = await clock.wait_for(result, 1.0)
        left = [t for t in asyncio.all_tasks() if t is not asyncio.current_task() and not t.done()]
        late = await client.send_goal(goal(("a",), [(1.0, (0.0,))]), 2, timeout=BOUND)  # once closed, nothing new starts
        return took, answer, len(left), late

    took, answer, left, late = run_sim(main)
    assert took <= CLOSE_TIMEOUT
    assert answer.status == GoalStatus.STATUS_ABORTED
    assert left == 0
    assert late is None
