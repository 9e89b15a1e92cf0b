"""Breakpoints in a real headless Chromium (issue 26's must-show): a breakpoint set in the builder's gutter stops
the run before its operation, "Run to here" goes on and stops before the chosen one, a breakpoint set at run time
from the monitor stops it again, and the file was never changed.

Skipped only where no Chromium can be driven; waits are bounded polls of what the page shows.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.webdriver.common.by import By  # noqa: E402

from test_studio_browser import WAIT, driver, open_station, press, text, until, validated  # noqa: E402,F401 - driver: the fixture

ROOT = Path(__file__).resolve().parents[1]


def where(driver: Any) -> str:
    return str(driver.find_element(By.CSS_SELECTOR, "#bp-bar .bp-where").text)


def started(records: list[dict[str, Any]]) -> list[str]:
    """The operations some group started a function of, in order, once each."""
    out: list[str] = []
    for r in records:
        if r["event"] == "function_start" and r["operation"] not in out:
            out.append(r["operation"])
    return out


def test_a_breakpoint_stops_before_its_operation_and_run_to_here_goes_on_to_the_chosen_one(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    app = tmp_path / "rivet_installation.xml"
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", app)
    original = app.read_bytes()
    trace = tmp_path / "run.jsonl"
    served = open_station(driver, tmp_path, file="rivet_installation.xml", no_check=True, trace=str(trace))
    feed = served.station.feed
    try:
        until(driver, lambda d: validated(d) == "valid")
        gutter = '.op-index.op-break[data-op="2"]'  # operation 3 (the third row)
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, gutter).click() or True)
        until(driver, lambda d: "on" in d.find_element(By.CSS_SELECTOR, gutter).get_attribute("class").split())

        press(driver, "ctl-start")
        press(driver, "tab-monitor")
        until(driver, lambda d: text(d, "engine-state") == "paused" and where(d).startswith("paused at breakpoint before operation 3 '3' (line "))
        assert started(feed.read(0, 0)[1]) == ["1", "2"]  # every group at the barrier before 3
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, '.bp-row[data-op="3"]').get_attribute("class").split().count("paused-here") == 1)

        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, '.bp-row[data-op="6"] .bp-run-to').click() or True)
        until(driver, lambda d: text(d, "engine-state") == "paused" and where(d).startswith("paused before operation 6 '6' (line "))
        assert where(driver).endswith("the run-to target is reached")
        assert started(feed.read(0, 0)[1]) == ["1", "2", "3", "4", "5"]

        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, '.bp-row[data-op="8"] .bp-toggle').click() or True)  # this run only
        until(driver, lambda d: "on" in d.find_element(By.CSS_SELECTOR, '.bp-row[data-op="8"]').get_attribute("class").split())
        press(driver, "tab-monitor")
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, "#bp-bar .bp-continue").click() or True)
        until(driver, lambda d: text(d, "engine-state") == "paused" and where(d).startswith("paused at breakpoint before operation 8 '8' (line "))
        assert started(feed.read(0, 0)[1]) == ["1", "2", "3", "4", "5", "6", "7"]
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, "#bp-bar .bp-continue").click() or True)
        until(driver, lambda d: text(d, "engine-state") == "finished")
        served.station.session.join(WAIT)  # type: ignore[union-attr]

        records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
        assert [(r["operation"], r["kind"]) for r in records if r["event"] == "breakpoint"] == [("3", "break"), ("6", "run_to"), ("8", "break")]
        commands = [(r["command"], r.get("target"), r["source"], r["accepted"]) for r in records if r["event"] == "operator"]
        assert commands == [("start", None, "studio", True), ("run_to", "6", "studio", True), ("break", "8", "studio", True),
                            ("resume", None, "studio", True), ("resume", None, "studio", True)]
        assert app.read_bytes() == original  # the gutter changed the page's document, the monitor only the run
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        served.close()
