"""``run`` refuses every back-end option before anything runs: before the dry run, before the run.

A value the back end refuses (``control_period=1e308``) was refused only once the dry run had
taken its seconds, or by the run after it.  Each row of docs/faults.md that refuses an option of
``--backend-option`` (or the back end's own check of its options against the run, like a speed the
controller cannot follow) is run here with the dry run and the run made to fail loudly if they
start: the same line and exit code as the row says, from the check that comes first.
"""
from __future__ import annotations

import io
import shlex
from pathlib import Path
from typing import Any

import pytest
from test_cli_faults import ROWS, Row, pattern

from cell_runner import cli, run_command
from cell_runner.dry_run import check
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import check_options

ROOT = Path(__file__).resolve().parents[1]
#: The rows refusing an option the back end reads (all of them in-process, none with a peer or a {tmp} file).
OPTION_ROWS = [
    row for row in ROWS
    if row.exit_code == 2 and "{" not in row.command and ("--backend-option" in row.command or "--fault" in row.command)
]


def test_the_rows_cover_every_back_end() -> None:
    commands = " ".join(row.command for row in OPTION_ROWS)
    assert len(OPTION_ROWS) >= 15
    assert all(app in commands for app in ("rivet_installation.xml", "kuka_rsi_demo.xml", "vplus_pick_inspect.xml"))


@pytest.mark.parametrize("row", OPTION_ROWS, ids=[row.id for row in OPTION_ROWS])
def test_a_refused_back_end_option_is_refused_before_the_dry_run(row: Row, monkeypatch: pytest.MonkeyPatch) -> None:
    def never(*_args: Any, **_kwargs: Any) -> Any:
        raise AssertionError("started although an option was bad")

    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(check, "dry_run", never)
    monkeypatch.setattr(run_command, "run_with_clock", never)
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(shlex.split(row.command)[3:], out, err)
    assert code == row.exit_code, err.getvalue()
    assert pattern(row.message, {}).search(err.getvalue()), err.getvalue()


def test_the_back_ends_check_what_they_build_from() -> None:
    """check_options is each back end's own parse: what it refuses, the factory would refuse in the same words."""
    cases = [
        ("nextage-sim", BackendOptions(robot=NEXTAGE_OPEN, extra={"initial_pose": "sideways"}), 1.0,
         "nextage-sim: initial_pose: unknown Nextage pose 'sideways' (known: initial, off)"),
        ("vplus", BackendOptions(robot=ADEPT_VIPER_S850, extra={"tolerance_mm": "60"}), 1.0,
         "vplus: tolerance_mm must be a number in [0.01, 50] mm, got 60"),
        ("kuka-rsi", BackendOptions(robot=KUKA_KR, extra={"tolerance_mm": "60"}), 1.0, None),  # within KUKA RSI's own range
        ("kuka-rsi", BackendOptions(robot=KUKA_KR, extra={"tolerance_mm": "200"}), 1.0,
         "kuka-rsi: tolerance_mm must be a number in [0.001, 100] mm, got '200'"),
        ("kuka-rsi", BackendOptions(robot=KUKA_KR), float("inf"),
         "the kuka-rsi back end runs on the robot's real-time clock: run with --speed 1 (the default)"),
        ("vplus", BackendOptions(robot=ADEPT_VIPER_S850, host="192.0.2.1", port=0), 1.0,
         "vplus: port 0 names no AdeptServer: give the port the controller at 192.0.2.1 listens on"),
    ]
    for backend, options, speed, message in cases:
        if message is None:
            check_options(backend, options, speed)
            continue
        with pytest.raises(ValueError) as refused:
            check_options(backend, options, speed)
        assert str(refused.value) == message
