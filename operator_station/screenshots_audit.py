"""The Audit view's screenshot for docs/studio.md (run by :mod:`operator_station.screenshots`).

A station with two users (the passwords are the shot's own, made here): the operator logs in, is refused a save,
runs the rivet demonstrator at 4x, pauses and resumes it; then the Audit view with those actions newest first.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app_functions.registry import full_catalog
from operator_station import browser
from operator_station.access import Access
from operator_station.cli import build_station
from operator_station.testing import serve, shipped_apps
from operator_station.users import hash_password, parse_users


def shoot_audit(out: Path, args: Callable[..., Any], until: Callable[..., None]) -> list[Path]:
    """``args``/``until``: the screenshot script's station arguments and bounded page poll."""
    out.mkdir(parents=True, exist_ok=True)
    users = parse_users(f"anna:operator:{hash_password('anna-pw', 'sha256')}\nben:engineer:{hash_password('ben-pw', 'sha256')}\n", "users")
    shot = out / "studio_audit.png"
    with shipped_apps("rivet_installation.xml") as folder:
        driver = browser.chromium(1600, 640)
        station = build_station(args(file="rivet_installation.xml", speed=4.0, no_check=True), full_catalog(), folder, Access.for_address("127.0.0.1", users=users))
        served = serve(station)
        try:
            driver.get(served.url)
            until(driver, "document.getElementById('login-form') !== null")
            driver.find_element("id", "login-name").send_keys("anna")
            driver.find_element("id", "login-password").send_keys("anna-pw")
            driver.find_element("id", "login-submit").click()
            until(driver, "document.body.dataset.ready === 'true' && document.getElementById('who-line').textContent === 'anna · operator'")
            driver.execute_script("Store.post('/api/save', Builder.current())")  # refused: the operator's save, audited
            driver.find_element("id", "ctl-start").click()
            until(driver, "document.getElementById('engine-state').textContent === 'running'")
            driver.find_element("id", "ctl-pause").click()
            until(driver, "document.getElementById('engine-state').textContent === 'paused'")
            driver.find_element("id", "ctl-resume").click()
            until(driver, "document.getElementById('engine-state').textContent === 'finished'", 300.0)
            driver.find_element("id", "tab-audit").click()
            until(driver, "[...document.querySelectorAll('#audit-rows tr td:nth-child(4)')].some((td) => td.textContent === 'run end')")
            time.sleep(0.3)  # a frame for the view to lay out (a picture, not a test)
            driver.save_screenshot(str(shot))
        finally:
            served.close()
            driver.quit()
    return [shot]
