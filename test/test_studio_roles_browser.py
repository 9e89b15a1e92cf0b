"""Roles and the audit trail in a real headless Chromium (issue 26 item 5): an operator logs in on the station's
form, finds Save and Teach disabled with the reason, is refused a save and a teach even by a script of the page
(403, the file unchanged),
runs the saved application, pauses and resumes it; the Audit view shows each of those actions -- the refusals
too -- newest first, with who and role; an engineer logged in after saves, and the save's digests show.

Skipped only where no Chromium can be driven, as test_studio_browser.py; waits are bounded polls of what the
page shows."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.webdriver.common.by import By  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from operator_station.access import Access  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import serve  # noqa: E402
from operator_station.users import hash_password, parse_users  # noqa: E402
from test_studio_browser import driver, press, until  # noqa: E402, F401 - driver: the shared headless Chromium fixture
from test_studio_server import station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
USERS = parse_users(f"anna:operator:{hash_password('anna-pw', 'sha256')}\nben:engineer:{hash_password('ben-pw', 'sha256')}\n", "users")


def log_in(driver: Any, url: str, name: str, password: str) -> None:
    driver.get(url)
    until(driver, lambda d: d.find_element(By.ID, "login-form"))
    driver.find_element(By.ID, "login-name").send_keys(name)
    driver.find_element(By.ID, "login-password").send_keys(password)
    press(driver, "login-submit")


def audit_rows(driver: Any) -> list[list[str]]:
    """The Audit view's rows as shown (when, who, role, what, ok, answer, digests, details, session), newest first."""
    return list(driver.execute_script(
        "return [...document.querySelectorAll('#audit-rows tr')].map(tr => [...tr.children].map(td => td.textContent));"))


def test_an_operator_is_refused_save_runs_and_pauses_and_the_audit_view_shows_it_all(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    access = Access.for_address("127.0.0.1", users=USERS)
    station = build_station(station_args(file="rivet_installation.xml", speed=2.0, no_check=True), full_catalog(), tmp_path, access)
    served = serve(station)
    original = (tmp_path / "rivet_installation.xml").read_bytes()
    try:
        log_in(driver, served.url, "anna", "not her password")
        until(driver, lambda d: d.find_element(By.ID, "login-answer").text == "login: wrong name or password")
        driver.find_element(By.ID, "login-password").send_keys("anna-pw")
        press(driver, "login-submit")
        until(driver, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "true")
        until(driver, lambda d: d.find_element(By.ID, "who-line").text == "anna · operator")

        save = driver.find_element(By.ID, "save-btn")
        until(driver, lambda d: save.get_attribute("disabled") is not None)
        assert save.get_attribute("title") == "needs the engineer role; this session is operator 'anna'"
        refused = driver.execute_async_script(  # the page's own script, past the disabled button: the station refuses it
            "const done = arguments[arguments.length - 1];"
            "Store.post('/api/save', Builder.current()).then(done);")
        assert refused == {"ok": False, "error": "save: needs the engineer role; this session is operator 'anna'"}
        assert (tmp_path / "rivet_installation.xml").read_bytes() == original
        press(driver, "tab-jog")  # teaching and jogging are the engineer's: disabled, and refused when sent anyway
        until(driver, lambda d: d.find_element(By.ID, "teach-btn").get_attribute("disabled") is not None)
        assert driver.find_element(By.ID, "teach-btn").get_attribute("title") == "needs the engineer role; this session is operator 'anna'"
        taught = driver.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            "Store.post('/api/teach', {group: 'left_arm', name: 'taught_1'}).then(done);")
        assert taught == {"ok": False, "error": "teach: needs the engineer role; this session is operator 'anna'"}
        press(driver, "tab-builder")

        press(driver, "ctl-start")  # the saved application, unedited: an operator runs it
        until(driver, lambda d: (station.feed.snapshot.status or {}).get("state") == "running")
        press(driver, "ctl-pause")
        until(driver, lambda d: (station.feed.snapshot.status or {}).get("state") == "paused")
        press(driver, "ctl-resume")
        until(driver, lambda d: (station.feed.snapshot.status or {}).get("state") in ("running", "finished"))
        press(driver, "ctl-stop")
        until(driver, lambda d: not station.session.running)  # type: ignore[union-attr]

        press(driver, "tab-audit")
        expected = [("anna", "operator", "stop"), ("anna", "operator", "resume"), ("anna", "operator", "pause"), ("anna", "operator", "run start"),
                    ("anna", "operator", "teach"), ("anna", "operator", "save"), ("anna", "operator", "login"), ("anna", "", "login")]
        until(driver, lambda d: [tuple(r[1:4]) for r in audit_rows(d) if r[3] != "run end"][:8] == expected)
        rows = {(r[3], r[4]) for r in audit_rows(driver)}
        assert ("save", "refused") in rows and ("teach", "refused") in rows and ("login", "refused") in rows and ("pause", "ok") in rows
        assert all(r[0].endswith("Z") and r[8] for r in audit_rows(driver))  # when (UTC) and the session on every row

        press(driver, "logout-btn")
        log_in(driver, served.url, "ben", "ben-pw")
        until(driver, lambda d: d.find_element(By.ID, "who-line").text == "ben · engineer")
        until(driver, lambda d: d.find_element(By.ID, "save-btn").get_attribute("disabled") is None)
        press(driver, "save-btn")
        until(driver, lambda d: d.find_element(By.ID, "validation-summary").text == "saved rivet_installation.xml")
        press(driver, "tab-audit")
        until(driver, lambda d: audit_rows(d) and audit_rows(d)[0][1:5] == ["ben", "engineer", "save", "ok"])
        digests = audit_rows(driver)[0][6]
        assert " → " in digests and all(len(part) == 12 for part in digests.split(" → "))
    finally:
        served.close()
