"""Editing a paused run from the page, in a real headless Chromium (issue 26's must-show): an edit that would collide
is refused with the dry run's finding at its cell and the run stays paused with its own remainder; a safe one is
swapped in and the run goes on to FINISHED with it.

Skipped only where no Chromium can be driven (the reason says what is missing).  Waits are bounded polls of what the
page shows, never a fixed sleep.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.webdriver.common.by import By  # noqa: E402

from execution_engine.engine.remainder_swap import application_digest  # noqa: E402
from test_paused_edit import HOME, LEFT_IN, REACH, RIGHT_OUT, application, op  # noqa: E402
from test_studio_browser import cell, driver, open_station, press, text, type_into, until, validated  # noqa: E402,F401

#: The left arm waits 40 s of run time in operation 2 (5 s of wall time at --speed 8): the run is paused inside it.
APP = application(REACH, op("hold", left_arm=("wait", "40")), op("closer", left_arm=("move_to", LEFT_IN)), HOME)
WIDER = "0.30,0.25,0.10,180deg,0,90deg"


def lock(driver: Any, row: int) -> str | None:
    return driver.find_element(By.CSS_SELECTOR, f'.ops-row[data-op="{row}"]').get_attribute("data-lock")


def answers(driver: Any) -> int:
    return int(driver.find_element(By.TAG_NAME, "body").get_attribute("data-edit-answers") or 0)


def apply_edit(driver: Any, value: str, answered: int) -> str | None:
    """Type ``value`` as the selected call's first parameter and apply it as an edit of the paused run, the
    ``answered``-th; the station's answer as the page marks it (refused, swapped)."""
    type_into(driver, "param-0", value)
    until(driver, lambda d: validated(d) == "valid")
    press(driver, "apply-edit-btn")
    until(driver, lambda d: answers(d) == answered)
    return driver.find_element(By.TAG_NAME, "body").get_attribute("data-edit-answer")


def test_a_colliding_edit_of_the_paused_run_is_refused_at_its_cell_and_a_safe_one_is_swapped_and_runs_to_finished(driver: Any, tmp_path: Path) -> None:
    (tmp_path / "edit_demo.xml").write_text(APP)
    served = open_station(driver, tmp_path, file="edit_demo.xml", speed=8.0, trace=str(tmp_path / "run.jsonl"))
    station = served.station
    try:
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "ctl-start")
        until(driver, lambda d: (station.feed.snapshot.status or {}).get("operation_id") == "hold")
        press(driver, "ctl-pause")
        until(driver, lambda d: text(d, "engine-state") == "paused")
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, '.tab[data-view="builder"]').click() or True)  # Start showed the monitor
        engine = station.session.edit_target.engine  # type: ignore[union-attr]
        old = engine.app
        until(driver, lambda d: lock(d, 0) == "done" and lock(d, 1) == "running" and lock(d, 2) is None)  # the builder locks what ran
        assert driver.find_element(By.CSS_SELECTOR, '.ops-row[data-op="1"] input.op-id').get_attribute("disabled") is not None

        until(driver, lambda d: cell(d, 2, "left_arm").click() or True)  # the left hand sent to where the right one stands
        assert apply_edit(driver, RIGHT_OUT, 1) == "refused", text(driver, "validation-summary")
        until(driver, lambda d: "has-error" in (cell(d, 2, "left_arm").get_attribute("class") or "") and "collision" in cell(d, 2, "left_arm").text)
        assert "not swapped" in text(driver, "validation-summary") and "found by the dry run of operations 3.." in text(driver, "validation-summary")
        assert text(driver, "engine-state") == "paused" and engine.app is old  # nothing changed

        assert apply_edit(driver, WIDER, 2) == "swapped", text(driver, "validation-summary")
        assert text(driver, "validation-summary").startswith("edit: swapped: operations from 3 on are edit_demo.xml's")
        new = engine.app
        assert new is not old and new.operations[2].calls["left_arm"].params[0] == WIDER

        press(driver, "ctl-resume")
        until(driver, lambda d: text(d, "engine-state") == "finished")
        records = station.feed.read(0, 0)[1]
        (swap,) = [r for r in records if r["event"] == "swap"]
        assert (swap["from_digest"], swap["to_digest"], swap["from_operation"]) == (application_digest(old), application_digest(new), 3)
        moved = [r for r in records if r["event"] == "function_end" and r["operation"] == "closer" and r["group"] == "left_arm"]
        assert [r["outcome"] for r in moved] == ["succeeded"]
        assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "finished"
        traced = [json.loads(line) for line in (tmp_path / "run.jsonl").read_text().splitlines()]
        assert [r for r in traced if r["event"] == "swap"] == [swap]  # the trace holds it as the page does
    finally:
        served.close()
