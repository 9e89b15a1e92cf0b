"""Editing a paused ``sync="flags"`` run from the page, in a real headless Chromium: the left arm holds at its
breakpoint before ``closer`` while the right one waits inside ``right_wait`` for the left's flag; an edit sending the
left hand to where the right one waits is refused with the dry run's collision at its cell and nothing changes, a
safe one is swapped with each group where it stands, and Resume runs it to FINISHED.

Skipped only where no Chromium can be driven (the reason says what is missing).  Waits are bounded polls of what the
page shows, never a fixed sleep; the run holds at its breakpoint, so nothing races.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.webdriver.common.by import By  # noqa: E402

from test_paused_edit import RIGHT_OUT  # noqa: E402
from test_paused_edit_browser import apply_edit, lock  # noqa: E402
from test_paused_edit_flags import OLD, WHERE, WIDER  # noqa: E402
from test_studio_browser import cell, driver, open_station, press, text, until, validated  # noqa: E402,F401


def test_a_paused_flags_run_refuses_a_colliding_edit_at_its_cell_and_swaps_a_safe_one_that_runs_to_finished(driver: Any, tmp_path: Path) -> None:
    (tmp_path / "edit_flags.xml").write_text(OLD)
    served = open_station(driver, tmp_path, file="edit_flags.xml", speed=8.0)
    station = served.station
    groups = lambda: (station.feed.snapshot.status or {}).get("groups") or {}  # noqa: E731
    try:
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "ctl-start")
        until(driver, lambda d: text(d, "engine-state") == "paused" and groups().get("right_arm", {}).get("state") == "waiting for flag left_done")
        until(driver, lambda d: d.find_element(By.CSS_SELECTOR, '.tab[data-view="builder"]').click() or True)  # Start showed the monitor
        engine = station.session.edit_target.engine  # type: ignore[union-attr]
        old = engine.app
        until(driver, lambda d: lock(d, 0) == "done" and lock(d, 2) is None)  # reach has run; closer, held before, is open
        until(driver, lambda d: lock(d, 1) == "running" and lock(d, 3) is None)  # the right arm is in right_wait (each group's position)

        until(driver, lambda d: cell(d, 2, "left_arm").click() or True)  # the left hand sent to where the right one waits
        assert apply_edit(driver, RIGHT_OUT, 1) == "refused", text(driver, "validation-summary")
        until(driver, lambda d: "has-error" in (cell(d, 2, "left_arm").get_attribute("class") or "") and "collision" in cell(d, 2, "left_arm").text)
        assert "found by the dry run of the operations no group has started" in text(driver, "validation-summary")
        assert text(driver, "engine-state") == "paused" and engine.app is old  # nothing changed

        assert apply_edit(driver, WIDER, 2) == "swapped", text(driver, "validation-summary")
        assert WHERE in text(driver, "validation-summary")
        assert engine.app is not old and engine.app.operation("closer").calls["left_arm"].params[0] == WIDER

        press(driver, "ctl-resume")
        until(driver, lambda d: text(d, "engine-state") == "finished")
        records = station.feed.read(0, 0)[1]
        (swap,) = [r for r in records if r["event"] == "swap"]
        assert swap["groups"]["left_arm"] == {"where": "before", "operation": 3} and swap["groups"]["right_arm"] == {"where": "in", "operation": 2}
        moved = [r["outcome"] for r in records if r["event"] == "function_end" and r["operation"] == "closer" and r["group"] == "left_arm"]
        assert moved == ["succeeded"] and records[-1]["event"] == "run_end" and records[-1]["outcome"] == "finished"
    finally:
        served.close()
