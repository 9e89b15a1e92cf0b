"""A cell of two robots on two back ends (issue 23 item 4): apps_xml/examples/mixed_cell.xml, a KUKA KR 6 over RSI
(its simulated KR C4 on the wall clock) feeding a part to the Nextage's right arm (its kinematic simulator).

The run goes through the same checks as any other: the dry run of the whole cell (every robot's base placed in the
cell's world frame, one collision model of both robots), then the run, one bridge per robot.  The placement's
arithmetic is checked apart, without robots: what a back end does in its base frame is what the application
asked in the cell's world frame.
"""
from __future__ import annotations

import io
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from dds_domain import stop_group
from hypothesis import given, strategies as st

from cell_runner.cli import main
from core_functions.cell_robots import CellRobot
from core_functions.geometry import Pose
from core_functions.primitives import MoveCartesian, MoveRelative
from execution_engine.app_model.document import parse_document
from operator_station.builder import cell_names
from core_functions.robots import KUKA_KR
from robot_bridges.backend import BackendOptions
from robot_bridges.cell_backend import member_options
from robot_bridges.placed import PlacedBackend

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "apps_xml" / "examples" / "mixed_cell.xml"
CELL = ROOT / "apps_xml" / "examples" / "cells" / "mixed_cell.xml"


def _records(trace: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines() if line.strip()]


def _without(tmp_path: Path, *operations: str) -> Path:
    """The example, its cell beside it, without ``operations`` (their ids): a shorter run on the same two robots."""
    cells = tmp_path / "cells"
    cells.mkdir(exist_ok=True)
    (cells / "mixed_cell.xml").write_text(CELL.read_text(encoding="utf-8"), encoding="utf-8")
    text = EXAMPLE.read_text(encoding="utf-8")
    for operation in operations:
        start = text.index(f'  <operation id="{operation}" ')
        text = text[:start] + text[text.index("</operation>", start) + len("</operation>\n"):]
    app = tmp_path / "mixed_cell.xml"
    app.write_text(text, encoding="utf-8")
    return app


def _when(records: list[dict[str, object]], event: str, group: str, operation: str) -> float:
    return next(float(r["t"]) for r in records if r.get("event") == event and r.get("group") == group and r.get("operation") == operation)  # type: ignore[arg-type]


def test_the_mixed_cell_runs_to_finished_and_its_flag_orders_the_hand_over_across_the_robots(tmp_path: Path) -> None:
    """Checked first (the dry run of both robots), then run: FINISHED; the Nextage's right arm takes the part from the
    buffer only after the KUKA has left it there and set part_ready, though each group goes at its own pace."""
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(EXAMPLE), "-q", "--trace", str(trace), "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 0, out.getvalue() + err.getvalue()
    assert "application mixed_cell: FINISHED" in out.getvalue()
    records = _records(trace)

    def flag(group: str, name: str, state: str) -> float:
        return next(float(r["t"]) for r in records if r.get("event") == "flag" and r.get("group") == group  # type: ignore[arg-type]
                    and r.get("flag") == name and r.get("state") == state)

    placed = _when(records, "function_end", "arm", "4")  # the KUKA's place on the buffer
    assert placed <= flag("arm", "part_ready", "set") <= flag("right_arm", "part_ready", "passed") <= _when(records, "function_start", "right_arm", "7")
    assert flag("right_arm", "part_ready", "waiting") < placed  # the right arm was there first, waiting for the other robot
    assert flag("arm", "handover", "left") <= flag("right_arm", "handover", "passed")  # one hand at a time above the buffer


def test_a_collision_between_the_kuka_and_a_nextage_arm_is_found_by_the_dry_run_before_anything_moves(tmp_path: Path) -> None:
    """Without its move out of the way, the Nextage's right hand stays where the KUKA reaches in to leave the part: the
    dry run of the whole cell finds the KUKA's forearm on the Nextage's hand, and the run is refused, nothing started.
    The application ends with that leaving (operation 4): the cell's dry run goes on the wall clock (the KUKA's), and
    what follows would only make it longer."""
    app = _without(tmp_path, "2", "5", "6", "7", "8", "9")
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(app), "-q", "--trace", str(trace), "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    assert code == 1, out.getvalue() + err.getvalue()
    lines = err.getvalue().splitlines()
    assert any("collision between right_arm hand (assembler/RARM_JOINT5_Link) and arm feeder/link_" in line for line in lines), err.getvalue()
    # the verdict's line; the simulated KR C4's log (late replies on a loaded machine) may come after it
    assert any(line.startswith(f"{app}: not run: ") and line.endswith("problem(s) found by the dry run; use --no-check to run anyway") for line in lines), err.getvalue()
    assert not trace.exists() or not any(r.get("event") == "function_start" for r in _records(trace))


def test_launch_starts_one_bridge_node_per_robot_and_the_mixed_cell_runs_to_finished_over_dds(tmp_path: Path, dds_env: dict[str, str]) -> None:
    """launch: a bridge process per robot (feeder_bridge on RSI, assembler_bridge on the Nextage simulator, each with
    its base pose from the cell), a machine per group, the engine checking the whole cell first: FINISHED.  The example
    without its two places (operations 4 and 8): each robot still makes a Cartesian pick in the cell's frame (what its
    bridge turns into its base frame) and the flag still crosses from one robot's machine to the other's, in two thirds
    of the real time (the whole example runs in the test above)."""
    app = _without(tmp_path, "4", "8")
    env = {**os.environ, **dds_env, "XDG_DATA_HOME": str(tmp_path / "data")}
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "launch", str(app), "--transport", "dds"],
        cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True,
    )
    try:
        out, _ = process.communicate(timeout=240)
    finally:
        stop_group(process)
    assert process.returncode == 0, out
    assert "[execution_engine] application mixed_cell: FINISHED" in out
    for node in ("feeder_bridge", "assembler_bridge", "arm_machine", "right_arm_machine"):
        assert f"[launch] {node} stopped (exit code 0)" in out, out


class _Recorder(PlacedBackend):
    """Only the placement's conversions; no back end behind them."""

    def __init__(self, base: Pose) -> None:  # noqa: D107 - PlacedBackend's state without an inner back end
        self.base, self.to_base = base, base.inverse()


_coordinate = st.floats(-2.0, 2.0)
_angle = st.floats(-math.pi, math.pi)
_poses = st.builds(Pose.from_xyz_rpy, _coordinate, _coordinate, _coordinate, _angle, _angle, _angle)


def _close(a: Pose, b: Pose) -> bool:
    return a.distance_to(b) < 1e-9 and a.angle_to(b) < 1e-7


@given(base=_poses, target=_poses)
def test_a_cartesian_target_reaches_the_robot_in_its_own_base_frame_and_comes_back_in_the_cells(base: Pose, target: Pose) -> None:
    placed = _Recorder(base)
    inward = placed.inward(MoveCartesian(target))
    assert isinstance(inward, MoveCartesian)
    assert _close(base.compose(inward.target), target)
    assert _close(placed.tcp_out(inward.target), target)


@given(base=_poses, start=_poses, delta=_poses)
def test_a_relative_move_in_the_cells_axes_ends_where_it_would_in_the_robots(base: Pose, start: Pose, delta: Pose) -> None:
    """A world-axes move_relative, turned into the robot's base axes, ends at the same place of the cell."""
    placed = _Recorder(base)
    world = MoveRelative(delta, reference="world")
    inward = placed.inward(world)
    assert isinstance(inward, MoveRelative)
    in_base = inward.goal(base.inverse().compose(start))
    assert _close(base.compose(in_base), world.goal(start))


def test_a_cell_robot_s_connection_options_are_its_back_end_s_address_and_the_rest_its_extras() -> None:
    """<option name="rsi_listen"/"host"/"port"> reach a KUKA of the cell as --rsi-listen, --host and --port reach a
    KUKA of its own; a port that is not a number is refused naming the robot."""
    feeder = CellRobot("feeder", KUKA_KR, Pose(), "kuka-rsi", (("rsi_listen", "0.0.0.0:49152"), ("host", "192.168.1.20"), ("port", "49153"), ("cycle", "12")))
    options = member_options(BackendOptions(robot=KUKA_KR, seed=7), feeder)
    assert (options.rsi_listen, options.host, options.port, options.extra, options.seed) == ("0.0.0.0:49152", "192.168.1.20", 49153, {"cycle": "12"}, 7)
    with pytest.raises(ValueError, match=r"^robot 'feeder': option port must be a whole number, got 'x'$"):
        member_options(BackendOptions(robot=KUKA_KR), CellRobot("feeder", KUKA_KR, Pose(), "kuka-rsi", (("port", "x"),)))


def test_the_studio_offers_the_groups_poses_and_cameras_of_every_robot_of_the_cell() -> None:
    """The operator station's builder: an application on robot="cell" is given its cell's robots' groups to fill."""
    document, problems = parse_document(EXAMPLE.read_bytes(), EXAMPLE)
    assert document is not None and not problems
    offered = cell_names(document, EXAMPLE)
    assert offered["groups"] == ["arm", "left_arm", "right_arm", "torso_head"] and offered["problem"] is None
    assert {"home", "initial"} <= set(offered["robot_poses"]) and "left_hand_camera" in offered["cameras"]
