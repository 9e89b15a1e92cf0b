"""The screenshot of editing a paused run for docs/studio.md (run by :mod:`operator_station.screenshots`).

Two arms reach out, the left one waits 40 s, then moves in: the run is paused inside the wait, the builder marks the
first operation done and the second running, and an edit sending the left hand to where the right one stands is
applied -- refused, with the dry run's collision at its cell.
"""
from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from selenium.webdriver.common.keys import Keys

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.cli import build_station
from operator_station.testing import serve

LEFT, RIGHT = "0.30,0.20,0.10,180deg,0,90deg", "0.30,-0.20,0.10,180deg,0,90deg"


def _move(group: str, function: str, value: str) -> str:
    return f'<{group}><function name="{function}"><params><param value="{value}"/></params></function></{group}>'


APP = (
    '<?xml version="1.0"?>\n<application name="edit_demo" robot="nextage">\n'
    f'  <operation id="reach" name="reach out">{_move("left_arm", "move_to", LEFT)}{_move("right_arm", "move_to", RIGHT)}</operation>\n'
    f'  <operation id="hold" name="hold">{_move("left_arm", "wait", "40")}</operation>\n'
    f'  <operation id="closer" name="move in">{_move("left_arm", "move_to", "0.30,0.12,0.10,180deg,0,90deg")}</operation>\n'
    f'  <operation id="home" name="home">{_move("left_arm", "move_to_joint_pose", "initial")}{_move("right_arm", "move_to_joint_pose", "initial")}</operation>\n'
    "</application>\n"
)


def shoot_paused_edit(out: Path, args: Callable[..., Any], until: Callable[..., None]) -> Path:
    """``args``/``until``: the screenshot script's station arguments and bounded page poll."""
    out.mkdir(parents=True, exist_ok=True)
    shot = out / "studio_paused_edit.png"
    with tempfile.TemporaryDirectory(prefix="studio_shots_") as name:
        folder = Path(name)
        (folder / "edit_demo.xml").write_text(APP)
        driver = browser.chromium(1600, 720)
        served = serve(build_station(args(file="edit_demo.xml", speed=8.0), full_catalog(), folder))
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.find_element("id", "ctl-start").click()
            until(driver, "Store.snapshot && Store.snapshot.status && Store.snapshot.status.operation_id === 'hold'")
            driver.find_element("id", "ctl-pause").click()
            until(driver, "document.getElementById('engine-state').textContent === 'paused'")
            driver.find_element("id", "tab-builder").click()
            until(driver, "document.querySelector('.ops-row[data-op=\"1\"]').dataset.lock === 'running'")
            driver.find_element("css selector", '.op-cell[data-op="2"][data-group="left_arm"]').click()
            until(driver, "document.getElementById('param-0') !== null")
            field = driver.find_element("id", "param-0")
            field.clear()
            field.send_keys(RIGHT, Keys.TAB)
            until(driver, f"document.getElementById('param-0').value === '{RIGHT}' && Builder.state.valid === true")
            driver.find_element("id", "apply-edit-btn").click()
            until(driver, "document.body.dataset.editAnswers === '1'")
            until(driver, "document.querySelector('.op-cell[data-op=\"2\"][data-group=\"left_arm\"]').classList.contains('has-error')")
            driver.save_screenshot(str(shot))
        finally:
            served.close()
            driver.quit()
    return shot
