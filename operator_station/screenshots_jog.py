"""The Jog view's screenshot for docs/studio.md (run by :mod:`operator_station.screenshots`).

The rivet demonstrator's station: the left arm jogged in the world's z by holding + for a moment, released, then
its TCP taught as frame ``taught_1`` under ``part``: the diff of the cell shown, waiting for the save.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.support.ui import Select

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.cli import build_station
from operator_station.testing import serve, shipped_apps


def shoot_jog(out: Path, args: Callable[..., Any], until: Callable[..., None]) -> list[Path]:
    """``args``/``until``: the screenshot script's station arguments and bounded page poll."""
    out.mkdir(parents=True, exist_ok=True)
    shot = out / "studio_jog.png"
    with shipped_apps("rivet_installation.xml") as folder:
        driver = browser.chromium(1600, 900)
        station = build_station(args(file="rivet_installation.xml"), full_catalog(), folder)
        served = serve(station)
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true'")
            driver.find_element("id", "tab-jog").click()
            until(driver, "document.querySelectorAll('#jog-pad .jog-button').length > 0")
            Select(driver.find_element("id", "jog-mode")).select_by_value("cartesian")
            until(driver, "document.querySelector('#jog-pad .jog-button[data-axis=\"z\"]') !== null")
            plus = driver.find_element("css selector", '#jog-pad .jog-button[data-axis="z"][data-direction="1"]')
            ActionChains(driver).click_and_hold(plus).perform()
            until(driver, "document.getElementById('jog-status').textContent.startsWith('jogging')")
            time.sleep(1.5)  # held for a moment: a picture, not a test
            ActionChains(driver).release(plus).perform()
            until(driver, "document.getElementById('jog-status').textContent === 'jog released'")
            Select(driver.find_element("id", "teach-parent")).select_by_value("part")
            driver.find_element("id", "teach-btn").click()
            until(driver, "!document.getElementById('teach-save').disabled")
            driver.save_screenshot(str(shot))
        finally:
            driver.quit()
            served.close()
            station.stop()
    return [shot]
