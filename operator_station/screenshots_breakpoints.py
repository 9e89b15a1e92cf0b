"""The breakpoints' screenshot for docs/studio.md (run by :mod:`operator_station.screenshots`).

The rivet demonstrator with a breakpoint set in the builder's gutter before operation 3; the run pauses there
and the monitor's Breakpoints panel says why, with a run-time breakpoint set before operation 8 as well.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.cli import build_station
from operator_station.testing import serve, shipped_apps


def shoot_breakpoints(out: Path, args: Callable[..., Any], until: Callable[..., None]) -> Path:
    """``args``/``until``: the screenshot script's station arguments and bounded page poll."""
    out.mkdir(parents=True, exist_ok=True)
    shot = out / "studio_breakpoints.png"
    with shipped_apps("rivet_installation.xml") as folder:
        driver = browser.chromium(1600, 900)
        served = serve(build_station(args(file="rivet_installation.xml", no_check=True), full_catalog(), folder))
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.find_element("css selector", '.op-index.op-break[data-op="2"]').click()  # operation 3's gutter
            until(driver, "document.querySelector('.op-index.op-break[data-op=\"2\"]').classList.contains('on')")
            driver.find_element("id", "ctl-start").click()
            driver.find_element("id", "tab-monitor").click()
            until(driver, "document.getElementById('engine-state').textContent === 'paused'")
            until(driver, "document.querySelector('.bp-row[data-op=\"8\"] .bp-toggle') !== null")
            driver.find_element("css selector", '.bp-row[data-op="8"] .bp-toggle').click()  # this run only
            until(driver, "document.querySelector('.bp-row[data-op=\"8\"]').classList.contains('on')")
            driver.save_screenshot(str(shot))
        finally:
            served.close()
            driver.quit()
    return shot
