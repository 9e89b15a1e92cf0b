"""A fault of a robot a cell renames speaks the cell's names (issue 23 item 4): the side_by_side cell names a KUKA's
``arm`` ``kuka_arm`` (joints ``kuka_A1``..) and a Viper's ``arm`` ``inspector`` (joints ``viper_joint_1``..); the
operator reading a fault, in the console, the run's error or the trace, finds those names, never the model's own
``arm`` or ``joint_3``, which the application does not know.

Renaming is by whole words (robot_bridges/placed.py ``PlacedBackend.cell_text``): a name inside a longer word
(``arm_controller``, an already renamed ``viper_joint_3``) stays as it is.
"""
from __future__ import annotations

import functools
import io
import json
import math
import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, strategies as st

from cell_runner.cli import main
from core_functions.cell_robots import CellNames
from core_functions.geometry import Pose
from core_functions.primitives import MoveJoints
from core_functions.robots import ADEPT_VIPER_S850
from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.placed import PlacedBackend
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "apps_xml" / "examples" / "cells" / "side_by_side_cell.xml"
VIPER_NAMES = CellNames("viper_", (("arm", "inspector"),))
OWN_JOINTS = ADEPT_VIPER_S850.joint_names


def _app(tmp_path: Path, body: str) -> Path:
    app = tmp_path / "fault.xml"
    app.write_text(f'<?xml version="1.0"?>\n<application name="fault" robot="cell" cell="{CELL}" sync="flags">\n'
                   f'  <error_policy retries="0" action="abort"/>\n{body}</application>\n', encoding="utf-8")
    return app


def _call(group: str, function: str, *values: str) -> str:
    params = "".join(f'<param value="{v}"/>' for v in values)
    return f'<{group}><function name="{function}"><params>{params}</params></function></{group}>'


CASES = {
    # the Viper stretched out, then sent to a point only its elbow beyond its limit reaches: its V+ back end names joint_3
    "inspector": ('<operation id="1" name="out">' + _call("inspector", "move_joints", "0 0 0 0 0 0 deg") + "</operation>\n"
                  '<operation id="2" name="too low">' + _call("inspector", "move_to", "1.5 0 0.2 3.14159 0 0", "linear") + "</operation>\n",
                  "joint_limit", ("viper_joint_3",), ("joint_3",)),
    # the KUKA sent 2.5 m away: its RSI back end says the target is out of reach of its arm
    "kuka_arm": ('<operation id="1" name="far">' + _call("kuka_arm", "move_to", "2.5 0 0.2 3.14159 0 0", "linear") + "</operation>\n",
                 "unreachable", ("kuka_arm",), ("arm",)),
}


@pytest.mark.parametrize("group", sorted(CASES))
def test_a_fault_of_a_renamed_robot_reaches_the_run_s_error_and_trace_under_the_cell_s_names(tmp_path: Path, group: str) -> None:
    body, kind, cell_words, own_words = CASES[group]
    trace = tmp_path / "trace.jsonl"
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(_app(tmp_path, body)), "--no-check", "-q", "--trace", str(trace),
                 "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)
    text = out.getvalue() + err.getvalue()
    assert code != 0 and "application fault: FAILED" in text, text
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines() if line.strip()]
    errors = [r["error"] for r in records if r.get("event") == "error" and r.get("group") == group]
    assert errors, records
    summary = next(line for line in text.splitlines() if line.strip().startswith(f"error: {group} operation"))
    for message in (errors[0], summary):
        assert f"{kind}: " in message, message
        words = set(re.findall(r"\w+", message))
        assert set(cell_words) <= words, message  # the cell's names, as whole words
        assert not words & set(own_words), message  # and none of the model's own


def _viper(clock: Clock) -> Any:
    return create_backend("vplus", clock, BackendOptions(robot=ADEPT_VIPER_S850))


def test_a_back_end_s_fault_is_raised_again_with_its_kind_and_the_cell_s_names(run_sim: Any) -> None:
    """Straight from the back end: the Viper's own limit check names joint_1; out of the placed back end the same
    fault (kind, cause kept) names viper_joint_1; a fault already in the cell's names passes as it was raised."""

    async def body(clock: Clock) -> tuple[BridgeError, BridgeError]:
        inner = await _viper(clock)
        placed = PlacedBackend(inner, Pose.from_xyz_rpy(1.5, 0.0, 0.0, 0.0, 0.0, math.pi), "checker", VIPER_NAMES)
        await placed.start()
        try:
            target = (math.radians(200.0), 0.0, 0.0, 0.0, 0.0, 0.0)
            with pytest.raises(BridgeError) as own:
                await inner.execute("arm", MoveJoints(target, joint_names=OWN_JOINTS))
            with pytest.raises(BridgeError) as cell:
                await placed.execute("inspector", MoveJoints(target, joint_names=tuple(f"viper_{j}" for j in OWN_JOINTS)))
            return own.value, cell.value
        finally:
            await placed.close()

    own, cell = run_sim(body)
    assert own.kind is cell.kind is FaultKind.JOINT_LIMIT
    assert "joint_1" in re.findall(r"\w+", own.detail), own.detail
    assert cell.detail == re.sub(r"\bjoint_1\b", "viper_joint_1", own.detail)
    assert isinstance(cell.__cause__, BridgeError) and cell.__cause__.detail == own.detail
    assert "viper_joint_1" in re.findall(r"\w+", cell.detail) and "joint_1" not in re.findall(r"\w+", cell.detail)
    assert str(cell) == f"joint_limit: {cell.detail}"


def _closed(clock: Clock, names: CellNames) -> Any:
    """A placed Viper whose renaming table is built (its first message renamed), its simulator closed again."""

    async def body() -> PlacedBackend:
        placed = PlacedBackend(await _viper(clock), Pose(), "checker", names)
        placed.cell_text("arm")
        await placed.close()
        return placed
    return body()


def test_renaming_takes_whole_words_and_never_twice(run_sim: Any) -> None:
    async def body(clock: Clock) -> tuple[PlacedBackend, PlacedBackend]:
        return await _closed(clock, VIPER_NAMES), await _closed(clock, CellNames())

    placed, solo = run_sim(body)
    texts = ["arm: joint_2 at 50 deg is outside [-190, 45]", "the arm_controller drives joint_20 and viper_joint_2",
             "joint_1, joint_6; arm.", "Arm and ARM and arms stay", ""]
    assert [placed.cell_text(t) for t in texts] == [
        "inspector: viper_joint_2 at 50 deg is outside [-190, 45]", "the arm_controller drives joint_20 and viper_joint_2",
        "viper_joint_1, viper_joint_6; inspector.", "Arm and ARM and arms stay", ""]
    assert solo.cell_text(texts[0]) == texts[0]  # a robot the cell does not rename: as it was


@functools.cache
def _placed_viper() -> PlacedBackend:
    return run_with_clock(lambda clock: _closed(clock, VIPER_NAMES), simulated_clock())


@given(st.lists(st.sampled_from(["arm", "joint_1", "joint_6", "viper_joint_1", "inspector", "arm_x", "x", " ", ":", ".", "_"]), max_size=12))
def test_a_renamed_message_never_holds_a_model_name_as_a_word_nor_loses_a_cell_name(tokens: list[str]) -> None:
    text = "".join(tokens)
    words = re.findall(r"\w+", _placed_viper().cell_text(text))
    assert not {"arm", "joint_1", "joint_6"} & set(words)
    before = re.findall(r"\w+", text)
    assert words.count("viper_joint_1") == before.count("viper_joint_1") + before.count("joint_1")
    assert words.count("inspector") == before.count("inspector") + before.count("arm")
