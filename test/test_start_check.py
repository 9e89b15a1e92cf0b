"""Every run is checked from where the robot is (issue 20, finding 4): the measured joints, the dry
run from them, the way back for a robot left in the middle of an application, and the refusals.

In-process on simulated time, the Nextage simulator with its collision check on, as ``run`` has it.
"""
from __future__ import annotations

import asyncio
import io
import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.robots import NEXTAGE_OPEN
from crossing_cell import WAIT_OPERATION, CollisionWatch, crossing_app
from cell_runner.deployment import Deployment, deploy_local
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.runner import dry_run
from cell_runner.dry_run.simulators import DryRunSetup, setup_for
from cell_runner.dry_run.start import (
    ResumeFrom,
    StartRefused,
    UntrustedState,
    backend_measure,
    check_run,
    execute,
    measured,
    plan_start,
    start_checked,
)
from execution_engine.app_model.model import Application
from node_transport.clock import Clock
from node_transport.msgs import JointState
from node_transport.qos import SENSOR
from node_transport.wire import JOINT_STATES
from robot_bridges.backend import BackendOptions, RobotBackend
from robot_bridges.registry import create_backend


def setup(app: Application) -> DryRunSetup:
    return setup_for("nextage-sim", BackendOptions(robot=app.robot))


async def cell(clock: Clock, app: Application) -> tuple[Deployment, RobotBackend, CollisionWatch]:
    """The Nextage simulator (collision check on, as run has it), machines and engine, and a watch on joint_states."""
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
    deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
    watch = CollisionWatch()
    deployment.transport.create_node("collision_watch").create_subscription(JointState, JOINT_STATES, watch, SENSOR)
    return deployment, backend, watch


async def cancelled_in_the_wait(clock: Clock, deployment: Deployment, app: Application) -> None:
    """Run ``app`` and stop it once it is in its 30 s wait: the left hand stays in the middle."""
    engine = deployment.engine
    first = asyncio.get_running_loop().create_task(engine.run(app))
    for _ in range(600):
        if engine.report is not None and engine.report.operations_done >= WAIT_OPERATION - 1 and engine.state == "running":
            break
        await clock.sleep(0.1)
    await clock.sleep(1.0)
    await engine.operator_command("stop", "test")
    report = await first
    assert report.outcome == "stopped" and report.operations_done == WAIT_OPERATION - 1


def test_a_run_started_again_in_the_middle_goes_back_first_and_never_crosses_the_hands(run_sim: Any, tmp_path: Path) -> None:
    app = crossing_app(tmp_path)
    out = io.StringIO()

    async def main(clock: Clock) -> tuple[DryRunReport, Any, CollisionWatch]:
        deployment, backend, watch = await cell(clock, app)
        try:
            await cancelled_in_the_wait(clock, deployment, app)
            state = measured(app.robot, *backend.joint_state(), "test")
            unchecked = await asyncio.to_thread(dry_run, app, "nextage-sim", BackendOptions(robot=app.robot), None, state.joints)
            report = await start_checked(deployment.engine, app, backend, clock, setup(app), None, None, None, out)
            return unchecked, report, watch
        finally:
            await deployment.close()

    unchecked, report, watch = run_sim(main)
    # the hazard: from where the cancel left the robot, the first operation crosses the hands
    assert any(f.kind == "collision" and f.operation == "1" and f.group == "right_arm" for f in unchecked.findings), unchecked.findings
    # the run: the way back, proved by the dry run, then the whole application
    said = out.getvalue()
    assert "the robot is not where crossing starts" in said and "the run starts with the way back" in said
    assert "left_arm back 0.05 m along the tool axis" in said and "application crossing (way back): FINISHED" in said
    assert report.ok and report.operations_done == 5 and not report.errors
    assert watch.samples > 100 and watch.touching == []


def test_a_robot_left_in_a_collision_is_not_moved_the_run_is_refused_with_the_findings(run_sim: Any, tmp_path: Path) -> None:
    app = crossing_app(tmp_path)

    async def main(clock: Clock) -> tuple[StartRefused, Any, Any, Any]:
        deployment, backend, _ = await cell(clock, app)
        try:
            await cancelled_in_the_wait(clock, deployment, app)
            crashed = await deployment.engine.run(app)  # unchecked: the robot's own check stops the hands touching
            before = backend.joint_state()
            with pytest.raises(StartRefused) as refused:
                await start_checked(deployment.engine, app, backend, clock, setup(app), None, None, None, io.StringIO())
            return refused.value, crashed, before, backend.joint_state()
        finally:
            await deployment.close()

    refusal, crashed, before, after = run_sim(main)
    assert crashed.errors and crashed.errors[0].fault == "collision"
    assert "none of" in refusal.reason and "way(s) back" in refusal.reason and "bring the robot to the start by hand" in refusal.reason
    assert any("way back" in line and "collision" in line for line in refusal.lines), refusal.lines
    assert after == before  # nothing moved


def test_a_stop_while_the_run_is_checked_ends_it_before_anything_moves(run_sim: Any, tmp_path: Path) -> None:
    app = crossing_app(tmp_path)

    async def main(clock: Clock) -> tuple[Any, Any, Any]:
        deployment, backend, _ = await cell(clock, app)
        try:
            await cancelled_in_the_wait(clock, deployment, app)
            before = backend.joint_state()
            measure = backend_measure(app.robot, backend, "test")
            run = await check_run(deployment.engine, app, setup(app), None, measure, clock)
            await deployment.engine.operator_command("stop", "test")
            return await run.run(), before, backend.joint_state()
        finally:
            await deployment.close()

    report, before, after = run_sim(main)
    assert report.outcome == "stopped" and "while the run was being checked" in report.message and report.operations_done == 0
    assert after == before


def test_a_robot_that_moved_while_it_was_checked_is_not_run(run_sim: Any, tmp_path: Path) -> None:
    app = crossing_app(tmp_path)

    async def main(clock: Clock) -> StartRefused:
        deployment, backend, _ = await cell(clock, app)
        try:
            measure = backend_measure(app.robot, backend, "test")
            plan = await asyncio.to_thread(plan_start, app, setup(app), await measure(), None)
            names, positions = backend.joint_state()
            nudged = tuple(p + (0.01 if n == "LARM_JOINT0" else 0.0) for n, p in zip(names, positions))

            async def elsewhere() -> Any:
                return measured(app.robot, names, nudged, "a second look")

            with pytest.raises(StartRefused) as refused:
                await execute(deployment.engine, plan, elsewhere)
            return refused.value
        finally:
            await deployment.close()

    refusal = run_sim(main)
    assert "the robot moved while its run was being checked (LARM_JOINT0 by 0.57 deg, a second look)" in refusal.reason


def test_a_resumed_run_goes_on_from_where_the_robot_is_when_the_dry_run_proves_it(run_sim: Any, tmp_path: Path) -> None:
    app = crossing_app(tmp_path)

    async def main(clock: Clock) -> Any:
        deployment, backend, _ = await cell(clock, app)
        try:
            await cancelled_in_the_wait(clock, deployment, app)
            state = measured(app.robot, *backend.joint_state(), "test")
            resumed = await asyncio.to_thread(plan_start, app, setup(app), state, None, resume=ResumeFrom(WAIT_OPERATION - 1))
            restarted = await asyncio.to_thread(plan_start, app, setup(app), state, None)
            return resumed, restarted
        finally:
            await deployment.close()

    resumed, restarted = run_sim(main)
    assert resumed.way_back is None and "the resumed run goes on from there" in resumed.lines[0]
    assert resumed.report.ok and resumed.report.operations_total == 2  # the wait and the left arm's way home, from there
    assert restarted.way_back is not None  # from the start of the application, the way back comes first


def test_at_the_start_pose_the_check_done_before_connecting_holds(tmp_path: Path) -> None:
    app = crossing_app(tmp_path)
    checked = dry_run(app, "nextage-sim", BackendOptions(robot=app.robot))
    assert checked.ok and checked.start is not None
    state = measured(app.robot, *checked.start, "test")
    plan = plan_start(app, setup(app), state, None, checked=checked)
    assert plan.report is checked and plan.way_back is None and plan.lines == ()


# ------------------------------------------------------------------------- the measured joints
def test_joints_that_cannot_be_trusted_are_refused_in_one_line() -> None:
    names = NEXTAGE_OPEN.joint_names
    home = [NEXTAGE_OPEN.poses["initial"][n] for n in names]
    with pytest.raises(UntrustedState, match=r"^/joint_states gives no position for LARM_JOINT5$"):
        measured(NEXTAGE_OPEN, names[:-1], home[:-1], "/joint_states")
    with pytest.raises(UntrustedState, match=r"gives CHEST_JOINT0 = nan, not a number"):
        measured(NEXTAGE_OPEN, names, [math.nan, *home[1:]], "/joint_states")
    with pytest.raises(UntrustedState, match=r"gives CHEST_JOINT0 at 180.00 deg, outside its limits \[-163.0, 163.0\] deg"):
        measured(NEXTAGE_OPEN, names, [math.pi, *home[1:]], "/joint_states")
    state = measured(NEXTAGE_OPEN, ["extra", *names], [1e9, *home], "/joint_states")  # other joints on the topic: not ours
    assert state.names == names and state.positions == tuple(home)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=15, max_size=15), st.permutations(range(15)))
def test_any_joint_state_is_taken_within_the_limits_or_refused(values: list[float], order: list[int]) -> None:
    names = [NEXTAGE_OPEN.joint_names[k] for k in order]
    try:
        state = measured(NEXTAGE_OPEN, names, values, "peer")
    except UntrustedState as error:
        assert str(error).startswith("peer gives ") and "\n" not in str(error)
        return
    limits = {j.name: j for g in NEXTAGE_OPEN.groups for j in g.joints}
    assert state.names == NEXTAGE_OPEN.joint_names
    assert all(limits[n].lower <= v <= limits[n].upper for n, v in zip(state.names, state.positions))
