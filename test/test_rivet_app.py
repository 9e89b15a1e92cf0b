"""The demonstrator end to end on the Nextage simulator, through the CLI, read back from its trace.

What the paper promises (section 3.1, Figure 12) and the issue asks to show: left-arm deburring and
right-arm picking of one operation overlap in time; the left arm does nothing while the right arm
inserts; the run reaches Finish; faults end in a clear report; pause/resume reaches the same target.
"""
from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path
from typing import Any

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main
from cell_runner.deployment import deploy_local
from core_functions.geometry import Pose
from core_functions.primitives import MoveCartesian
from execution_engine.app_model import load_application
from node_transport import typed
from node_transport.clock import Clock
from node_transport.msgs import Trigger
from node_transport.wire import BridgeCommand, BridgeFeedback, bridge_topic
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
TRACE_EVENTS = {"transition", "function_start", "function_end", "primitive_start", "primitive_end", "error", "engine_state", "operator", "flag", "plan"}


def run_cli(tmp_path: Path, *extra: str) -> tuple[int, str, list[dict[str, Any]]]:
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(RIVET), "--speed", "max", "--trace", str(trace), "--trajectory-db", str(tmp_path / "t.sqlite"), *extra], out, err)
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    return code, out.getvalue() + err.getvalue(), events


def functions(events: list[dict[str, Any]], group: str) -> list[tuple[str, str, float, float, str]]:
    """(operation, function, t_start, t_end, outcome) of every function of ``group``."""
    starts: dict[str, dict[str, Any]] = {}
    out = []
    for e in events:
        if e["group"] != group:
            continue
        if e["event"] == "function_start":
            starts[e["request_id"]] = e
        elif e["event"] == "function_end":
            s = starts.pop(e["request_id"])
            out.append((e["operation"], e["function"], s["t"], e["t"], e["outcome"]))
    return out


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, str, list[dict[str, Any]]]:
    return run_cli(tmp_path_factory.mktemp("rivet"))


def test_the_demonstrator_reaches_finish(clean_run: tuple[int, str, list[dict[str, Any]]]) -> None:
    code, output, events = clean_run
    assert code == 0, output
    assert "application rivet_installation: FINISHED" in output and "operations: 10/10" in output
    finishes = {e["group"] for e in events if e["event"] == "transition" and e["to"] == "Finish"}
    assert finishes == {"left_arm", "right_arm", "torso_head"}
    assert not [e for e in events if e["event"] == "error"]


def test_the_trace_has_the_documented_fields(clean_run: tuple[int, str, list[dict[str, Any]]]) -> None:
    _, _, events = clean_run
    *events, end = events  # the run's end closes the trace: outcome, exit code, counts
    assert end == {
        "t": end["t"], "event": "run_end", "group": "engine", "outcome": "finished", "exit_code": 0,
        "operations_done": 10, "operations_total": 10, "records": len(events) + 1,
    } and end["t"] >= events[-1]["t"]
    assert {e["event"] for e in events} <= TRACE_EVENTS
    for e in events:
        assert {"t", "event", "group", "operation"} <= set(e) and isinstance(e["t"], float)
        if e["event"] == "transition":
            assert e["from"] and e["to"] and e["signal"]
        if e["event"] in ("function_start", "function_end", "primitive_start", "primitive_end"):
            assert e["function"] and e["operation"]
        if e["event"] == "plan":  # the plan the run was checked against (execution_engine/run_plan.py)
            assert [o for o, _ in e["operations"]] == [str(k) for k in range(1, 11)] and e["cycle_time"] > 0 and e["functions"]
    assert [e["event"] for e in events].count("plan") == 1
    times = [e["t"] for e in events]
    assert times == sorted(times)


def test_deburring_and_picking_of_one_operation_overlap(clean_run: tuple[int, str, list[dict[str, Any]]]) -> None:
    _, _, events = clean_run
    left = {op: (t0, t1) for op, f, t0, t1, _ in functions(events, "left_arm") if f == "debur_drilling"}
    right = {op: (t0, t1) for op, f, t0, t1, _ in functions(events, "right_arm") if f == "pick_rivet"}
    assert len(left) == 4 and set(left) == set(right)
    for op in left:
        (l0, l1), (r0, r1) = left[op], right[op]
        overlap = min(l1, r1) - max(l0, r0)
        assert overlap > 0.5 * min(l1 - l0, r1 - r0), (op, left[op], right[op])


def test_the_left_arm_does_nothing_while_the_right_arm_inserts(clean_run: tuple[int, str, list[dict[str, Any]]]) -> None:
    _, _, events = clean_run
    inserts = [(op, t0, t1) for op, f, t0, t1, _ in functions(events, "right_arm") if f == "insert_rivet"]
    assert len(inserts) == 4
    for op, t0, t1 in inserts:
        left_activity = [e for e in events if e["group"] == "left_arm" and (e["operation"] == op or t0 < e["t"] < t1)]
        assert left_activity == [], (op, left_activity[:3])
        # and the insertion starts only after the deburring of the same hole has ended
        hole = next(e for e in events if e["group"] == "right_arm" and e["operation"] == op and e["event"] == "primitive_start")
        assert hole["t"] == pytest.approx(t0)


def test_operations_follow_each_other_only_when_every_group_is_done(clean_run: tuple[int, str, list[dict[str, Any]]]) -> None:
    _, _, events = clean_run
    spans: dict[str, list[float]] = {}
    for group in ("left_arm", "right_arm", "torso_head"):
        for op, _f, t0, t1, outcome in functions(events, group):
            assert outcome == "succeeded"
            spans.setdefault(op, []).extend([t0, t1])
    ordered = sorted(spans, key=int)
    for a, b in zip(ordered, ordered[1:]):
        assert min(spans[b]) >= max(spans[a]) - 1e-9


def test_an_injected_fault_recovers_by_retry(tmp_path: Path) -> None:
    code, output, events = run_cli(tmp_path, "--fault", "right_arm:timeout@0.5")
    assert code == 0, output
    assert "retries: 1" in output and "retrying (attempt 2 of 2): timeout is transient" in output
    right = [(e["from"], e["to"]) for e in events if e["group"] == "right_arm" and e["event"] == "transition"]
    assert ("Motion", "ErrorHandling") in right and ("ErrorHandling", "Ready") in right
    left = [(e["from"], e["to"]) for e in events if e["group"] == "left_arm" and e["event"] == "transition"]
    assert ("Motion", "Pause") in left and ("Pause", "Motion") in left  # paused while the error was handled


@pytest.mark.parametrize("kind", ["joint_limit", "unreachable"])
def test_a_deterministic_fault_ends_the_run_without_a_retry_with_a_report_and_the_safe_pose(tmp_path: Path, kind: str) -> None:
    code, output, events = run_cli(tmp_path, "--fault", f"right_arm:{kind}@0.5")
    assert code == 1
    assert "application rivet_installation: FAILED" in output
    assert "right_arm: pick_rivet failed" in output and kind in output
    assert f"not retried: {kind} is deterministic" in output and "retries:" not in output  # the policy allows 1
    assert "robot at safe pose 'initial'" in output
    assert "right_arm    retreat  done: 0.05 m back along the tool axis" in output
    errors = [e for e in events if e["event"] == "error"]
    assert errors and errors[0]["group"] == "right_arm"
    left = [(e["from"], e["to"]) for e in events if e["group"] == "left_arm" and e["event"] == "transition"]
    assert ("Motion", "Pause") in left or ("Vision", "Pause") in left
    finishes = {e["group"] for e in events if e["event"] == "transition" and e["to"] == "Finish"}
    assert finishes == {"left_arm", "right_arm", "torso_head"}  # no hang: every machine ended


def test_vision_brings_the_rivet_to_the_true_hole_within_the_process_tolerance(run_sim: Any) -> None:
    """Holes are up to 0.6 mm off their CAD position; the paper needs 0.2 mm (section 3.1)."""

    async def main_(clock: Clock) -> tuple[list[MoveCartesian], Any, Any]:
        app = load_application(RIVET, full_catalog())
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
        moves: list[MoveCartesian] = []

        def record(msg: Any) -> None:
            command = typed.from_msg(BridgeCommand, msg, clock)
            if isinstance(command.primitive, MoveCartesian):
                moves.append(command.primitive)

        deployment.transport.create_node("spy").create_subscription(typed.BridgeCommandMsg, bridge_topic("right_arm", "command"), record)
        try:
            report = await deployment.engine.run(app)
        finally:
            await deployment.close()
        return moves, report, app.cell

    moves, report, cell = run_sim(main_)
    assert report.ok
    grip = 0.004
    for i in range(1, 5):
        hole = f"drill_{i}"
        inserted = next(m for m in moves if m.frame == f"{hole} inserted")
        truth = cell.true_pose(hole).offset_local(dz=-grip)
        nominal = cell.pose(hole).offset_local(dz=-grip)
        assert inserted.target.distance_to(truth) < 0.0002, hole
        assert nominal.distance_to(truth) > 0.0002  # without vision it would miss


def test_pause_then_resume_mid_motion_reaches_the_same_target(run_sim: Any) -> None:
    async def main_(clock: Clock) -> tuple[Any, MoveCartesian, Any, Pose, Pose]:
        app = load_application(RIVET, full_catalog())
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"})
        spy = deployment.transport.create_node("spy")
        commands: dict[str, BridgeCommand] = {}
        done: dict[str, BridgeFeedback] = {}

        def on_command(msg: Any) -> None:
            command = typed.from_msg(BridgeCommand, msg, clock)
            commands[command.id] = command

        def on_feedback(msg: Any) -> None:
            feedback = typed.from_msg(BridgeFeedback, msg, clock)
            if feedback.status == "done":
                done[feedback.id] = feedback

        spy.create_subscription(typed.BridgeCommandMsg, bridge_topic("left_arm", "command"), on_command)
        spy.create_subscription(typed.BridgeFeedbackMsg, bridge_topic("left_arm", "feedback"), on_feedback)
        pause = spy.create_client(Trigger, "/execution_engine/pause")
        resume = spy.create_client(Trigger, "/execution_engine/resume")
        task = asyncio.ensure_future(deployment.engine.run(app))
        while deployment.machines["left_arm"].state != "Motion" or clock.now() < 2.0:
            await clock.sleep(0.01)
        await clock.sleep(0.3)  # mid-motion
        running = [c for c in commands.values() if c.op == "execute" and c.id not in done][-1]
        assert (await pause.call(Trigger.Request())).success
        await clock.sleep(0.5)
        held = backend.tcp_pose("left_arm")
        await clock.sleep(10.0)
        still = backend.tcp_pose("left_arm")
        assert (await resume.call(Trigger.Request())).success
        report = await task
        await deployment.close()
        return report, running.primitive, done[running.id].result, held, still

    report, paused_move, result, held, still = run_sim(main_)
    assert report.ok
    assert isinstance(paused_move, MoveCartesian)
    assert held.distance_to(still) < 1e-9  # held still while paused
    assert held.distance_to(paused_move.target) > 0.005  # it was really stopped part-way
    assert result.tcp.distance_to(paused_move.target) < 1e-4 and result.tcp.angle_to(paused_move.target) < 1e-3
