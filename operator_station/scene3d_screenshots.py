"""The 3D view's screenshots of docs/studio.md (taken by ``python -m operator_station.screenshots``): the rivet
demonstrator mid-run, a recording of it replayed at two slider positions, the dry run's collision of the two arms at its
moment, the same collision stopped by the simulator at its moment, and the mixed cell's two robots where its cell places them --
each in headless Chromium with the tests' own driver.
"""
from __future__ import annotations

import argparse
import io
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lxml import etree

from app_functions.registry import full_catalog
from cell_runner.cli import main as run_main
from operator_station import browser
from operator_station.cli import build_station
from operator_station.testing import serve

ROOT = Path(__file__).resolve().parent.parent
Until = Callable[..., None]
#: The demonstrator's third operation with the left arm sent to the hole the right arm inserts into (test_scene3d.ARMS_MEET).
MEET = ("""    <left_arm>
      <function name='wait'></function>
    </left_arm>
    <torso_head>
      <function name='wait'></function>
    </torso_head>
    <right_arm>
      <function name='insert_rivet'>""", """    <left_arm>
      <function name='approach'>
        <params>
          <param value='drill_1'></param>
        </params>
      </function>
    </left_arm>
    <torso_head>
      <function name='wait'></function>
    </torso_head>
    <right_arm>
      <function name='insert_rivet'>""")


def _folder(name: str) -> Path:
    folder = Path(name)
    shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
    shutil.copytree(ROOT / "apps_xml" / "examples", folder / "examples")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", folder / "rivet_installation.xml")
    return folder


def _arms_meet(folder: Path) -> Path:
    """The demonstrator's first three operations, the left arm sent into the right arm's hole in the third."""
    text = (ROOT / "apps_xml" / "rivet_installation.xml").read_text(encoding="utf-8").replace(*MEET, 1)
    root = etree.fromstring(text.encode())
    for extra in root.findall("operation")[3:]:
        root.remove(extra)
    root.set("name", "rivet_arms_meet")
    path = folder / "rivet_arms_meet.xml"
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return path


def _show(driver: Any, until: Until, frames: bool = False) -> None:
    driver.find_element("id", "tab-view3d").click()
    until(driver, "window.view3d && view3d.ready()")
    if driver.find_element("id", "view3d-frames").is_selected() != frames:
        driver.find_element("id", "view3d-frames").click()
    driver.execute_script("view3d.update()")
    time.sleep(0.6)  # a few frames drawn before the picture (a picture, not a test)


def shoot_3d(out: Path, args: Callable[..., argparse.Namespace], until: Until) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    shots = [out / f"studio_3d_{n}.png" for n in ("live", "replay_early", "replay_late", "dry_run_collision", "mixed_cell", "collision_run")]
    with tempfile.TemporaryDirectory(prefix="studio_shots_") as name:
        folder = _folder(name)
        driver = browser.chromium(1400, 860)
        try:
            served = serve(build_station(args(file="rivet_installation.xml", speed=4.0), full_catalog(), folder))
            try:
                driver.get(served.url)
                until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
                driver.find_element("id", "ctl-start").click()
                until(driver, "Store.groupView().left_arm.primitive && Store.groupView().left_arm.primitive.startsWith('move_cartesian')"
                              " && Store.groupView().right_arm.primitive && view3d.goals().length >= 2", 300.0)
                _show(driver, until)
                driver.save_screenshot(str(shots[0]))
                driver.find_element("id", "ctl-stop").click()
            finally:
                served.close()
            recording = folder / "rivet.mcap"
            code = run_main(["run", str(folder / "rivet_installation.xml"), "--speed", "max", "-q", "--record", str(recording)], io.StringIO(), io.StringIO())
            if code != 0:
                raise RuntimeError(f"the recording for the screenshots could not be made (exit {code})")
            replay = serve(build_station(args(replay=str(recording)), full_catalog(), folder))
            try:
                driver.get(replay.url)
                until(driver, "document.body.dataset.ready === 'true' && window.view3d && view3d.ready() && view3d.located().length > 0")
                for shot, share, frames in ((shots[1], 0.08, False), (shots[2], 0.62, True)):
                    _show(driver, until, frames)
                    driver.execute_script("const s = document.getElementById('view3d-slider'); s.value = s.max * arguments[0]; s.dispatchEvent(new Event('input'))", share)
                    time.sleep(0.6)
                    driver.save_screenshot(str(shot))
            finally:
                replay.close()
            meet = serve(build_station(args(file=_arms_meet(folder).name), full_catalog(), folder))
            try:
                driver.get(meet.url)
                until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
                driver.find_element("id", "ctl-start").click()
                until(driver, "view3d.highlighted().length === 2 && view3d.shown() !== null", 300.0)
                _show(driver, until)
                # in front of the robot, both arms coming in to where the dry run has the two hands meet (the robot drawn at
                # that finding's instant)
                driver.execute_script("""const [a, b] = view3d.shown().bodies.map((n) => view3d.linkPosition(n));
                    const m = a.map((x, i) => (x + b[i]) / 2);
                    view3d.look([m[0] + 0.9, m[1] - 0.1, m[2] + 0.6], [m[0] - 0.05, m[1], m[2] + 0.15]);""")
                time.sleep(0.6)
                driver.save_screenshot(str(shots[3]))
            finally:
                meet.close()
            stopped = serve(build_station(args(file="rivet_arms_meet.xml", no_check=True), full_catalog(), folder))
            try:  # the same application without the dry run: the simulator's own check stops the arm as the hands meet
                driver.get(stopped.url)
                until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
                driver.find_element("id", "ctl-start").click()
                until(driver, "document.getElementById('engine-state').textContent === 'failed' && view3d.findings().length > 0", 300.0)
                _show(driver, until)
                driver.execute_script("const s = document.getElementById('view3d-slider'); s.value = view3d.findings()[0].t; s.dispatchEvent(new Event('input'))")
                driver.execute_script("view3d.look([0.95, 0.55, 0.55], [0.34, 0.02, 0.05])")  # close to the part, where the hands met
                time.sleep(0.6)
                driver.save_screenshot(str(shots[5]))
            finally:
                stopped.close()
            mixed = serve(build_station(args(file="examples/mixed_cell.xml"), full_catalog(), folder))
            try:
                driver.get(mixed.url)
                until(driver, "document.body.dataset.ready === 'true' && window.view3d && view3d.ready()")
                _show(driver, until, True)
                driver.execute_script("view3d.look([2.1, 0.5, 1.5], [0.35, -0.45, 0.25])")  # both robots, the KUKA behind the Nextage's right arm
                time.sleep(0.6)
                driver.save_screenshot(str(shots[4]))
            finally:
                mixed.close()
        finally:
            driver.quit()
    return shots
