"""Every bridge serves control_msgs/action/FollowJointTrajectory (issue 23, item 1), on the local transport.

An independent client (fjt_client.py: the wire only) sends goals to the Nextage simulator's, the V+
simulator's and the KUKA RSI simulator's bridge: a 3-point goal succeeds and ``joint_states`` follows
it; goals beyond a limit and with an unknown joint end with the right error codes, naming the joint,
and move nothing; a cancel stops the arm on its path.  On the Nextage: a new goal preempts the
running one, the cell's pause holds a goal and its resume continues it, the safety stop ends it, and
the engine and a client never command one group at once (each refused, named).
"""
from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest
from crossing_cell import CROSSING, start_nextage_cell
from fjt_client import FJT, KINDS, NEXTAGE, Arm, ControllerState, Header, JointTolerance, Kind, Time, distance_to_path, duration, follows, goal, start_bridge, three_points

from core_functions.primitives import MoveJoints
from core_functions.robots import NEXTAGE_OPEN
from node_transport.action import GoalStatus
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import Bool
from node_transport.port import poll_until
from node_transport.qos import LATCHED
from node_transport.wire import ENGINE_STATUS, SAFETY_STOP, BridgeCommand, BridgeFeedback, EngineStatus, FaultKind, GroupProgress, bridge_topic
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.nextage_sim.backend import NextageSimBackend

R = FJT.Result
BOUND = 30.0
STEP = {"nextage": (0.1, -0.1, 0.0, 0.0, 0.1, 0.0), "vplus": (0.1, 0.05, -0.1, 0.0, -0.1, 0.0), "rsi": (0.1, 0.05, -0.05, 0.0, 0.1, 0.0)}


async def cell(clock: Clock, kind: str) -> tuple[Any, Arm]:
    bus = LocalTransport(clock)
    bridge = await start_bridge(KINDS[kind], bus.create_node(f"{kind}_bridge"), clock)
    arm = Arm(bus.create_node("moveit_simple_controller_manager"), KINDS[kind], clock)
    await arm.ready(BOUND)
    return bridge, arm


async def robot_says(bridge: BridgeNode, arm: Arm) -> np.ndarray:
    """The group's joints by the robot's own word (V+: a break asks the controller where the arm is)."""
    measured = await bridge.backend.measure(bridge.backend.groups[0] if arm.kind is not NEXTAGE else "left_arm")
    where = dict(zip(measured.joint_names, measured.positions))
    return np.array([where[n] for n in arm.kind.joints])


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_client_moves_each_bridge_and_is_refused_and_stopped_as_ros_says(kind: str, run_sim: Any) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        bridge, arm = await cell(clock, kind)
        try:
            names, start = arm.kind.joints, arm.joints()
            points = three_points(start, STEP[kind])
            began = clock.now()
            done = await arm.run(goal(names, points), BOUND)
            await clock.sleep(0.2)  # the next joint_states
            trail, reached = arm.trail(began), arm.joints()
            beyond = points[0][1].copy()
            beyond[1] = 4.0  # past every joint 2's range (Nextage, Viper, KR 6)
            over_limit = await arm.run(goal(names, [(1.0, beyond)]), BOUND)
            too_fast = await arm.run(goal(names, [(0.02, reached + np.array(STEP[kind]) * 3)]), BOUND)
            unknown = await arm.run(goal((*names[:-1], "not_a_joint"), [(1.0, reached)]), BOUND)
            after_refusals = arm.joints()
            far = three_points(reached, [-2 * v for v in STEP[kind]], spacing=2.0)
            handle = await arm.send(goal(names, far), BOUND)
            moved = await poll_until(clock, lambda: float(np.max(np.abs(arm.joints() - reached))) > 0.08, BOUND, 0.01)
            cancel = await arm.cancel(handle, BOUND)
            cancelled = await arm.client.result(handle, BOUND)
            stopped = await arm.at_rest(BOUND)
            await clock.sleep(1.0)
            return dict(points=points, done=done, trail=trail, reached=reached, over_limit=over_limit, too_fast=too_fast, unknown=unknown,
                        after_refusals=after_refusals, far=[reached] + [p for _, p in far], cancel=cancel, cancelled=cancelled,
                        stopped=stopped, still=arm.joints(), feedback=len(handle.feedback), moved=moved, robot=await robot_says(bridge, arm))
        finally:
            await bridge.close()

    out = run_sim(main)
    assert out["done"].status == GoalStatus.STATUS_SUCCEEDED and out["done"].result.error_code == R.SUCCESSFUL, out["done"].result.error_string
    np.testing.assert_allclose(out["reached"], out["points"][-1][1], atol=1e-3)
    assert follows(out["trail"], [out["trail"][0]] + [p for _, p in out["points"]]) is None, "joint_states follow the path"
    refusals = [(out[k].status, out[k].result.error_code) for k in ("over_limit", "too_fast", "unknown")]
    assert refusals == [(GoalStatus.STATUS_ABORTED, R.INVALID_GOAL)] * 2 + [(GoalStatus.STATUS_ABORTED, R.INVALID_JOINTS)]
    joint2 = KINDS[kind].joints[1]
    assert f"{joint2} at 4.0000 rad is outside its limits" in out["over_limit"].result.error_string
    assert "above its limit" in out["too_fast"].result.error_string
    assert "'not_a_joint' is not one of the group's joints" in out["unknown"].result.error_string
    np.testing.assert_allclose(out["after_refusals"], out["reached"], atol=1e-6)  # a refused goal moves nothing
    assert out["moved"] and out["cancel"].return_code == 0 and out["cancelled"].status == GoalStatus.STATUS_CANCELED
    far = out["far"]
    assert np.max(np.abs(out["stopped"] - far[-1])) > 0.05, "stopped before the end"
    assert np.max(np.abs(out["stopped"] - far[0])) > 0.05, "it had moved"
    assert distance_to_path(out["stopped"], far) < 0.01, "stopped on its path"
    np.testing.assert_allclose(out["still"], out["stopped"], atol=1e-4)  # and stays stopped
    np.testing.assert_allclose(out["robot"], out["still"], atol=1e-3)  # where the robot (its simulator) says it is: joint_states is not stale
    assert out["feedback"] > 0


def test_a_new_goal_preempts_the_running_one_as_ros2_control_does(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        bridge, arm = await cell(clock, "nextage")
        try:
            start = arm.joints()
            first = await arm.send(goal(arm.kind.joints, three_points(start, (0.2, 0, 0, 0, 0, 0), 2.0)), BOUND)
            await clock.sleep(1.5)
            target = start + np.array((0.0, -0.2, 0.0, 0.0, 0.1, 0.0))
            second = await arm.send(goal(arm.kind.joints, [(1.5, target)]), BOUND)
            answers = await arm.client.result(first, BOUND), await arm.client.result(second, BOUND)
            await clock.sleep(0.2)  # the next joint_states
            return (*answers, arm.joints(), target)
        finally:
            await bridge.close()

    first, second, reached, target = run_sim(main)
    assert first.status == GoalStatus.STATUS_ABORTED and first.result.error_code == R.INVALID_GOAL
    assert "preempted by a new goal" in first.result.error_string
    assert second.status == GoalStatus.STATUS_SUCCEEDED, second.result.error_string
    np.testing.assert_allclose(reached, target, atol=1e-3)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_cells_pause_holds_a_goal_and_resume_continues_it_the_safety_stop_ends_it(kind: str, run_sim: Any) -> None:
    """The engine's status says paused: the arm stops on its path and the path's time with it; running again: it
    goes on from there to the end, never faster than the path (no jump on joint_states).  The safety stop: the goal
    ends, the arm stays where it stopped, and no goal runs while it is on."""
    async def main(clock: Clock) -> tuple[Any, ...]:
        bridge, arm = await cell(clock, kind)
        engine = TypedPublisher(arm.node, EngineStatus, ENGINE_STATUS, LATCHED)
        safety = arm.node.create_publisher(Bool, f"/{SAFETY_STOP}", LATCHED)
        try:
            start = arm.joints()
            points = three_points(start, (0.1, 0, 0, 0, 0.1, 0))
            began = clock.now()
            handle = await arm.send(goal(arm.kind.joints, points), BOUND)
            await clock.sleep(1.5)
            engine.publish(EngineStatus("", "paused", 0, 0, clock.now()))
            paused = clock.now()
            held = await arm.at_rest(BOUND)
            await clock.sleep_until(paused + 3.0)
            still = arm.joints()
            engine.publish(EngineStatus("", "idle", 0, 0, clock.now()))
            resumed = await arm.client.result(handle, BOUND)
            took = clock.now() - began
            await clock.sleep(0.2)  # the next joint_states
            trail = arm.trail(began)
            handle = await arm.send(goal(arm.kind.joints, three_points(arm.joints(), (-0.1, 0, 0, 0, -0.1, 0))), BOUND)
            await clock.sleep(1.5)
            safety.publish(Bool(True))
            ended = await arm.client.result(handle, BOUND)
            stopped = await arm.at_rest(BOUND)
            refused = await arm.run(goal(arm.kind.joints, [(1.0, stopped)]), BOUND)
            await clock.sleep(1.0)
            return held, still, resumed, took, ended, stopped, arm.joints(), refused, points, trail
        finally:
            await bridge.close()

    held, still, resumed, took, ended, stopped, later, refused, points, trail = run_sim(main)
    np.testing.assert_allclose(still, held, atol=1e-6)
    finishing = 1.0 if kind == "vplus" else 0.0  # V+ finishes the leg under way (at most 1 s of path) before it stands
    assert resumed.status == GoalStatus.STATUS_SUCCEEDED and took >= 3.0 + 3.0 - finishing - 1e-6, resumed.result.error_string
    np.testing.assert_allclose(trail[-1], points[-1][1], atol=1e-3)
    assert distance_to_path(held, [trail[0]] + [p for _, p in points]) < 0.01, "held on its path"
    assert follows(trail, [trail[0]] + [p for _, p in points]) is None, "and went on along it from there"
    assert np.max(np.abs(np.diff(trail, axis=0))) < 0.1 + 1e-6, "no jump: at most the path's speed for a joint_states period (or a V+ leg)"
    assert ended.status == GoalStatus.STATUS_ABORTED and ended.result.error_code == R.PATH_TOLERANCE_VIOLATED
    assert "safety stop" in ended.result.error_string
    np.testing.assert_allclose(later, stopped, atol=1e-6)
    assert refused.result.error_code == R.INVALID_GOAL and "safety stop is on" in refused.result.error_string


def test_an_arm_that_stalls_off_its_path_ends_the_goal_on_the_path_tolerance(run_sim: Any) -> None:
    """The group's machine pauses the bridge (its own pause command) while a goal plays: the arm holds, the
    path goes on, and once they are further apart than the goal's path tolerance the goal ends, naming the joint."""
    async def main(clock: Clock) -> tuple[Any, float, Any]:
        bridge, arm = await cell(clock, "nextage")
        commands = TypedPublisher(arm.node, BridgeCommand, bridge_topic("left_arm", "command"))
        try:
            names = arm.kind.joints
            tolerance = tuple(JointTolerance(name=n, position=0.02) for n in names)
            handle = await arm.send(goal(names, three_points(arm.joints(), (0.0, 0, 0, 0, 0.1, 0)), path_tolerance=tolerance), BOUND)
            await clock.sleep(0.5)
            commands.publish(BridgeCommand("m-1", "left_arm", "pause"))
            paused = clock.now()
            stalled = await arm.client.result(handle, BOUND)
            return stalled, clock.now() - paused, handle
        finally:
            await bridge.close()

    stalled, after, handle = run_sim(main)
    assert stalled.status == GoalStatus.STATUS_ABORTED and stalled.result.error_code == R.PATH_TOLERANCE_VIOLATED
    assert "LARM_JOINT4 is" in stalled.result.error_string and "beyond its path tolerance 0.02 rad" in stalled.result.error_string
    assert 0.2 - 0.06 <= after <= 0.2 + 0.11  # 0.02 rad at 0.1 rad/s, found within a sample period or two
    assert max(abs(e) for e in handle.feedback[-1].error.positions) > 0.02


class OffsetNextage(NextageSimBackend):
    """A Nextage whose LARM_JOINT2 reads 10 mrad off where the arm is (a sensor out of calibration)."""

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names, positions = super().joint_state()
        return names, tuple(v + (0.01 if n == "LARM_JOINT2" else 0.0) for n, v in zip(names, positions))


def test_an_arm_that_ends_off_its_goal_fails_the_goal_tolerance_after_the_goal_time(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, float]:
        bus = LocalTransport(clock)
        bridge = BridgeNode(bus.create_node("nextage_bridge"), OffsetNextage(clock))
        await bridge.start()
        arm = Arm(bus.create_node("client"), NEXTAGE, clock)
        await arm.ready(BOUND)
        try:
            names = arm.kind.joints
            target = arm.joints() + np.array((0.1, 0, 0, 0, 0, 0))
            loose = await arm.run(goal(names, [(1.0, target)], goal_tolerance=(JointTolerance(name="LARM_JOINT2", position=0.05),)), BOUND)
            tight = (JointTolerance(name="LARM_JOINT2", position=0.001),)
            began = clock.now()
            missed = await arm.run(goal(names, [(1.0, target)], goal_tolerance=tight, goal_time_tolerance=duration(0.5)), BOUND)
            return loose, missed, clock.now() - began
        finally:
            await bridge.close()

    loose, missed, took = run_sim(main)
    assert loose.status == GoalStatus.STATUS_SUCCEEDED, loose.result.error_string
    assert missed.status == GoalStatus.STATUS_ABORTED and missed.result.error_code == R.GOAL_TOLERANCE_VIOLATED
    assert "LARM_JOINT2 is 0.0100 rad from the last point" in missed.result.error_string and "0.5 s after the path's end" in missed.result.error_string
    assert took >= 1.0 + 0.5


def test_the_engine_and_a_client_never_command_one_group_at_once(run_sim: Any) -> None:
    """A machine's primitive while a goal holds the group: BUSY, naming the goal; a goal while the
    engine's run holds the group: refused, naming the run; the other arm is free meanwhile."""
    async def main(clock: Clock) -> tuple[Any, ...]:
        bridge, arm = await cell(clock, "nextage")
        answers: list[BridgeFeedback] = []
        subscribe(arm.node, BridgeFeedback, bridge_topic("left_arm", "feedback"), answers.append, lambda error: None)
        commands = TypedPublisher(arm.node, BridgeCommand, bridge_topic("left_arm", "command"))
        engine = TypedPublisher(arm.node, EngineStatus, ENGINE_STATUS, LATCHED)
        try:
            start = arm.joints()
            handle = await arm.send(goal(arm.kind.joints, three_points(start, (0.1, 0, 0, 0, 0, 0))), BOUND)
            await clock.sleep(0.5)
            commands.publish(BridgeCommand("m-1", "left_arm", "execute", MoveJoints(tuple(start))))
            await clock.sleep(0.5)
            finished = await arm.client.result(handle, BOUND)
            engine.publish(EngineStatus("rivets", "running", 1, 3, clock.now(), "1", {"left_arm": GroupProgress("Motion"), "right_arm": GroupProgress("Ready")}))
            await clock.sleep(0.1)
            refused = await arm.run(goal(arm.kind.joints, [(1.0, start)]), BOUND)
            return answers, finished, refused
        finally:
            await bridge.close()

    answers, finished, refused = run_sim(main)
    busy = [a for a in answers if a.id == "m-1"]
    assert [(a.status, a.fault) for a in busy] == [("error", FaultKind.BUSY)]
    assert "left_arm is following FollowJointTrajectory goal" in (busy[0].error or "")
    assert finished.status == GoalStatus.STATUS_SUCCEEDED
    assert refused.result.error_code == R.INVALID_GOAL and "the engine's run of application 'rivets' holds the group" in refused.result.error_string


def test_a_goal_whose_header_stamp_ended_in_the_past_is_old(run_sim: Any) -> None:
    async def main(clock: Clock) -> Any:
        bridge, arm = await cell(clock, "nextage")
        try:
            now = arm.node.now_stamp()
            return await arm.run(goal(arm.kind.joints, [(1.0, arm.joints())], header=Header(stamp=Time(now.sec - 10, 0))), BOUND)
        finally:
            await bridge.close()

    old = run_sim(main)
    assert old.status == GoalStatus.STATUS_ABORTED and old.result.error_code == R.OLD_HEADER_TIMESTAMP


def test_the_controller_state_follows_the_path_and_the_arm(run_sim: Any) -> None:
    """``<controller>/controller_state``, as joint_trajectory_controller publishes it (rqt_joint_trajectory_controller, PlotJuggler)."""
    async def main(clock: Clock) -> list[Any]:
        bridge, arm = await cell(clock, "nextage")
        states: list[Any] = []
        arm.node.create_subscription(ControllerState, f"/{NEXTAGE.controller}/controller_state", states.append)
        try:
            await arm.run(goal(arm.kind.joints, [(1.0, arm.joints() + 0.05)]), BOUND)
            await clock.sleep(0.2)
            return states
        finally:
            await bridge.close()

    states = run_sim(main)
    assert states and all(s.joint_names == NEXTAGE.joints and len(s.feedback.positions) == 6 for s in states)
    moving = [s for s in states if any(abs(v) > 1e-6 for v in s.reference.velocities)]
    assert moving and all(max(abs(v) for v in s.reference.velocities) == pytest.approx(0.05) for s in moving)
    assert all(max(abs(e) for e in s.error.positions) < 5e-3 for s in states)
    assert states[-1].reference.velocities == (0.0,) * 6 and states[-1].speed_scaling_factor == 1.0


def test_a_goal_while_the_engine_runs_the_cell_is_refused_naming_the_run(run_sim: Any, tmp_path: Any, monkeypatch: Any) -> None:
    """The whole Nextage cell (bridge, machines, engine: their executables' bodies) runs an application; a client's
    goal for the left arm meanwhile ends INVALID_GOAL naming the run, and the arm does only what the run does."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))  # the machines' default trajectory database
    application = tmp_path / "crossing.xml"
    application.write_text(CROSSING)

    async def main(clock: Clock) -> tuple[Any, list[str]]:
        bus = LocalTransport(clock)
        tasks = start_nextage_cell(bus, speed=1.0, application=str(application), check=False)
        arm = Arm(bus.create_node("moveit_simple_controller_manager"), NEXTAGE, clock)
        states: list[EngineStatus] = []
        subscribe(arm.node, EngineStatus, ENGINE_STATUS, states.append, lambda error: None, LATCHED)
        try:
            await arm.ready(BOUND)
            assert await poll_until(clock, lambda: any(s.state == "running" for s in states), BOUND, 0.05), "the run never started"
            refused = await arm.run(goal(arm.kind.joints, [(1.0, arm.joints() + 0.05)]), BOUND)
            return refused, [s.state for s in states]
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    refused, seen = run_sim(main)
    assert refused.status == GoalStatus.STATUS_ABORTED and refused.result.error_code == R.INVALID_GOAL
    assert "the engine's run of application 'crossing' holds the group" in refused.result.error_string


def test_the_groups_are_independent_two_clients_move_both_arms_at_once(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        bridge, left = await cell(clock, "nextage")
        right = Arm(left.node, Kind("nextage", "right_arm_controller", NEXTAGE_OPEN.group("right_arm").joint_names), clock)
        try:
            await right.ready(BOUND)
            targets = left.joints() + np.array((0.1, 0, 0, 0, 0.1, 0)), right.joints() + np.array((-0.1, 0, 0, 0, -0.1, 0))
            began = clock.now()
            done = await asyncio.gather(left.run(goal(left.kind.joints, [(2.0, targets[0])]), BOUND),
                                        right.run(goal(right.kind.joints, [(2.0, targets[1])]), BOUND))
            took = clock.now() - began
            await clock.sleep(0.2)  # the next joint_states
            return done, took, (left.joints(), right.joints()), targets
        finally:
            await bridge.close()

    done, took, reached, targets = run_sim(main)
    assert [d.status for d in done] == [GoalStatus.STATUS_SUCCEEDED] * 2 and took < 2.5  # together, not one after the other
    np.testing.assert_allclose(reached[0], targets[0], atol=1e-3)
    np.testing.assert_allclose(reached[1], targets[1], atol=1e-3)
