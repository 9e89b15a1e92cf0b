"""The kept dry-run verdict wherever a run is checked: the station's Start and an engine node's goals, keyed as ``run``'s.

What an integrator relies on: pressing Start again on an unchanged application, or sending the same goal again,
does not dry-run it again and says so; an application changed anywhere -- an edit on the page not yet saved, a
goal carrying other XML under the same name, a file it includes -- is checked again, because the key holds the
application as it was read, not only the file on the disk.
"""
from __future__ import annotations

import shutil
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

import cell_runner.dry_run.cell_start as cell_start_module
from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from cell_runner.dry_run.cell_start import CellStarts
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.verdict_cache import cache_dir, verdict_key
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import read_application
from execution_engine.engine.run_action import RunApplicationGoal, RunApplicationServer
from node_transport.clock import Clock
from rclpy_like import RclpyLikeActionClient
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
KEPT = "dry run: unchanged since the check of "
SETUP = setup_for("nextage-sim", BackendOptions(robot=NEXTAGE_OPEN))


def moving(pose: str) -> str:
    return (f'<?xml version="1.0"?>\n<application name="kept" robot="nextage" version="1">\n'
            f'  <operation id="1" name="move"><left_arm><function name="move_to_joint_pose"><params><param name="pose" value="{pose}"/>'
            '</params></function></left_arm></operation>\n</application>\n')


def counting(monkeypatch: pytest.MonkeyPatch, module: ModuleType, name: str) -> list[str]:
    """The names of the applications ``module.name`` (a dry run) is called with from now on."""
    calls: list[str] = []
    real = getattr(module, name)

    def counted(app: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(app.name)
        return real(app, *args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def entries() -> list[Path]:
    folder = cache_dir()
    return sorted(folder.glob("*.verdict.json")) if folder.is_dir() else []


# ------------------------------------------------------------------------------------ the key
def test_the_key_holds_the_application_as_read_not_only_its_file(tmp_path: Path) -> None:
    """A goal's XML (or a page's document) under one name, the file there holding something else or nothing."""
    where = tmp_path / "goal.xml"
    catalog = full_catalog()
    first, _ = read_application(where, catalog, data=moving("initial").encode())
    other, _ = read_application(where, catalog, data=moving("off").encode())
    assert first is not None and other is not None
    assert verdict_key(first, SETUP, None) == verdict_key(read_application(where, catalog, data=moving("initial").encode())[0], SETUP, None)
    assert verdict_key(first, SETUP, None) != verdict_key(other, SETUP, None)
    where.write_text(moving("off"))  # the file says one thing, the goal another: the goal's is what runs
    assert verdict_key(first, SETUP, None) != verdict_key(other, SETUP, None)


def test_a_change_in_an_included_file_changes_the_key(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copytree(ROOT / "apps_xml" / "blocks", tmp_path / "blocks")
    shutil.copyfile(ROOT / "apps_xml" / "rivet_blocks.xml", tmp_path / "rivet_blocks.xml")
    catalog = full_catalog()

    def key() -> str:
        app, problems = read_application(tmp_path / "rivet_blocks.xml", catalog)
        assert app is not None, problems
        return verdict_key(app, SETUP, None)

    before = key()
    block = tmp_path / "blocks" / "rivet_block.xml"
    block.write_text(block.read_text().replace('name="insert {hole}"', 'name="insert a rivet in {hole}"'))
    assert key() != before  # the calling application's bytes are the same; what it runs is not


# ----------------------------------------------------------------------------------- the station
pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

import operator_station.session as session_module  # noqa: E402
from test_studio_server import cell_dir, rivet, run_to_end  # noqa: E402, F401 - cell_dir is a fixture


def test_the_station_dry_runs_an_unchanged_application_once_and_an_edited_one_again(cell_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = counting(monkeypatch, session_module, "dry_run")
    station, client, document = rivet(cell_dir)
    run_to_end(station, client, "rivet_installation.xml", document)
    assert calls == ["rivet_installation"] and len(entries()) == 1
    assert station.session is not None and station.session.report is not None and station.session.report.ok
    said = [m["message"] for m in station.feed.snapshot.messages]
    assert not any(m.startswith(KEPT) for m in said), said

    run_to_end(station, client, "rivet_installation.xml", document)  # Start again: the kept verdict
    said = [m["message"] for m in station.feed.snapshot.messages]
    assert calls == ["rivet_installation"], "dry-run again though nothing changed"
    assert any(m.startswith(KEPT) and "cached verdict: passed" in m for m in said), said
    assert station.session.report is not None and station.session.report.ok and station.session.report.operations_done == 10

    document["operations"][0]["calls"][0]["params"][0]["value"] = "0.7"  # an edit on the page, not saved
    run_to_end(station, client, "rivet_installation.xml", document)
    assert calls == ["rivet_installation"] * 2, "an edited application must be checked again"
    assert len(entries()) == 2


# --------------------------------------------------------------------------------- an engine node
def test_an_engine_node_dry_runs_a_goal_once_and_says_so_the_next_time(run_sim: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = counting(monkeypatch, cell_start_module, "dry_run_setup")

    async def main(clock: Clock) -> list[Any]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:"})
        engine = deployment.engine
        RunApplicationServer(engine.node, engine, CellStarts(engine.node, engine, ":memory:", engine.startup_timeout).run_goal)
        client = RclpyLikeActionClient(deployment.transport.create_node("ros2_action_send_goal"))
        answers = []
        try:
            for number, xml in enumerate((moving("initial"), moving("initial"), moving("off")), start=1):
                handle = await client.send_goal(RunApplicationGoal(application_xml=xml), number)
                assert handle is not None
                answers.append(await client.result(handle))
        finally:
            await deployment.close()
        return answers

    first, again, other = run_sim(main)
    assert all(a.result.ok for a in (first, again, other)), [a.result.report for a in (first, again, other)]
    assert KEPT not in first.result.report
    assert KEPT in again.result.report and "cached verdict: passed" in again.result.report
    assert KEPT not in other.result.report
    assert calls == ["kept", "kept"]  # the first goal and the other application; the same one again was not dry-run
    assert len(entries()) == 2
