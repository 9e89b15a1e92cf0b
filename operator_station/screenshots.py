"""The screenshots of docs/studio.md, taken in headless Chromium with the tests' own driver.

Usage: python -m operator_station.screenshots [docs/img]

Serves a station on the rivet demonstrator (a copy, in a temporary folder) at 4x, shows the
builder with a cell selected and a bad edit, runs the application and shoots the monitor while
both arms work, the timeline when it has finished, then replays the trace and shoots the monitor
and the timeline with the time slider put back to the middle of the run; last, the builder on the
pallet-grid example (a loop as a block).
"""
from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.cli import build_station
from operator_station.scene3d_screenshots import shoot_3d
from operator_station.screenshots_audit import shoot_audit
from operator_station.screenshots_jog import shoot_jog
from operator_station.screenshots_breakpoints import shoot_breakpoints
from operator_station.screenshots_paused_edit import shoot_paused_edit
from operator_station.screenshots_speed import shoot_speed
from operator_station.testing import serve, shipped_apps, station_args, until

ROOT = Path(__file__).resolve().parent.parent


def _tab(driver: Any, name: str) -> None:
    driver.find_element("id", f"tab-{name}").click()
    time.sleep(0.5)  # a frame or two for the view to lay out before the picture (a picture, not a test)


def shoot(out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    shots: list[Path] = []
    with shipped_apps("rivet_installation.xml") as folder:
        trace = folder / "run.jsonl"
        driver = browser.chromium(1600, 1000)
        served = serve(build_station(station_args(file="rivet_installation.xml", speed=4.0, trace=str(trace)), full_catalog(), folder))
        take: Callable[[str], None] = lambda name: (driver.save_screenshot(str(out / name)), shots.append(out / name))  # noqa: E731
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.execute_script("Builder.select(1, 'left_arm')")
            field = driver.find_element("id", "param-0")
            field.clear()
            field.send_keys("drill_9")
            until(driver, "document.querySelector('.op-cell.has-error') !== null")
            take("studio_builder.png")
            field = driver.find_element("id", "param-0")
            field.clear()
            field.send_keys("drill_1")
            until(driver, "Builder.state.valid === true")
            driver.find_element("id", "ctl-start").click()
            until(driver, "['Motion','Vision','EndEffector'].includes(Store.groupView().left_arm.state) && Store.groupView().right_arm.state === 'Motion'")
            take("studio_monitor.png")
            until(driver, "document.getElementById('engine-state').textContent === 'finished'", 300.0)
            served.station.session.join(60.0)  # type: ignore[union-attr]
            _tab(driver, "timeline")
            until(driver, "Timeline.model() && Timeline.model().bars > 0")
            take("studio_timeline.png")
        finally:
            served.close()
        replay = serve(build_station(station_args(replay=str(trace)), full_catalog(), folder))
        try:
            driver.get(replay.url)
            until(driver, "Store.snapshot && Store.snapshot.mode === 'replay' && Store.records.length > 0")
            _tab(driver, "timeline")
            until(driver, "Timeline.model() && Timeline.model().bars > 0")
            middle = driver.execute_script("return Timeline.model().end / 2")
            driver.execute_script(f"Store.setCursor({middle})")
            until(driver, f"Timeline.model() && Math.abs(Timeline.model().end - {middle}) < 1e-6")
            take("studio_replay_timeline.png")
            _tab(driver, "monitor")
            take("studio_replay_monitor.png")
        finally:
            replay.close()
            driver.quit()
    shots.append(shoot_loops(out))
    shots += shoot_audit(out, station_args, until)
    shots += shoot_3d(out, station_args, until)
    shots += shoot_jog(out, station_args, until)
    shots.append(shoot_breakpoints(out, station_args, until))
    shots.append(shoot_paused_edit(out, station_args, until))
    shots.append(shoot_speed(out, station_args, until))
    shots += shoot_monitor(out)
    shots += shoot_timeline(out)
    return shots


def shoot_loops(out: Path) -> Path:
    """The builder on the pallet-grid example: a for_each over a grid as a block, an operation inside it selected."""
    with tempfile.TemporaryDirectory(prefix="studio_shots_") as name:
        folder = Path(name)
        shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
        shutil.copytree(ROOT / "apps_xml" / "examples", folder / "examples")
        driver = browser.chromium(1600, 700)
        served = serve(build_station(station_args(file="examples/pallet_grid.xml"), full_catalog(), folder))
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true && Builder.state.cellNames")
            driver.execute_script("Builder.select(1, 'right_arm')")
            until(driver, "document.getElementById('fn-select') !== null")
            driver.save_screenshot(str(out / "studio_builder_loops.png"))
        finally:
            served.close()
            driver.quit()
    return out / "studio_builder_loops.png"


def shoot_timeline(out: Path) -> list[Path]:
    """The timeline of the asynchronous rivet demonstrator (sync="flags") after its run, with a vision fault the retry
    recovers: the axis, the critical path crossing between the arms, the flag and zone waits by name, the dry run's
    plan under each function, the error and the retry; then zoomed in on the right arm's wait for the left arm's flag,
    the primitives inside the functions."""
    out.mkdir(parents=True, exist_ok=True)
    shots = [out / "studio_timeline_critical.png", out / "studio_timeline_zoomed.png"]
    with shipped_apps("rivet_async.xml") as folder:
        driver = browser.chromium(1600, 560)
        served = serve(build_station(station_args(file="rivet_async.xml", fault=["left_arm:vision"]), full_catalog(), folder))
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.find_element("id", "ctl-start").click()
            until(driver, "document.getElementById('engine-state').textContent === 'finished'", 300.0)
            served.station.session.join(60.0)  # type: ignore[union-attr]
            _tab(driver, "timeline")
            until(driver, "Timeline.model() && Timeline.model().critical.length > 0 && Timeline.model().plan.length > 0")
            driver.save_screenshot(str(shots[0]))
            wait = driver.execute_script("return Timeline.model().waits.right_arm.find((w) => w.waiting.startsWith('flag '))")
            driver.execute_script(f"Timeline.show({wait['start'] - 1.5}, {wait['end'] + 2.5})")
            until(driver, "document.querySelector('#timeline-svg rect.primitive') !== null")
            driver.save_screenshot(str(shots[1]))
        finally:
            served.close()
            driver.quit()
    return shots


#: Scroll an element to the top of the window, below the sticky top bar.
SCROLL_TO = "arguments[0].scrollIntoView(); window.scrollBy(0, -document.getElementById('topbar').offsetHeight - 6);"


def shoot_monitor(out: Path) -> list[Path]:
    """The monitor's state graphs and run summary: the asynchronous rivet demonstrator (sync="flags") at 4x with a
    vision fault the retry recovers; the left arm's card paused mid-motion (Pause current, the pause edge lit, the state it left
    marked), then the summary panel once the run has ended."""
    out.mkdir(parents=True, exist_ok=True)
    with shipped_apps("rivet_async.xml") as folder:
        driver = browser.chromium(1600, 1000)
        served = serve(build_station(station_args(file="rivet_async.xml", speed=4.0, fault=["left_arm:vision"]), full_catalog(), folder))
        shots = [out / "studio_state_graph.png", out / "studio_run_summary.png"]
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.find_element("id", "ctl-start").click()
            _tab(driver, "monitor")
            for _ in range(8):  # an arm between two primitives is held in Ready, not paused mid-motion: then again
                until(driver, "['Motion','Vision','EndEffector'].includes(Store.groupView().left_arm.state)")
                driver.find_element("id", "ctl-pause").click()
                until(driver, "document.getElementById('engine-state').textContent === 'paused'")
                time.sleep(1.0)  # the machines follow the engine's pause (a picture, not a test)
                if driver.execute_script("return Store.groupView().left_arm.state") == "Pause":
                    break
                driver.find_element("id", "ctl-resume").click()
            driver.execute_script("Monitor.render()")
            time.sleep(0.3)
            card = driver.find_element("css selector", '.group-card[data-group="left_arm"]')
            driver.execute_script(SCROLL_TO, card)  # the whole card in the window, below the top bar: the picture is of what is shown
            card.screenshot(str(shots[0]))
            driver.find_element("id", "ctl-resume").click()
            until(driver, "document.body.dataset.summary === 'finished'", 300.0)
            time.sleep(0.3)
            summary = driver.find_element("id", "run-summary")
            driver.execute_script(SCROLL_TO, summary)
            summary.screenshot(str(shots[1]))
        finally:
            served.close()
            driver.quit()
    return shots


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default=str(ROOT / "docs" / "img"))
    args = parser.parse_args()
    if browser.missing():
        print(f"cannot take screenshots: {browser.missing()}", file=sys.stderr)
        return 2
    for path in shoot(Path(args.out)):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
