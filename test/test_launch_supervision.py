"""One process per node: the launcher's cell, its supervision, and the engine noticing a lost machine."""
from __future__ import annotations

import asyncio
import io
import sys
from pathlib import Path
from collections.abc import Callable
from typing import Any

import pytest
from app_builder import Cell, make_app

from cell_runner.cli import main
from cell_runner.launcher import EXIT_NODE_DIED, NodeSpec, cell_nodes, launch, select
from execution_engine.engine.group_link import WATCH_PERIOD
from execution_engine.machine.bridge_watch import WATCH_PERIOD as BRIDGE_WATCH_PERIOD
from execution_engine.machine.zone_gate import ZoneGate
from node_transport.clock import Clock, real_clock, run_with_clock

ROOT = Path(__file__).resolve().parent.parent
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"


def test_the_cell_of_an_application_is_the_launch_files_cell() -> None:
    specs = cell_nodes(RIVET, "dds", 2.0)
    assert [s.name for s in specs] == ["nextage_sim_bridge", "left_arm_machine", "right_arm_machine", "torso_head_machine", "execution_engine"]
    bridge, left, *_, engine = specs
    assert "--transport" in bridge.argv and bridge.argv[bridge.argv.index("--transport") + 1] == "dds"
    assert bridge.argv[-2:] == ("-p", "speed:=2.0")
    assert str(ROOT / "config" / "nextage_sim.yaml") in bridge.argv
    assert ("-r", "__node:=left_arm_machine") == left.argv[left.argv.index("-r"):left.argv.index("-r") + 2]
    assert "group:=left_arm" in left.argv and "robot:=nextage_open" in left.argv
    assert f"application:={RIVET.resolve()}" in engine.argv and "exit_when_done:=true" in engine.argv
    assert [s.name for s in select(specs, "nextage_sim_bridge")] == ["nextage_sim_bridge"]
    with pytest.raises(ValueError, match="unknown node.*bridge.*this cell has"):
        select(specs, "bridge")


def _node(name: str, code: str) -> NodeSpec:
    return NodeSpec(name, (sys.executable, "-c", code))


SERVE = "import signal, sys, time; signal.signal(signal.SIGTERM, lambda *a: (print('stopping', flush=True), sys.exit(0))); print('up', flush=True); time.sleep(60)"


def _launch(specs: list[NodeSpec]) -> tuple[int, str]:
    out = io.StringIO()

    async def main(clock: Clock) -> int:
        return await launch(clock, specs, out, grace=0.5, stop_timeout=5.0)

    return run_with_clock(main, real_clock()), out.getvalue()


def test_a_node_that_dies_is_named_the_others_stop_and_the_exit_code_says_so() -> None:
    code, text = _launch([
        _node("robot_bridge", SERVE),
        _node("left_arm_machine", "import os, signal; print('up', flush=True); os.kill(os.getpid(), signal.SIGKILL)"),
        _node("execution_engine", SERVE),
    ])
    assert code == EXIT_NODE_DIED
    assert "[launch] left_arm_machine died (killed by SIGKILL" in text
    assert "[launch] execution_engine stopped" in text and "[launch] robot_bridge stopped" in text
    assert text.index("[launch] execution_engine stopped") < text.index("[launch] robot_bridge stopped")  # engine first, bridge last


def test_the_launch_ends_with_the_engine_and_its_exit_code() -> None:
    code, text = _launch([_node("robot_bridge", SERVE), _node("execution_engine", "print('application x: FAILED'); raise SystemExit(1)")])
    assert code == 1
    assert "[execution_engine] application x: FAILED" in text and "[launch] execution_engine ended (exit code 1)" in text
    assert "[launch] robot_bridge stopped" in text


def _lose_mid_motion(run_sim: Any, leaving: Callable[[Cell], Any]) -> tuple[Any, float, Cell]:
    """Both arms start a 10 s motion; at 2 s the node ``leaving(cell)`` leaves the graph (as when its
    process dies).  The run's report, the moment of the loss, the cell."""
    async def main(clock: Clock) -> tuple[Any, float, Cell]:
        cell = await Cell(clock, durations={"move_joints": 10.0}).start()
        lost_at: list[float] = []

        async def kill() -> None:
            await clock.sleep(2.0)
            leaving(cell).destroy()
            lost_at.append(clock.now())

        killer = asyncio.get_running_loop().create_task(kill())
        ops = [{"left_arm": ("move_to_joint_pose", "initial"), "right_arm": ("move_to_joint_pose", "initial")}]
        report = await cell.run(make_app(ops))
        await killer
        return report, lost_at[0], cell

    return run_sim(main)  # type: ignore[no-any-return]


def test_a_lost_machine_ends_the_run_naming_its_node_within_the_watch_period(run_sim: Any) -> None:
    """The machine's node leaves mid-function (its process died): the engine does not wait for the
    function timeout, stops the other groups and ends the run naming the node."""
    report, lost_at, cell = _lose_mid_motion(run_sim, lambda cell: cell.deployment.machines["left_arm"].node)
    assert report.outcome == "failed"
    assert "left_arm_machine" in report.message and "lost" in report.message
    error = report.errors[0]
    assert error.group == "left_arm" and error.t - lost_at <= WATCH_PERIOD + 1e-6
    right = cell.backend.executed("right_arm")
    assert right and right[0].outcome == "stopped" and right[0].t_end is not None and right[0].t_end < 10.0  # stopped, not left to finish


def test_a_lost_bridge_ends_the_working_groups_in_error_handling_naming_its_node(run_sim: Any) -> None:
    """The bridge's node leaves mid-motion (its process killed): each machine waiting on it does not
    wait out the primitive timeout but fails within the watch period with a CONNECTION fault that
    names the bridge's node, lands in ErrorHandling, and the run fails."""
    report, lost_at, cell = _lose_mid_motion(run_sim, lambda cell: cell.deployment.bridge.node)
    assert report.outcome == "failed"
    error = report.errors[0]
    assert error.fault == "connection" and error.t - lost_at <= BRIDGE_WATCH_PERIOD + 1e-6
    assert "bridge /scripted_bridge lost" in error.error and "/bridge/feedback" in error.error
    for group in ("left_arm", "right_arm"):
        ends = [e for e in cell.events if e["group"] == group and e["event"] == "function_end"]
        assert ends and ends[0]["state"] == "ErrorHandling" and ends[0]["t"] - lost_at <= BRIDGE_WATCH_PERIOD + 1e-6


def test_a_motion_waiting_for_a_zone_ends_when_the_bridge_is_lost(run_sim: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """A function whose next motion waits for an interference zone (here never granted) while the
    bridge's node leaves: nothing could ever move it, so it ends at once with the bridge named
    instead of waiting for the zone for ever."""
    monkeypatch.setattr(ZoneGate, "admits", lambda gate, _primitive: gate.ctx.group != "left_arm")

    async def main(clock: Clock) -> tuple[Any, float]:
        cell = await Cell(clock).start()
        lost_at: list[float] = []

        async def kill() -> None:
            await clock.sleep(2.0)
            cell.deployment.bridge.node.destroy()
            lost_at.append(clock.now())

        killer = asyncio.get_running_loop().create_task(kill())
        report = await cell.run(make_app([{"left_arm": ("move_to_joint_pose", "initial")}]))
        await killer
        return report, lost_at[0]

    report, lost_at = run_sim(main)
    error = report.errors[0]
    assert report.outcome == "failed" and error.group == "left_arm" and error.fault == "connection"
    assert "bridge /scripted_bridge lost" in error.error and error.t - lost_at <= BRIDGE_WATCH_PERIOD + 1e-6


def test_launch_is_a_subcommand_with_one_line_errors(tmp_path: Path) -> None:
    out, err = io.StringIO(), io.StringIO()
    assert main(["launch", str(tmp_path / "missing.xml")], out, err) == 1
    assert err.getvalue() == f"error: {tmp_path / 'missing.xml'}: no such file\n"
    err = io.StringIO()
    assert main(["launch", str(RIVET), "--nodes", "nobody"], out, err) == 2
    assert err.getvalue().startswith("error: --nodes: unknown node(s) nobody; this cell has nextage_sim_bridge, ")
