"""The ``ros2-control`` back end (issue 23 item 2) against a joint_trajectory_controller stand-in, in simulated time.

The cell (engine, machine, bridge) runs on one local transport, the robot's "ROS graph" (the fake
driver of fake_fjt_server.py and the back end's client node) on another, as ``run`` has it with a
real robot.  What a user relies on: an application runs to FINISHED on a robot known only by its URDF
and its controller's action, no trajectory faster than the URDF allows; a pause cancels the goal and
the resume plans again from where the arm stopped; a goal the controller refuses, a joint state that
cannot be true and a controller that stops reporting are faults with the controller's words; a
gripper nobody configured is said at validate time; a bad option is one line naming it.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fake_fjt_server import R, FakeDriver, moved_too_fast, urdf_limits

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.app_digest import NotDigestible
from cell_runner.dry_run.runner import dry_run
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.verdict_cache import verdict_key
from core_functions.primitives import EndEffector, FullBodyMove, MoveCartesian, MoveJoints
from core_functions.robots import KUKA_KR, NEXTAGE_OPEN
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from node_transport import typed
from node_transport.local import LocalTransport
from node_transport.qos import LATCHED
from node_transport.wire import sm_topic
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.registry import check_options
from robot_bridges.ros2_control.backend import Ros2ControlBackend
from robot_bridges.ros2_control.link import GraphLink
from robot_bridges.ros2_control.options import parse_options

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
ROOT = Path(__file__).resolve().parents[1]
URDF_FILE = ROOT / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf"
URDF = URDF_FILE.read_text()
DEMO = ROOT / "apps_xml" / "kuka_rsi_demo.xml"
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"
GRIPPER = "/gripper_controller/gripper_cmd"
OPTIONS = {"arm.controller": CONTROLLER, "arm.gripper": GRIPPER, "arm.gripper_open": "0.04", "arm.gripper_closed": "0.01"}


async def robot(clock: Clock, extra: dict[str, str] | None = None, gripper: str | None = GRIPPER) -> tuple[LocalTransport, FakeDriver, Ros2ControlBackend]:
    graph = LocalTransport(clock)
    driver = FakeDriver(graph.create_node("controller_manager"), clock, URDF, {CONTROLLER: KUKA_KR.group("arm").joint_names}, KUKA_KR.poses["home"], gripper=gripper)
    settings = parse_options(BackendOptions(robot=KUKA_KR, extra=extra if extra is not None else OPTIONS))
    backend = Ros2ControlBackend(clock, KUKA_KR, settings, GraphLink(graph.create_node("ros2_control_client"), settings))
    await backend.start()
    return graph, driver, backend


async def run_demo(clock: Clock, refuse: tuple[int, str] | None = None) -> tuple[Any, FakeDriver, list[str]]:
    """The KUKA demonstrator on the cell's transport, the robot on the graph's; the arm machine's states as seen on its topic."""
    graph, driver, backend = await robot(clock)
    driver.refuse = refuse
    app = load_application(DEMO, full_catalog())
    deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
    states: list[str] = []
    deployment.transport.create_node("viewer").create_subscription(typed.MachineStateMsg, sm_topic("arm", "state"), lambda m: states.append(m.state), LATCHED)
    try:
        report = await deployment.engine.run(app)
    finally:
        await deployment.close()
        await driver.close()
        await graph.shutdown()
    return report, driver, states


def test_the_kuka_demo_runs_to_finished_within_the_urdf_speeds(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[Any, FakeDriver]:
        report, driver, _ = await run_demo(clock)
        return report, driver

    report, driver = run_sim(main)
    assert report.ok, report.summary_lines()
    limits = urdf_limits(URDF)
    assert len(driver.goals) >= 8 and all(g.outcome == "succeeded" for g in driver.goals)
    assert [bad for g in driver.goals for bad in moved_too_fast(g, limits)] == []
    assert driver.grips == [0.04, 0.01, 0.04]  # pick: open, close; place: open -- at the configured positions
    home = [KUKA_KR.poses["home"][j] for j in KUKA_KR.group("arm").joint_names]
    np.testing.assert_allclose([driver.positions[j] for j in KUKA_KR.group("arm").joint_names], home, atol=0.01)


def test_pause_cancels_and_resume_replans_from_where_the_arm_stopped(run_sim: Run) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        graph, driver, backend = await robot(clock)
        target = tuple(math.radians(v) for v in (90, -60, 60, 0, 30, 0))
        try:
            motion = clock.loop.create_task(backend.execute("arm", MoveJoints(target)))
            await clock.sleep(0.4)
            await backend.pause("arm")
            await clock.sleep(0.2)
            held = dict(driver.positions)
            await clock.sleep(2.0)  # paused: nothing moves, nothing is sent
            still, goals_while_paused = dict(driver.positions), len(driver.goals)
            await backend.resume("arm")
            result = await motion
            return dict(driver=driver, held=held, still=still, paused_goals=goals_while_paused, result=result, target=target)
        finally:
            await driver.close()
            await graph.shutdown()

    out = run_sim(main)
    driver = out["driver"]
    first, second = driver.goals
    assert first.outcome == "canceled" and second.outcome == "succeeded" and out["paused_goals"] == 1
    assert out["held"] == out["still"], "the arm held while paused"
    stopped = [out["held"][j] for j in second.joints]
    assert 0.1 < stopped[0] < math.radians(89), "cancelled mid-way"
    np.testing.assert_allclose(second.points[0], stopped, atol=1e-9)  # the new plan starts where the arm stood
    np.testing.assert_allclose(out["result"].positions, out["target"], atol=0.01)
    assert moved_too_fast(second, urdf_limits(URDF)) == []


def test_a_goal_the_controller_refuses_ends_in_error_handling_with_its_words(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str]]:
        report, _, states = await run_demo(clock, refuse=(R.PATH_TOLERANCE_VIOLATED, "A3 deviates 0.2 rad from the path"))
        return report, states

    report, states = run_sim(main)
    assert not report.ok and "ErrorHandling" in states
    error = report.errors[0].error
    assert "PATH_TOLERANCE_VIOLATED: A3 deviates 0.2 rad from the path" in error and CONTROLLER in error


@pytest.mark.parametrize("trouble", ["nan", "jump", "silence"])
def test_joint_states_that_cannot_be_trusted_fault_the_motion(run_sim: Run, trouble: str) -> None:
    async def main(clock: Clock) -> BridgeError:
        graph, driver, backend = await robot(clock)
        try:
            motion = clock.loop.create_task(backend.execute("arm", MoveJoints(tuple(math.radians(v) for v in (90, -60, 60, 0, 30, 0)))))
            await clock.sleep(0.3)
            if trouble == "nan":
                driver.corrupt = ("A2", math.nan)
            elif trouble == "jump":
                driver.corrupt = ("A4", driver.positions["A4"] + 0.5)
            else:
                driver.states_on = False
            with pytest.raises(BridgeError) as caught:
                await motion
            await clock.sleep(driver.period * 2)  # the controller's next step takes the cancel
            assert driver.goals[-1].outcome == "canceled", "the goal is cancelled, not left running"
            return caught.value
        finally:
            await driver.close()
            await graph.shutdown()

    error = run_sim(main)
    assert error.kind is FaultKind.CONTROLLER
    expected = {"nan": "A2 is nan", "jump": "A4 jumped", "silence": "joint_states stopped"}[trouble]
    assert expected in str(error)


def test_cartesian_moves_use_the_urdf_model_and_a_linear_move_stays_on_its_line(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, list[Any]]:
        graph, driver, backend = await robot(clock)
        try:
            await backend.execute("arm", MoveJoints(tuple(math.radians(v) for v in (0, -80, 85, 0, 35, 0))))
            start = backend.tcp_pose("arm")
            assert start is not None
            target = start.translated(dy=0.2, dz=-0.1)
            await backend.execute("arm", MoveCartesian(target, "linear"))
            goal = driver.goals[-1]
            poses = [backend.chains["arm"].tip_pose(backend.chains["arm"].with_joints(np.zeros(6), p)) for p in goal.points]
            return start, target, poses
        finally:
            await driver.close()
            await graph.shutdown()

    start, target, poses = run_sim(main)
    a, b = np.array([start.x, start.y, start.z]), np.array([target.x, target.y, target.z])
    for pose in poses:
        p = np.array([pose.x, pose.y, pose.z])
        u = float(np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1))
        assert np.linalg.norm(p - (a + u * (b - a))) < 2e-4  # every point sent lies on the straight line
    assert poses[-1].distance_to(target) < 1e-4


def test_end_effectors_without_a_gripper_are_not_available_and_the_dry_run_says_so_at_the_line(run_sim: Run) -> None:
    async def main(clock: Clock) -> BridgeError:
        graph, driver, backend = await robot(clock, extra={"arm.controller": CONTROLLER}, gripper=None)
        try:
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", EndEffector("gripper_close"))
            return caught.value
        finally:
            await driver.close()
            await graph.shutdown()

    error = run_sim(main)
    assert error.kind is FaultKind.UNSUPPORTED and "not available on this robot" in str(error) and "arm.gripper=" in str(error)
    app = load_application(DEMO, full_catalog())
    report = dry_run(app, "ros2-control", BackendOptions(robot=KUKA_KR, extra={"urdf": str(URDF_FILE), "transport": "model"}))
    found = [f for f in report.findings if "not available on this robot" in f.message]
    assert found and all(f.kind == "unsupported" for f in found)
    with_gripper = dry_run(app, "ros2-control", BackendOptions(robot=KUKA_KR, extra={"urdf": str(URDF_FILE), "transport": "model", "arm.gripper": GRIPPER}))
    assert with_gripper.findings == () or list(with_gripper.findings) == [], with_gripper.findings
    assert with_gripper.cycle_time > 1.0


@pytest.mark.parametrize(("extra", "message"), [
    ({"arm.controler": "x"}, "ros2-control: unknown option(s) arm.controler"),
    ({"transport": "zenoh"}, "ros2-control: transport='zenoh' must be one of dds, ros, model"),
    ({"state_timeout": "inf"}, "ros2-control: state_timeout must be a number in [0.01, 60] s, got 'inf'"),
    ({"arm.joints": "A1,A2,A3"}, "ros2-control: arm.joints must name 6 different joints"),
    ({"urdf": "/nonexistent/robot.urdf"}, "ros2-control: urdf=/nonexistent/robot.urdf: No such file or directory"),
])
def test_a_bad_option_is_one_line_naming_it(extra: dict[str, str], message: str) -> None:
    with pytest.raises(ValueError) as caught:
        check_options("ros2-control", BackendOptions(robot=KUKA_KR, extra=extra), 1.0)
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)


def test_a_controller_in_real_time_refuses_another_speed() -> None:
    with pytest.raises(ValueError, match="the controller runs in real time: run with --speed 1"):
        check_options("ros2-control", BackendOptions(robot=KUKA_KR), 10.0)


def test_a_dry_run_verdict_is_kept_only_for_a_urdf_file_and_follows_its_bytes(tmp_path: Path) -> None:
    app = load_application(DEMO, full_catalog())
    from_graph = setup_for("ros2-control", BackendOptions(robot=KUKA_KR, extra=OPTIONS))
    assert from_graph.options.extra["transport"] == "model" and from_graph.options.extra["description"] == "dds"
    with pytest.raises(NotDigestible, match="/robot_description"):
        verdict_key(app, from_graph, None)
    copy = tmp_path / "robot.urdf"
    copy.write_text(URDF)
    keyed = setup_for("ros2-control", BackendOptions(robot=KUKA_KR, extra={**OPTIONS, "urdf": str(copy)}))
    before = verdict_key(app, keyed, None)
    copy.write_text(URDF.replace('velocity="2.722713633111154"', 'velocity="1.0"', 1))
    assert verdict_key(app, keyed, None) != before, "another URDF, another verdict"


NEXTAGE_URDF = (ROOT / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf").read_text()


def test_a_full_body_move_drives_three_controllers_on_one_time_line_and_pauses_them_together(run_sim: Run) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        graph = LocalTransport(clock)
        controllers = {f"/{g.name}_controller/follow_joint_trajectory": g.joint_names for g in NEXTAGE_OPEN.groups}
        driver = FakeDriver(graph.create_node("controller_manager"), clock, NEXTAGE_URDF, controllers, NEXTAGE_OPEN.poses["initial"])
        settings = parse_options(BackendOptions(robot=NEXTAGE_OPEN))
        backend = Ros2ControlBackend(clock, NEXTAGE_OPEN, settings, GraphLink(graph.create_node("ros2_control_client"), settings))
        await backend.start()
        names = NEXTAGE_OPEN.joint_names
        goal = tuple(v + (0.3 if not n.startswith("HEAD") else 0.1) for n, v in zip(names, (NEXTAGE_OPEN.poses["initial"][n] for n in names)))
        try:
            motion = clock.loop.create_task(backend.execute("left_arm", FullBodyMove(names, goal)))
            await clock.sleep(0.3)
            busy = [await _refused(backend, g) for g in ("right_arm", "torso_head")]
            await backend.pause("right_arm")  # a partner's pause holds the whole move
            await clock.sleep(1.0)
            held = dict(driver.positions)
            await backend.resume("left_arm")
            result = await motion
            return dict(driver=driver, held=held, result=result, goal=goal, busy=busy)
        finally:
            await driver.close()
            await graph.shutdown()

    out = run_sim(main)
    goals = out["driver"].goals
    assert sorted(g.outcome for g in goals) == ["canceled"] * 3 + ["succeeded"] * 3
    first, second = goals[:3], goals[3:]
    assert {g.joints[0][:4] for g in first} == {"LARM", "RARM", "CHES"}
    assert all(g.times == first[0].times for g in first) and all(g.times == second[0].times for g in second), "one time line"
    for played in second:
        np.testing.assert_allclose(played.points[0], [out["held"][j] for j in played.joints], atol=1e-9)
    final = dict(zip(out["result"].joint_names, out["result"].positions))
    np.testing.assert_allclose([final[n] for n in NEXTAGE_OPEN.joint_names], out["goal"], atol=0.01)
    assert all("is running a primitive" in message for message in out["busy"])


async def _refused(backend: Ros2ControlBackend, group: str) -> str:
    with pytest.raises(BridgeError) as caught:
        await backend.execute(group, MoveJoints(tuple(0.0 for _ in NEXTAGE_OPEN.group(group).joint_names)))
    return str(caught.value)


def test_stop_cancels_the_goal_and_holds_the_arm_and_a_pause_racing_the_goal_still_cancels_it(run_sim: Run) -> None:
    async def main(clock: Clock) -> dict[str, Any]:
        graph, driver, backend = await robot(clock)
        far = tuple(math.radians(v) for v in (90, -60, 60, 0, 30, 0))
        try:
            motion = clock.loop.create_task(backend.execute("arm", MoveJoints(far)))
            await clock.sleep(0.3)
            await backend.stop("arm")
            with pytest.raises(BridgeError) as stopped:
                await motion
            await clock.sleep(0.1)
            held = dict(driver.positions)
            await clock.sleep(1.0)
            still = dict(driver.positions)
            raced = clock.loop.create_task(backend.execute("arm", MoveJoints(tuple(math.radians(v) for v in (0, -90, 90, 0, 0, 0)))))
            await clock.sleep(0)  # the goal is on its way, not yet accepted
            await backend.pause("arm")
            await clock.sleep(1.0)
            paused_outcome, paused_goals = driver.goals[-1].outcome, len(driver.goals)
            await backend.resume("arm")
            result = await raced
            return dict(stopped=stopped.value, held=held, still=still, driver=driver, paused_outcome=paused_outcome, paused_goals=paused_goals, result=result)
        finally:
            await driver.close()
            await graph.shutdown()

    out = run_sim(main)
    assert out["stopped"].kind is FaultKind.STOPPED and out["driver"].goals[0].outcome == "canceled"
    assert out["held"] == out["still"], "stopped: the arm holds"
    assert out["paused_outcome"] == "canceled" and out["paused_goals"] == 2, "a pause while the goal was on its way cancels it once accepted"
    np.testing.assert_allclose(out["result"].positions, [math.radians(v) for v in (0, -90, 90, 0, 0, 0)], atol=0.01)
