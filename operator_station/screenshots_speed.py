"""The speed override's screenshot for docs/studio.md (run by :mod:`operator_station.screenshots`).

The rivet demonstrator running at 2x: once both arms work, the control bar's speed slider is set to 0 %: every arm
brakes on its path and holds there, the bar says so and the engine's line shows the change the engine recorded.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.cli import build_station
from operator_station.testing import serve, shipped_apps


def shoot_speed(out: Path, args: Callable[..., Any], until: Callable[..., None]) -> Path:
    """``args``/``until``: the screenshot script's station arguments and bounded page poll."""
    out.mkdir(parents=True, exist_ok=True)
    shot = out / "studio_speed_override.png"
    with shipped_apps("rivet_installation.xml") as folder:
        driver = browser.chromium(1600, 1000)
        served = serve(build_station(args(file="rivet_installation.xml", speed=2.0), full_catalog(), folder))
        try:
            driver.get(served.url)
            until(driver, "document.body.dataset.ready === 'true' && Builder.state.valid === true")
            driver.find_element("id", "ctl-start").click()
            until(driver, "Store.groupView().left_arm.state === 'Motion' && Store.groupView().right_arm.state === 'Motion'", 300.0)
            driver.execute_script("const s = document.getElementById('speed-override'); s.value = '0'; s.dispatchEvent(new Event('change'));")
            until(driver, "!document.getElementById('speed-hold').hidden && Store.snapshot.status.speed_override === 0")
            until(driver, "Store.joints.samples.length > 3 && Store.joints.samples.slice(-3).every((s, i, a) => s.slice(1).every((v, k) => v === a[0][k + 1]))")
            driver.save_screenshot(str(shot))
        finally:
            served.close()
            driver.quit()
    return shot
