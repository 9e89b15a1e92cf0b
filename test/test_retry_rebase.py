"""A motion that may have run is never sent again blindly: the engine's retry re-bases relative moves.

The link drops while the controller runs a relative move; the application allows a retry.  The
retried function must end where the first attempt's move would have ended (its goal fixed from the
pose measured when that move started), not a whole move further.  Measured at the simulators:
the V+ simulator's arm and the Nextage simulator's joints.
"""
from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

import pytest
from app_builder import make_app
from machine_harness import Harness
from scripted_backend import ScriptedBackend

from cell_runner.deployment import deploy_local
from core_functions.geometry import Pose
from core_functions.primitives import MotionResult, MoveCartesian, MoveJoints, MoveRelative, SetSpeed
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN
from execution_engine.app_model.model import ErrorPolicy
from execution_engine.engine.report import RunReport
from execution_engine.machine.rebase import RelativeGoals, Step
from node_transport import typed
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.qos import COMMANDS
from node_transport.wire import BridgeCommand, BridgeFeedback, SmRequest, bridge_topic
from robot_bridges.backend import FaultKind, RobotBackend
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.vplus.backend import VPlusBackend
from robot_bridges.vplus.codec import Skill
from robot_bridges.vplus.simulator import VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
DOWN = "0.45,0.1,0.4,3.14159265,0,0"  # the Viper's tool pointing down, in reach
UP_20_MM = ("0", "0", "0.02", "0", "0", "0", "tool")


async def run_app(clock: Clock, backend: RobotBackend, operations: list[dict[str, tuple[str, ...]]], robot: Any, retries: int = 1) -> RunReport:
    deployment = await deploy_local(clock, robot, backend, machine_parameters={"trajectory_db": ":memory:"})
    try:
        return await deployment.engine.run(make_app(operations, ErrorPolicy(retries=retries, action="abort"), robot=robot))
    finally:
        await deployment.close()


def test_a_move_rel_tool_whose_link_dropped_is_not_sent_again_the_arm_moves_20_mm_not_40(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[RunReport, Pose, list[Skill]]:
        async with VPlusSimulator(clock) as sim:
            backend = VPlusBackend(clock, "127.0.0.1", sim.port, ack_timeout=2.0)
            sim.faults.drop_on.add("move_rel_tool")  # the controller runs the move; its ack never comes
            report = await run_app(clock, backend, [{"arm": ("move_to", DOWN)}, {"arm": ("move_relative", *UP_20_MM)}], ADEPT_VIPER_S850)
            return report, Pose.from_matrix(sim.arm.kin.forward(sim.arm.joints())), [m.command.skill for m in sim.received]

    report, after, skills = run_sim(main)
    assert report.ok and report.retries == 1
    assert report.errors[0].fault == "connection" and "move_rel_tool" in report.errors[0].error
    before = Pose.from_xyz_rpy(*(float(v) for v in DOWN.split(",")))  # where operation 1 left the tool
    assert after.distance_to(before) == pytest.approx(0.020, abs=2e-6)  # 20 mm in total, not 40
    assert after.distance_to(before.compose(Pose(0.0, 0.0, 0.02))) < 2e-6 and after.angle_to(before) < 1e-5  # along the tool's z
    assert skills.count(Skill.MOVE_REL_TOOL) == 1  # sent once; the retry sent the first attempt's goal as a move_to
    assert skills[-2:] == [Skill.MOVE_TO, Skill.BREAK]


def test_a_world_relative_move_retried_after_a_lost_link_ends_at_the_first_attempts_goal_on_nextage(run_sim: Run) -> None:
    """The Nextage simulator loses the link half-way through a 60 mm move (the arm did half); the retry goes on to the goal."""

    async def main(clock: Clock) -> tuple[RunReport, Pose, Pose]:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("left_arm")
        backend.inject_fault("left_arm", FaultKind.CONNECTION, 0.5)
        report = await run_app(clock, backend, [{"left_arm": ("move_relative", "0", "0.06", "0")}], NEXTAGE_OPEN)
        end = backend.tcp_pose("left_arm")
        assert start is not None and end is not None
        return report, start, end

    report, start, end = run_sim(main)
    assert report.ok and report.retries == 1 and report.errors[0].fault == "connection"
    assert end.y - start.y == pytest.approx(0.06, abs=1e-4)  # not 0.09: half a move done, then the rest to the goal
    assert abs(end.x - start.x) < 1e-4 and abs(end.z - start.z) < 1e-4


# ------------------------------------------------------------------------- the goal book
def request(attempt: int, operation: str = "3", params: tuple[str, ...] = UP_20_MM) -> SmRequest:
    return SmRequest(id=f"r{attempt}", operation=operation, function="move_relative", params=params, attempt=attempt)


def taken(goals: RelativeGoals, index: int, primitive: Any) -> Step:
    step = goals.step(index, primitive)
    goals.take(step)
    return step


UP = MoveRelative(Pose(0.0, 0.0, 0.002), reference="tool")
GOAL = MoveCartesian(Pose(0.4, 0.1, 0.3), "linear", frame="goal of move_relative #2, attempt 1")


def test_a_retry_sends_the_recorded_goal_only_along_the_same_plan() -> None:
    goals = RelativeGoals()
    goals.begin(request(1))
    assert taken(goals, 0, SetSpeed(0.25)).needs_goal is False
    assert taken(goals, 1, UP).needs_goal  # first attempt: measure, fix the goal, send the relative move
    goals.record(1, GOAL)
    goals.begin(request(2))  # the retry of the same call
    assert taken(goals, 0, SetSpeed(0.25)).send == SetSpeed(0.25)
    step = taken(goals, 1, UP)
    assert step.send == GOAL and not step.needs_goal
    goals.begin(request(3))  # the skill took another branch: from there on, measured afresh
    taken(goals, 0, SetSpeed(0.5))
    assert taken(goals, 1, UP).needs_goal


def test_goals_never_outlive_their_call() -> None:
    goals = RelativeGoals()
    goals.begin(request(1))
    taken(goals, 0, UP)
    goals.record(0, GOAL)
    goals.begin(request(1))  # a new run of the same operation: attempt 1 again
    assert taken(goals, 0, UP).needs_goal
    goals.record(0, GOAL)
    goals.begin(request(2, operation="4"))  # another call's retry
    assert taken(goals, 0, UP).needs_goal


def test_a_relative_move_that_may_have_run_without_a_known_goal_is_refused_on_a_retry() -> None:
    goals = RelativeGoals()
    goals.begin(request(1))
    nudge = MoveJoints((0.1,), ("joint_1",), relative=True)
    taken(goals, 0, nudge)
    goals.record(0, None)  # the bridge reported no joint of that name
    goals.begin(request(2))
    step = taken(goals, 0, nudge)
    assert step.refusal is not None and "may have run in an earlier attempt" in step.refusal and "not sent again" in step.refusal


def test_the_bridge_measures_an_idle_group_and_refuses_while_it_moves(run_sim: Run) -> None:
    async def main(clock: Clock) -> dict[tuple[str, str], BridgeFeedback]:
        transport = LocalTransport(clock)
        bridge = BridgeNode(transport.create_node("bridge"), ScriptedBackend(clock, NEXTAGE_OPEN, {"move_joints": 2.0}))
        await bridge.start()
        node = transport.create_node("machine")
        answers: dict[tuple[str, str], BridgeFeedback] = {}

        def heard(msg: Any) -> None:
            feedback = typed.from_msg(BridgeFeedback, msg, clock)
            answers[(feedback.id, feedback.status)] = feedback

        node.create_subscription(typed.BridgeFeedbackMsg, bridge_topic("left_arm", "feedback"), heard, COMMANDS)
        commands = node.create_publisher(typed.BridgeCommandMsg, bridge_topic("left_arm", "command"), COMMANDS)
        await clock.sleep(0.01)
        for command, wait in (
            (BridgeCommand("m1", "left_arm", "measure"), 0.1),
            (BridgeCommand("x1", "left_arm", "execute", MoveJoints((0.1,) * 6)), 0.5),
            (BridgeCommand("m2", "left_arm", "measure"), 3.0),  # while x1 moves
        ):
            commands.publish(typed.to_msg(command, clock))
            await clock.sleep(wait)
        await bridge.close()
        return answers

    answers = run_sim(main)
    measured = answers[("m1", "measured")].result
    assert isinstance(measured, MotionResult) and measured.tcp == Pose() and len(measured.positions) == len(NEXTAGE_OPEN.joint_names)
    busy = answers[("m2", "error")]
    assert busy.fault is FaultKind.BUSY and "no measurement now" in (busy.error or "")
    assert ("x1", "done") in answers


class SlowToMeasure(ScriptedBackend):
    """A controller that takes half a second to say where the arm is (a resync over a slow link)."""

    async def measure(self, group: str) -> MotionResult:
        await self.clock.sleep(0.5)
        return await super().measure(group)


def test_a_stop_while_the_arm_is_measured_wins_over_the_relative_move(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str]]:
        bench = await Harness(clock, backend_class=SlowToMeasure).start()
        backend = bench.backend
        request_id = bench.send("left_arm", "move_relative", "0", "0", "0.02")
        await bench.until_state("left_arm", "Motion")
        await clock.sleep(0.1)  # the measurement is under way
        assert (await bench.service("left_arm", "stop")).success
        result = await bench.result(request_id)
        await bench.close()
        return result, [e.kind for e in backend.log]

    result, executed = run_sim(main)
    assert result.outcome == "preempted" and result.fault is FaultKind.STOPPED
    assert executed == []  # the move never went out
