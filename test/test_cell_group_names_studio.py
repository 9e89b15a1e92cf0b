"""The studio's 3D view of a cell whose robots' groups and joints the cell names (apps_xml/examples/side_by_side.xml):
/joint_states carries kuka_A1.. and viper_joint_1.., the URDFs' joints are A1.. and joint_1..; the page puts each name
on its robot's joint (the robot's prefix taken off) and each group's TCP on its robot's tool link.  After the run, each
hand drawn through its URDF's chain is where its bridge said it ended, in the cell's world frame, and the monitor plots
each robot's joints apart, under the application's group names.

A real headless Chromium (Selenium), skipped only where none can be driven; waits are bounded polls of the page.
"""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from test_studio_3d import last_tcps, open_3d, show_3d, until  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "apps_xml" / "examples"


@pytest.fixture(scope="module")
def driver() -> Any:
    chrome = browser.chromium(1280, 860)
    try:
        yield chrome
    finally:
        chrome.quit()


def test_the_3d_view_draws_both_robots_by_the_cell_s_joint_names(driver: Any, tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    shutil.copy(EXAMPLES / "side_by_side.xml", tmp_path / "side_by_side.xml")
    shutil.copy(EXAMPLES / "cells" / "side_by_side_cell.xml", tmp_path / "cells" / "side_by_side_cell.xml")
    trace = tmp_path / "run.jsonl"
    served = open_3d(driver, tmp_path, file="side_by_side.xml", speed=1.0, trace=str(trace))
    try:
        until(driver, lambda d: d.find_element(By.ID, "ctl-start").click() or True)
        until(driver, lambda d: d.find_element(By.ID, "engine-state").text in ("finished", "failed", "stopped"))
        assert driver.find_element(By.ID, "engine-state").text == "finished", driver.find_element(By.ID, "alarms").text
        show_3d(driver)
        reported = last_tcps(trace)
        assert set(reported) == {"kuka_arm", "inspector"}
        for group in ("kuka_arm", "inspector"):
            drawn = until(driver, lambda d, g=group: d.execute_script("view3d.update(); return view3d.tcp(arguments[0])", g))
            assert drawn[:3] == pytest.approx([reported[group][k] for k in ("x", "y", "z")], abs=2e-4), group
        drawn_joints = driver.execute_script("return view3d.jointValues()")
        names = driver.execute_script("return Store.joints.names")
        assert {"kuka_A1", "viper_joint_1"} <= set(names)
        assert {"A1", "joint_1"} <= set(drawn_joints)  # the URDFs' own joints, set from the cell's names
        # the monitor plots each robot's joints apart, under the application's group names (not one plot of all)
        plotted = until(driver, lambda d: d.execute_script(
            "const p = [...document.querySelectorAll('#joint-plots .joint-plot')];"
            "return p.length >= 2 ? p.map((e) => [e.dataset.group, [...e.querySelectorAll('.u-series .u-label')].map((t) => t.textContent)]) : null"))
        assert {g: labels[1:] for g, labels in plotted} == {"kuka_arm": [f"kuka_A{i}" for i in range(1, 7)],
                                                           "inspector": [f"viper_joint_{i}" for i in range(1, 7)]}, plotted
    finally:
        served.close()
