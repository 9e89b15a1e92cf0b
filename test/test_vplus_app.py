"""The seed's focus approach as an app function, and the pick-and-inspect application end to end on the V+ simulator."""
from __future__ import annotations

import io
import json
import math
import os
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from app_functions.focus_approach import FocusApproach, FocusNotFound
from cell_runner.cli import main as cli_main
from core_functions.functions import Skill, SkillContext
from core_functions.geometry import Pose
from core_functions.primitives import MoveCartesian, MoveRelative, SetSpeed, Vision
from core_functions.robots import ADEPT_VIPER_S850
from core_functions.trajectory_store import TrajectoryStore
from execution_engine.app_model.cell import load_cell
from node_transport.clock import Clock
from robot_bridges.vplus.backend import VPlusBackend
from robot_bridges.vplus.measurement import SimulatedFocusCamera
from robot_bridges.vplus.simulator import VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
APPS = Path(__file__).resolve().parents[1] / "apps_xml"


def functions(clock: Clock) -> FocusApproach:
    cell = load_cell(APPS / "cells" / "vplus_cell.xml").bind(ADEPT_VIPER_S850).to_snapshot().index()
    return FocusApproach(SkillContext("arm", ADEPT_VIPER_S850, cell, TrajectoryStore(":memory:"), clock.now))


async def drive(skill: Skill, backend: VPlusBackend, log: list[Any]) -> None:
    """What the group machine does with a skill: each primitive to the back end, its result back in."""
    try:
        primitive = next(skill)
        while True:
            log.append(primitive)
            result = await backend.execute("arm", primitive)
            primitive = skill.send(result)
    except StopIteration:
        pass


async def at_focus_distance(clock: Clock, distance: float, camera: SimulatedFocusCamera) -> tuple[VPlusSimulator, VPlusBackend, FocusApproach]:
    sim = await VPlusSimulator(clock).start()
    backend = VPlusBackend(clock, "127.0.0.1", sim.port, measurement=camera)
    await backend.start()
    library = functions(clock)
    plane = library.cell.pose("focus_plane")
    await backend.execute("arm", MoveCartesian(plane.offset_local(dz=distance)))
    return sim, backend, library


@pytest.mark.parametrize("start_mm", [-12.0, -7.0, -1.0])
def test_focus_approach_stops_one_step_past_the_peak_and_steps_back(run_sim: Run, start_mm: float) -> None:
    async def main(clock: Clock) -> None:
        camera = SimulatedFocusCamera(noise=0.0)
        sim, backend, library = await at_focus_distance(clock, start_mm / 1000, camera)
        log: list[Any] = []
        await drive(library.focus_approach("focus_plane", step=0.002, speed=0.25), backend, log)
        plane = library.cell.pose("focus_plane")
        tcp = backend.tcp_pose("arm")
        assert tcp is not None
        final_mm = camera.distance(plane, tcp) * 1000
        assert abs(final_mm) <= 1.0 + 1e-3  # within half a step of the plane
        # the seed's loop: measure, and while rising, step; one step past the peak, then one back
        measures = [p for p in log if isinstance(p, Vision)]
        steps = [p for p in log if isinstance(p, MoveRelative)]
        assert len(steps) == len(measures)  # (n - 1) increments forward, one back
        assert steps[-1].delta.z == pytest.approx(-0.002) and all(s.delta.z == pytest.approx(0.002) for s in steps[:-1])
        assert all(s.reference == "tool" for s in steps)
        values = [library.ctx.measurements[f"focus_plane.sharpness.{i}"] for i in range(len(measures))]
        assert values[-1] < values[-2] and all(a <= b for a, b in zip(values[:-1], values[1:-1]))
        assert library.ctx.measurements["focus_plane.sharpness"] == values[-2]
        assert isinstance(log[0], SetSpeed) and log[0].fraction == 0.25 and isinstance(log[-1], SetSpeed)
        await backend.close()
        await sim.close()

    run_sim(main)


def test_focus_approach_gives_up_after_max_steps(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        sim, backend, library = await at_focus_distance(clock, -0.030, SimulatedFocusCamera(noise=0.0))
        with pytest.raises(FocusNotFound, match="still rising after 3 steps of 2 mm"):
            await drive(library.focus_approach("focus_plane", step=0.002, max_steps=3), backend, [])
        await backend.close()
        await sim.close()

    run_sim(main)


def test_inspection_turns_the_tool_and_comes_back(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        sim, backend, library = await at_focus_distance(clock, 0.0, SimulatedFocusCamera(noise=0.0))
        before = backend.tcp_pose("arm")
        log: list[Any] = []
        await drive(library.inspect_rotating("focus_plane", turns=4, angle=math.pi / 2), backend, log)
        turns = [p for p in log if isinstance(p, MoveRelative)]
        assert len(turns) == 4 and sum(t.delta.rpy()[2] for t in turns[:3]) == pytest.approx(3 * math.pi / 2)
        after = backend.tcp_pose("arm")
        assert before is not None and after is not None
        assert after.distance_to(before) < 2e-6 and after.angle_to(before) < 1e-4
        assert [library.ctx.measurements[f"focus_plane.inspect.{i}"] for i in range(4)] == pytest.approx([100.0] * 4, rel=1e-3)
        await backend.close()
        await sim.close()

    run_sim(main)


def test_the_pick_and_inspect_application_runs_end_to_end_on_the_simulator(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = cli_main(["run", str(APPS / "vplus_pick_inspect.xml"), "--robot", "vplus", "--speed", "max", "--trace", str(trace), "-q"], out, err)
    assert code == 0, err.getvalue() + out.getvalue()
    assert "FINISHED" in out.getvalue() and "14/14" in out.getvalue()
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    states = {e.get("state") for e in events}
    assert {"Motion", "Vision", "EndEffector"} <= states and "ErrorHandling" not in states


def test_an_error_on_the_robot_side_puts_the_group_machine_in_error_handling(tmp_path: Path) -> None:
    app = tmp_path / "unreachable.xml"
    app.write_text(
        '<application name="unreachable" robot="viper">\n'
        '  <error_policy retries="0" action="abort"/>\n'
        '  <operation id="1"><arm><function name="move_to"><params><param value="2.0,0,0.3,3.14159,0,0"/></params></function></arm></operation>\n'
        "</application>\n"
    )
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = cli_main(["run", str(app), "--robot", "vplus", "--speed", "max", "--trace", str(trace), "-q", "--no-check"], out, err)
    assert code == 1
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    assert "ErrorHandling" in {e.get("state") for e in events}
    assert "unreachable" in out.getvalue() + trace.read_text()


def test_the_default_camera_pose_of_the_cell_is_reachable_for_the_whole_approach() -> None:
    """Every pose the application asks for has a joint solution (checked on the published kinematics)."""
    library = functions(Clock())
    kin = VPlusBackend(Clock(), "127.0.0.1", 1).kin
    plane = library.cell.pose("focus_plane")
    seed = kin.home
    for name in ("part_slot", "camera_approach"):
        seed = kin.inverse(library.cell.pose(name).matrix(), seed)
    for mm in range(-14, 4, 2):
        seed = kin.inverse(plane.offset_local(dz=mm / 1000).matrix(), seed)
    assert kin.within_limits(seed)
    assert isinstance(plane, Pose)


def test_run_against_a_standalone_simulator_with_host_and_port(tmp_path: Path) -> None:
    """--host/--port reach a controller in another process: here the simulator program, both at 50x."""
    app = tmp_path / "moves.xml"
    app.write_text(
        '<application name="moves" robot="viper">\n'
        '  <operation id="1"><arm><function name="move_to_joint_pose"><params><param value="home"/></params></function></arm></operation>\n'
        '  <operation id="2"><arm><function name="gripper_close"/></arm></operation>\n'
        '  <operation id="3"><arm><function name="move_relative"><params><param value="0"/><param value="0"/><param value="-30 mm"/></params></function></arm></operation>\n'
        '  <operation id="4"><arm><function name="move_to"><params><param value="0.4,-0.1,0.5,3.14159,0,0"/></params></function></arm></operation>\n'
        "</application>\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "robot_bridges.vplus.simulator", "--port", "0", "--speed", "50"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert proc.stdout is not None
        port = re.search(r":(\d+) ", proc.stdout.readline()).group(1)  # type: ignore[union-attr]
        out, err = io.StringIO(), io.StringIO()
        code = cli_main(["run", str(app), "--robot", "vplus", "--host", "127.0.0.1", "--port", port, "--speed", "50", "--backend-option", "controller_speed=50", "-q"], out, err)
        assert code == 0, err.getvalue() + out.getvalue()
        assert "FINISHED" in out.getvalue() and "4/4" in out.getvalue()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
