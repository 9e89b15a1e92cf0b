"""``validate --simulate`` and the check before ``run``: every problem at its line, before anything moves.

The dry runs run the real engine, machines and skills against each robot's simulator on
simulated time (the KUKA one against the accelerated RSI simulator, which keeps its own time).
"""
from __future__ import annotations

import io
import re
import shutil
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from app_functions.registry import full_catalog
from cell_runner.cli import main
from cell_runner.deployment import deploy_local
from cell_runner.dry_run import dry_run
from cell_runner.dry_run.report import DryRunReport, Finding
import cell_runner.dry_run.runner as runner
from core_functions.primitives import TrajectoryResult
from core_functions.robots import NEXTAGE_OPEN
from core_functions.trajectory_store import TrajectoryStore
from execution_engine.app_model import load_application
from execution_engine.app_model.diagnostics import MAX_DIAGNOSTICS
from execution_engine.engine.report import RunReport
from node_transport.clock import Clock
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
APPS = ROOT / "apps_xml"
RIVET_CELL = APPS / "cells" / "rivet_cell.xml"
KUKA_CELL = APPS / "cells" / "kuka_rsi_cell.xml"
Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]

FAR = '<param value="1.2,0.3,0.2,180deg,0,0"/>'  # 1.2 m ahead: no arm gets there
WRIST = '<param value="0.33,-0.18,0.05,180deg,0,0"/>'  # reachable only with the wrist roll beyond 163 deg


def cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(args), out, err)
    return code, out.getvalue(), err.getvalue()


def write_app(folder: Path, robot: str, cell: Path, operations: list[dict[str, str]]) -> tuple[Path, dict[tuple[str, str], str]]:
    """An application, one line per group call, and where each call's ``<function`` is: FILE:LINE:COL."""
    path = folder / "app.xml"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f'<application name="checked" robot="{robot}" cell="{cell}">']
    where: dict[tuple[str, str], str] = {}
    for number, calls in enumerate(operations, start=1):
        lines.append(f'  <operation id="{number}">')
        for group, function in calls.items():
            text = f"    <{group}>{function}</{group}>"
            where[(str(number), group)] = f"{path}:{len(lines) + 1}:{text.index('<function') + 1}"
            lines.append(text)
        lines.append("  </operation>")
    lines.append("</application>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path, where


def call(name: str, *params: str) -> str:
    inner = f"<params>{''.join(params)}</params>" if params else ""
    return f'<function name="{name}">{inner}</function>'


def param(value: str) -> str:
    return f'<param value="{value}"/>'


def findings(err: str) -> list[str]:
    """The dry run's diagnostics: FILE:LINE:COL: operation ... lines."""
    return [line for line in err.splitlines() if re.match(r".+:\d+:\d+: operation ", line)]


# ------------------------------------------------------------------ the rivet demonstrator, broken
@pytest.fixture
def rivet_with_hole_4_out_of_reach(tmp_path: Path) -> tuple[Path, str, str]:
    """The shipped demonstrator with drill_4 moved 0.5 m to the left: operation 8 of 10, over a minute in."""
    (tmp_path / "cells").mkdir()
    cell = (tmp_path / "cells" / "rivet_cell.xml")
    cell.write_text(RIVET_CELL.read_text().replace('name="drill_4" xyz="0.0 -0.06 0.0"', 'name="drill_4" xyz="0.0 0.5 0.0"'))
    app = tmp_path / "rivet.xml"
    text = (APPS / "rivet_installation.xml").read_text()
    app.write_text(text)
    lines = text.splitlines()
    op8 = next(i for i, line in enumerate(lines) if "<operation id='8'" in line)
    op9 = next(i for i, line in enumerate(lines) if "<operation id='9'" in line)
    debur = next(i for i in range(op8, op9) if "debur_drilling" in lines[i])
    insert = next(i for i in range(op9, len(lines)) if "insert_rivet" in lines[i])
    at = lambda i: f"{app}:{i + 1}:{lines[i].index('<function') + 1}"  # noqa: E731
    return app, at(debur), at(insert)


def test_validate_simulate_reports_the_unreachable_hole_at_its_line_and_run_refuses_it(
    rivet_with_hole_4_out_of_reach: tuple[Path, str, str], tmp_path: Path
) -> None:
    app, debur, insert = rivet_with_hole_4_out_of_reach
    db = str(tmp_path / "t.sqlite")
    code, out, err = cli("validate", "--simulate", str(app), "--trajectory-db", db)
    assert code == 1, out + err
    assert f"{app}: valid" in out  # the schema and semantic checks pass: only the robot finds it
    found = findings(err)
    assert any(line.startswith(f"{debur}: operation 8 left_arm debur_drilling: unreachable: ") for line in found), err
    assert any(line.startswith(f"{insert}: operation 9 right_arm insert_rivet: unreachable: ") for line in found), err
    assert all(" drill_4 " in line or "drill_4" in line for line in found), err
    code, out, err = cli("run", str(app), "--speed", "max", "-q", "--trajectory-db", db)
    assert code == 1
    assert f"{app}: not run: {len(found)} problem(s) found by the dry run; use --no-check to run anyway" in err
    assert "application rivet_installation" not in out  # nothing was started


def test_run_with_no_check_starts_and_meets_the_problem_on_the_robot(rivet_with_hole_4_out_of_reach: tuple[Path, str, str], tmp_path: Path) -> None:
    app, _, _ = rivet_with_hole_4_out_of_reach
    code, out, err = cli("run", str(app), "--speed", "max", "-q", "--no-check", "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1
    assert "application rivet_installation: FAILED" in out and "operations: 7/10" in out
    assert "dry run" not in out + err


# --------------------------------------------------------------------------- each kind of problem
def test_every_problem_of_an_application_is_found_in_one_pass(tmp_path: Path) -> None:
    path, where = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("move_to", FAR), "right_arm": call("record_trajectory", param("sweep"), param("rivet_1 rivet_2"))},
        {"right_arm": call("move_to", WRIST)},
        {"left_arm": call("execute_trajectory", param("ghost")), "right_arm": call("execute_trajectory", param("sweep"))},
        {"right_arm": call("pick", FAR)},
    ])
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1
    found = findings(err)
    assert len(found) == 4, err
    assert found[0].startswith(f"{where[('1', 'left_arm')]}: operation 1 left_arm move_to: unreachable: ")
    assert found[1].startswith(f"{where[('2', 'right_arm')]}: operation 2 right_arm move_to: joint_limit: ")
    assert "RARM_JOINT5" in found[1] and "outside its limits" in found[1]
    assert found[2].startswith(f"{where[('3', 'left_arm')]}: operation 3 left_arm execute_trajectory: missing_trajectory: ")
    assert "'ghost' is replayed but was never recorded for left_arm" in found[2]
    assert not any("'sweep'" in line for line in found)  # recorded in operation 1, replayed in 3: fine
    assert found[3].startswith(f"{where[('4', 'right_arm')]}: operation 4 right_arm pick: unreachable: ")
    assert "(3 times in this call, first at " in found[3]  # approach, grasp and retreat: one finding, counted
    assert f"{path}: 4 problem(s) found by the dry run" in err
    assert "operations checked 4/4" in out


def test_a_function_that_fails_is_a_finding_and_the_dry_run_goes_on(tmp_path: Path) -> None:
    cell = tmp_path / "cell.xml"  # 6 mm rivets for 4.8 mm holes: insert_rivet refuses them
    cell.write_text(RIVET_CELL.read_text().replace('kind="rivet" diameter="0.0048"', 'kind="rivet" diameter="0.006"'))
    path, where = write_app(tmp_path, "nextage", cell, [
        {"right_arm": call("pick_rivet", param("rivet_1"), param("ref_R10"))},
        {"right_arm": call("insert_rivet", param("drill_1")), "left_arm": call("debur_drilling", param("drill_2"))},
        {"left_arm": call("move_to", FAR)},
    ])
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", str(tmp_path / "t.sqlite"))
    found = findings(err)
    assert code == 1 and len(found) == 2, err
    assert found[0].startswith(f"{where[('2', 'right_arm')]}: operation 2 right_arm insert_rivet: ")
    assert "rivet ref_R10 (6.00 mm) does not fit drill_1 (4.80 mm)" in found[0]
    assert found[1].startswith(f"{where[('3', 'left_arm')]}: operation 3 left_arm move_to: unreachable: "), err
    busy = re.search(r"left_arm +busy +([\d.]+) s", out)
    assert busy and float(busy.group(1)) > 5.0 and "not checked" not in out  # its deburring, stopped by the failure, was run again


def test_a_long_primitive_stopped_beside_a_failed_function_is_checked_again_and_frees_its_group(tmp_path: Path) -> None:
    cell = tmp_path / "cell.xml"
    cell.write_text(RIVET_CELL.read_text().replace('kind="rivet" diameter="0.0048"', 'kind="rivet" diameter="0.006"'))
    path, where = write_app(tmp_path, "nextage", cell, [
        {"right_arm": call("pick_rivet", param("rivet_1"), param("ref_R10"))},
        {"right_arm": call("insert_rivet", param("drill_1")), "torso_head": call("teach_trajectory", param("nod"), param("300"))},
        {"torso_head": call("move_to_joint_pose", param("initial"))},
    ])
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", str(tmp_path / "t.sqlite"))
    found = findings(err)
    assert code == 1 and len(found) == 1, err  # the torso's 300 s of teaching was stopped with the failure, not left holding it
    assert found[0].startswith(f"{where[('2', 'right_arm')]}: operation 2 right_arm insert_rivet: ")
    busy = re.search(r"torso_head +busy +([\d.]+) s", out)
    assert busy and float(busy.group(1)) >= 300.0


def kuka_app(tmp_path: Path) -> tuple[Path, dict[tuple[str, str], str]]:
    return write_app(tmp_path, "kuka", KUKA_CELL, [
        {"arm": call("move_joints", param("0 -80 85 0 35 0 deg"))},
        {"arm": call("gripper_close")},
        {"arm": call("end_effector", param("hand_release"))},
        {"arm": call("move_to_joint_pose", param("home"))},
    ])


def test_a_gripper_action_the_rsi_configuration_has_no_output_for_is_found(tmp_path: Path) -> None:
    """config/kuka_rsi_ethernet.xml has the tool outputs Tool.o1..o3 (gripper, air, spindle); without
    them, as in the seed's Fig. 2 configuration, closing the gripper cannot work."""
    config = tmp_path / "rsi_without_tools.xml"
    config.write_text("\n".join(line for line in (ROOT / "config" / "kuka_rsi_ethernet.xml").read_text().splitlines() if "Tool.o" not in line))
    path, where = kuka_app(tmp_path)
    db = str(tmp_path / "t.sqlite")
    code, out, err = cli("validate", "--simulate", str(path), "--backend-option", f"config={config}", "--trajectory-db", db)
    assert code == 1
    found = findings(err)
    assert found[0].startswith(f"{where[('2', 'arm')]}: operation 2 arm gripper_close: unsupported: end_effector(gripper_close): ")
    assert f"no tool output for gripper_close in {config}" in found[0]
    assert found[1].startswith(f"{where[('3', 'arm')]}: operation 3 arm end_effector: unsupported: ") and len(found) == 2
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", db)  # the shipped configuration
    found = findings(err)
    assert code == 1 and len(found) == 1 and "no tool output for hand_release" in found[0], err  # no air hand on a KUKA
    assert "(robot cycles)" in out


def test_a_controller_that_stops_for_good_ends_the_check_with_what_was_not_checked(tmp_path: Path) -> None:
    """An RSI correction monitor of 5 degrees stops the simulated KR C4 in the first move; RSI stays
    stopped, so the rest of the application cannot be checked -- and the report says so."""
    app = APPS / "kuka_rsi_demo.xml"
    code, out, err = cli("validate", "--simulate", str(app), "--backend-option", "axis_monitor=5", "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1
    found = findings(err)
    assert len(found) == 1 and re.match(rf"{re.escape(str(app))}:\d+:\d+: operation 1 arm move_joints: controller: .*AXISCORRMON", found[0]), err
    assert "operations checked 1/8" in out
    assert "not checked: the simulated controller stopped for good in operation 1; nothing after it was checked" in out


def test_a_real_controller_is_dry_run_on_its_simulator_never_contacted(tmp_path: Path) -> None:
    path, where = write_app(tmp_path, "viper", APPS / "cells" / "vplus_cell.xml", [{"arm": call("move_to", param("2.0,0,0.3,3.14159,0,0"))}])
    code, out, err = cli("run", str(path), "--robot", "vplus", "--host", "127.0.0.1", "--port", "9", "-q")
    assert code == 1  # not EXIT_USAGE: no connection to port 9 was tried
    assert findings(err)[0].startswith(f"{where[('1', 'arm')]}: operation 1 arm move_to: unreachable: "), err


# --------------------------------------------------------------------- what the dry run leaves
def test_the_trajectory_database_is_read_never_written(tmp_path: Path) -> None:
    db = tmp_path / "t.sqlite"
    store = TrajectoryStore(db)
    arm = NEXTAGE_OPEN.group("right_arm")
    store.save("right_arm", "taught", TrajectoryResult(arm.joint_names, (NEXTAGE_OPEN.group_pose("initial", "right_arm"),), (0.0,)), "teach", 0.0)
    store.close()
    before = db.read_bytes()
    path, _ = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"right_arm": call("execute_trajectory", param("taught"))},
        {"right_arm": call("record_trajectory", param("sweep"), param("rivet_1 rivet_2"))},
    ])
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", str(db))
    assert code == 0, err  # taught by an earlier run: there
    assert db.read_bytes() == before
    missing = tmp_path / "none.sqlite"
    cli("validate", "--simulate", str(path), "--trajectory-db", str(missing))
    assert not missing.exists()


def test_a_dry_run_that_breaks_down_is_one_clear_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path, _ = write_app(tmp_path, "nextage", RIVET_CELL, [{"right_arm": call("gripper_open")}])
    code, out, err = cli("validate", "--simulate", str(path), "--backend-option", "bogus=1")
    assert code == 2 and "error: cannot dry-run" in err and "unknown option(s) bogus" in err

    async def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("boom")

    monkeypatch.setattr(runner, "deploy_local", broken)
    code, out, err = cli("validate", "--simulate", str(path), "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1 and "Traceback" not in err
    assert f"error: the dry run of {path} failed (a defect, please report it): RuntimeError: boom" in err
    code, out, err = cli("run", str(path), "--speed", "max", "-q", "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1 and "not run: the dry run did not pass; use --no-check to run anyway" in err


# ------------------------------------------------------------------------------- the prediction
def test_the_predicted_cycle_time_is_the_real_runs_total(run_sim: Run, tmp_path: Path) -> None:
    app = load_application(APPS / "rivet_installation.xml", full_catalog())
    options = BackendOptions(robot=app.robot)
    report = dry_run(app, "nextage-sim", options, str(tmp_path / "t.sqlite"))

    async def real(clock: Clock) -> RunReport:
        backend = await create_backend("nextage-sim", clock, options)
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": str(tmp_path / "run.sqlite")})
        try:
            return await deployment.engine.run(app)
        finally:
            await deployment.close()

    run: RunReport = run_sim(real)
    assert run.ok and report.ok and report.time_base == "simulated clock"
    assert report.cycle_time == pytest.approx(run.total, abs=1e-6)
    for group, time in report.groups.items():
        spans = sorted((s for s in report.timeline if group in s.groups), key=lambda s: s.start)
        assert all(a.end <= b.start + 1e-9 for a, b in zip(spans, spans[1:]))  # one primitive at a time
        assert time.busy == pytest.approx(sum(s.duration for s in spans)) and time.busy + time.idle == pytest.approx(report.cycle_time)
    assert report.groups["right_arm"].busy == pytest.approx(run.group_busy["right_arm"], rel=0.02)


def test_run_prints_the_prediction_before_it_starts(tmp_path: Path) -> None:
    shutil.copy(APPS / "examples" / "bin_transfer.xml", tmp_path / "bin_transfer.xml")
    shutil.copytree(APPS / "examples" / "cells", tmp_path / "cells")
    code, out, err = cli("run", str(tmp_path / "bin_transfer.xml"), "--speed", "max", "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 0, err
    predicted = re.search(r"predicted cycle time +([\d.]+) s", out)
    total = re.search(r"total +([\d.]+) s", out)
    assert predicted and total and predicted.group(1) == total.group(1)
    assert out.index("dry run of bin_transfer") < out.index("application bin_transfer: FINISHED")


def test_the_documented_dry_run_is_real(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/application_xml.md section 5: the example of section 1 with hole_a moved out of the right arm's reach."""
    blocks = re.findall(r"```(\w+)\n(.*?)```", (ROOT / "docs" / "application_xml.md").read_text(), re.S)
    example = lambda start: next(b for lang, b in blocks if lang == "xml" and b.lstrip().startswith("<?xml") and start in b)  # noqa: E731
    shown = next(b for lang, b in blocks if lang == "text" and "found by the dry run" in b and "predicted" in b).splitlines()
    (tmp_path / "apps_xml" / "cells").mkdir(parents=True)
    (tmp_path / "apps_xml" / "cells" / "example_cell.xml").write_text(example("<cell ").replace('name="hole_a" xyz="0 40 0"', 'name="hole_a" xyz="0 400 0"'))
    (tmp_path / "apps_xml" / "example.xml").write_text(example("<application "))
    monkeypatch.chdir(tmp_path)
    code, out, err = cli("validate", "--simulate", "apps_xml/example.xml", "--trajectory-db", "t.sqlite")
    assert code == 1
    assert out.splitlines()[:2] == shown[:2]
    kind_of = lambda line: line.split(": ", 3)[:3]  # noqa: E731 - FILE:LINE:COL, operation and function, kind
    assert [kind_of(line) for line in findings(err)] == [kind_of(line) for line in shown if re.match(r".+:\d+:\d+: operation ", line)]
    code, out, err = cli("run", "apps_xml/example.xml", "-q", "--trajectory-db", "t.sqlite")
    refused = next(b for lang, b in blocks if lang == "text" and "not run:" in b).strip()
    assert code == 1 and refused in err



# ------------------------------------------------------------------ every problem, both modes
def test_flags_mode_reports_every_failure_not_only_the_first(tmp_path: Path) -> None:
    """sync="flags": two wait_flag calls that time out, one in each arm; both are reported at their
    lines (the application is run again without the first), and the rest is checked to its end."""
    path, where = write_app(tmp_path, "nextage", RIVET_CELL, [
        {"left_arm": call("wait_flag", param("a"), param("1")), "right_arm": call("wait", param("3"))},
        {"left_arm": call("wait", param("6")), "right_arm": call("set_flag", param("a"))},
        {"left_arm": call("set_flag", param("b")), "right_arm": call("wait_flag", param("b"), param("1"))},
        {"left_arm": call("approach", param("drill_1"))},
    ])
    path.write_text(path.read_text(encoding="utf-8").replace('robot="nextage"', 'robot="nextage" sync="flags"', 1), encoding="utf-8")
    code, out, err = cli("validate", "--simulate", str(path))
    assert code == 1
    found = findings(err)
    assert any(f.startswith(f"{where[('1', 'left_arm')]}: operation 1 left_arm wait_flag: timeout: flag 'a'") for f in found), err
    assert any(f.startswith(f"{where[('3', 'right_arm')]}: operation 3 right_arm wait_flag: timeout: flag 'b'") for f in found), err
    assert "operations checked 4/4" in out and "not checked" not in out + err
    assert "collisions checked: 1 motions" in out  # the last run's motion was swept


def test_the_dry_run_report_stops_after_its_limit_with_how_many_more() -> None:
    found = tuple(Finding("collision", "left_arm", str(k), "approach", "", "collision between a and b", "app.xml", k + 1, 5, 1.0) for k in range(MAX_DIAGNOSTICS + 37))
    report = DryRunReport("a", "app.xml", "nextage-sim", "simulated clock", found, (), 1.0, {}, len(found), len(found))
    lines = [str(d) for d in report.diagnostics()]
    assert len(lines) == MAX_DIAGNOSTICS + 1
    assert "and 37 more problems" in lines[-1] and lines[0].startswith("app.xml:1:5: operation 0 left_arm approach: collision: ")
