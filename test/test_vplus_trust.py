"""The V+ back end believes a controller's pose only where it is where the arm was sent.

A controller that acknowledges every move but reports another pose (here: the simulator's
``Faults.report_location``, or ``sim_frozen_pose=1``) is a ``controller`` fault naming the peer,
the commanded and the reported pose and the tolerance; it is not trusted again, and a run on it
ends FAILED with the machine in ErrorHandling.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from cell_runner.cli import main as cli_main
from core_functions.primitives import EndEffector, MoveCartesian, MoveJoints
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.vplus.backend import VPlusBackend
from robot_bridges.vplus.kinematics import HOME_DEG, location_to_pose
from robot_bridges.vplus.simulator import VPlusSimulator
from robot_bridges.vplus.trust import PoseTolerance

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
READY = tuple(math.radians(v) for v in (0.0, -60.0, 150.0, 0.0, 60.0, 0.0))
APPS = Path(__file__).resolve().parents[1] / "apps_xml"


@contextlib.asynccontextmanager
async def rig(clock: Clock, tolerance: PoseTolerance | None = None) -> AsyncIterator[tuple[VPlusSimulator, VPlusBackend]]:
    async with VPlusSimulator(clock) as sim:
        backend = VPlusBackend(clock, "127.0.0.1", sim.port, ack_timeout=2.0, tolerance=tolerance)
        await backend.start()
        try:
            yield sim, backend
        finally:
            await backend.close()


def test_a_controller_that_acks_every_move_but_reports_home_is_a_controller_fault_and_is_not_trusted_again(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[BridgeError, BridgeError, int, int]:
        async with rig(clock) as (sim, backend):
            sim.faults.report_location = sim.arm.location()  # home, whatever the arm does from now on
            with pytest.raises(BridgeError) as first:
                await backend.execute("arm", MoveJoints(READY))
            sent = len(sim.received)
            with pytest.raises(BridgeError) as later:
                await backend.execute("arm", MoveJoints(tuple(math.radians(v) for v in HOME_DEG)))
            return first.value, later.value, sent, len(sim.received)

    first, later, sent, sent_after = run_sim(main)
    assert first.kind is FaultKind.CONTROLLER
    message = str(first)
    assert message.startswith("controller: vplus 127.0.0.1:") and "\n" not in message
    assert "move_joints: commanded 702.500,0.000,671.817,0.000,150.000,0.000 (mm, deg)" in message  # READY
    assert "the controller reports 480.000,0.000,710.000,0.000,180.000,0.000 (mm, deg)" in message  # home
    assert "tolerance 1 mm, 0.5 deg): the controller did not move where it was told" in message
    assert later.kind is FaultKind.CONTROLLER and "nothing more is sent to it" in str(later)
    assert sent_after == sent  # nothing was sent to a controller no longer believed


def test_a_report_within_the_tolerance_is_taken_and_one_beyond_it_is_not(run_sim: Run) -> None:
    """0.3 mm off: within the default 1 mm; the same report with tolerance_mm=0.1 is a fault."""

    async def main(clock: Clock, tolerance: PoseTolerance | None) -> Any:
        async with rig(clock, tolerance) as (sim, backend):
            target = location_to_pose((450.0, 100.0, 400.0, 0.0, 180.0, 0.0))
            await backend.execute("arm", MoveCartesian(target))
            sim.faults.report_location = (450.3, 100.0, 400.0, 0.0, 180.0, 0.0)  # from now on, 0.3 mm off
            try:
                return await backend.execute("arm", MoveCartesian(target))
            except BridgeError as error:
                return error

    taken = run_sim(lambda clock: main(clock, None))
    refused = run_sim(lambda clock: main(clock, PoseTolerance(mm=0.1)))
    assert taken.tcp is not None and taken.tcp.x == pytest.approx(0.4503, abs=1e-6)
    assert isinstance(refused, BridgeError) and refused.kind is FaultKind.CONTROLLER
    assert "(0.300 mm and 0.000 deg apart; tolerance 0.1 mm, 0.5 deg)" in str(refused)


def test_a_hand_action_reporting_the_arm_elsewhere_is_a_controller_fault(run_sim: Run) -> None:
    async def main(clock: Clock) -> BridgeError:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", MoveJoints(READY))
            sim.faults.report_location = sim.arm.location()[:2] + (sim.arm.location()[2] + 25.0,) + sim.arm.location()[3:]
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", EndEffector("gripper_close"))
            return caught.value

    error = run_sim(main)
    assert error.kind is FaultKind.CONTROLLER and "end_effector(gripper_close): commanded " in str(error)
    assert "(25.000 mm and 0.000 deg apart" in str(error)


def test_a_run_on_a_lying_controller_fails_with_the_machine_in_error_handling(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    argv = ["run", str(APPS / "vplus_pick_inspect.xml"), "--robot", "vplus", "--speed", "max", "--no-check", "-q",
            "--backend-option", "sim_frozen_pose=1", "--trace", str(trace)]
    code = cli_main(argv, out, err)
    text = out.getvalue() + err.getvalue()
    assert code == 1, text
    assert "FAILED" in text and "FINISHED" not in text
    assert "the controller did not move where it was told" in text
    assert "not retried: controller must be cleared on the controller by an operator" in text
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    assert any(e.get("event") == "transition" and e.get("to") == "ErrorHandling" for e in events)
    assert any(e.get("event") == "error" and e.get("state") == "ErrorHandling" and "controller: vplus" in e.get("error", "") for e in events)
