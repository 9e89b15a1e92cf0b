"""The operator station in a real headless Chromium (Selenium): build, save, validate, run, pause, resume, check.

Skipped only where no Chromium can be driven (the reason says what is missing); ``.ci/run``
installs Debian's chromium and chromium-driver.  Waits are bounded polls of a condition the
page shows (WebDriverWait), never a fixed sleep.
"""
from __future__ import annotations

import io
import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.common.exceptions import (  # noqa: E402
    ElementClickInterceptedException,
    ElementNotInteractableException,
    NoSuchElementException,
    StaleElementReferenceException,
    TimeoutException,
)
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from execution_engine.timeline import build_timeline  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.program import main as cli_main  # noqa: E402
from operator_station.testing import ServedStation, serve  # noqa: E402
from test_studio_server import station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WAIT = 90.0  # wall seconds any one condition may take (a loaded CI machine), then the test fails


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    chrome = browser.chromium()
    try:
        yield chrome
    finally:
        chrome.quit()


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    return tmp_path


def open_station(driver: Any, folder: Path, **changes: Any) -> ServedStation:
    # The browser is shared by the file's tests: the page of a test before, left polling a station that has closed,
    # logs its failed requests after that test read its log; they are not this page's (CI at e60912b).
    driver.get("about:blank")
    driver.get_log("browser")
    served = serve(build_station(station_args(**changes), full_catalog(), folder))
    driver.get(served.url)
    until(driver, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "true")
    return served


def until(driver: Any, condition: Any, timeout: float = WAIT) -> Any:
    """Poll ``condition`` until it holds; the page re-renders rows as it goes, so a stale element means: look again
    (and a click landing on an input's suggestion list: click again)."""
    ignored = (NoSuchElementException, StaleElementReferenceException, ElementClickInterceptedException, ElementNotInteractableException)
    return WebDriverWait(driver, timeout, poll_frequency=0.05, ignored_exceptions=ignored).until(condition)


def press(driver: Any, element_id: str) -> None:
    """Click a button, again if something (an input's suggestion list) was in the way."""
    until(driver, lambda d: d.find_element(By.ID, element_id).click() or True)


def cell(driver: Any, op: int, group: str) -> Any:
    return driver.find_element(By.CSS_SELECTOR, f'.op-cell[data-op="{op}"][data-group="{group}"]')


def choose(driver: Any, op: int, group: str, function: str, *params: str) -> None:
    """Select a cell, pick its function from the catalog, type its params into the typed inputs."""
    until(driver, lambda d: cell(d, op, group).click() or True)
    until(driver, lambda d: d.find_element(By.CSS_SELECTOR, f'.catalog-fn[data-name="{function}"]').click() or True)
    until(driver, lambda d: d.find_element(By.ID, "fn-select").get_attribute("value") == function)
    for index, value in enumerate(params):
        type_into(driver, f"param-{index}", value)


def type_into(driver: Any, element_id: str, value: str) -> None:
    """Type into an input until it holds ``value`` (the inspector may be redrawn under the typing, e.g. when
    the cell's names arrive): then type again into the new input."""

    def typed(d: Any) -> bool:
        field = d.find_element(By.ID, element_id)
        if field.get_attribute("value") != value:
            field.clear()
            field.send_keys(value)
        return bool(d.find_element(By.ID, element_id).get_attribute("value") == value)

    until(driver, typed)


def text(driver: Any, element_id: str) -> str:
    return str(driver.find_element(By.ID, element_id).text)


def group_state(driver: Any, group: str) -> str:
    return str(driver.find_element(By.CSS_SELECTOR, f'.group-card[data-group="{group}"] .g-state').text)


def validated(driver: Any) -> str:
    """The validation summary once the validation of the last edit is in."""
    until(driver, lambda d: text(d, "validation-summary") not in ("", "validating…"))
    return text(driver, "validation-summary")


def test_built_in_the_page_saved_validated_run_paused_resumed_and_checked_against_the_trace(driver: Any, folder: Path) -> None:
    trace = folder / "run.jsonl"
    served = open_station(driver, folder, speed=2.0, trace=str(trace))
    try:
        # ---- the catalog lists every function; build from scratch: a new application, the rivet cell, two operations
        listed = {e.get_attribute("data-name") for e in driver.find_elements(By.CSS_SELECTOR, ".catalog-fn")}
        assert listed == set(full_catalog().names())
        press(driver, "new-btn")
        Select(driver.find_element(By.ID, "app-robot")).select_by_value("nextage_open")
        for field, value in (("doc-path", "built.xml"), ("app-name", "built_in_the_page"), ("app-cell", "cells/rivet_cell.xml")):
            type_into(driver, field, value)
        choose(driver, 0, "left_arm", "debur_drilling", "drill_1")
        choose(driver, 0, "right_arm", "pick_rivet", "rivet_1", "ref_R10")
        press(driver, "add-op")
        choose(driver, 1, "right_arm", "insert_rivet", "drill_1")
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "save-btn")
        until(driver, lambda d: text(d, "validation-summary") == "saved built.xml")
        assert cli_main(["validate", str(folder / "built.xml")], out=io.StringIO(), err=io.StringIO()) == 0
        saved = (folder / "built.xml").read_text(encoding="utf-8")
        assert "<function name='debur_drilling'>" in saved and "<param value='ref_R10'></param>" in saved

        # ---- run, pause both arms mid-motion from the page, resume
        press(driver, "ctl-start")
        working = lambda d: all(group_state(d, g) not in ("Ready", "Pause", "Finish", "") for g in ("left_arm", "right_arm"))  # noqa: E731
        both_paused = lambda d: text(d, "engine-state") == "paused" and all(group_state(d, g) == "Pause" for g in ("left_arm", "right_arm"))  # noqa: E731
        for attempt in range(1, 6):  # an arm between two primitives is held in Ready, not paused mid-motion: then try again
            until(driver, working)
            press(driver, "ctl-pause")
            until(driver, lambda d: text(d, "engine-state") == "paused")
            try:
                until(driver, both_paused, timeout=10.0)
                break
            except TimeoutException:
                press(driver, "ctl-resume")
                until(driver, lambda d: text(d, "engine-state") == "running")
        else:
            pytest.fail("the two arms were never both caught in a motion by five pauses")
        press(driver, "ctl-resume")
        until(driver, lambda d: text(d, "engine-state") == "finished")
        served.station.session.join(WAIT)  # type: ignore[union-attr]

        # ---- the page against the trace
        records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
        assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "finished"
        until(driver, lambda d: d.execute_script("return Store.records.length") == len(records))
        assert driver.execute_script("return Store.records") == records
        for group in ("left_arm", "right_arm", "torso_head"):
            last = [r["to"] for r in records if r["event"] == "transition" and r["group"] == group]
            until(driver, lambda d, g=group, s=(last[-1] if last else "Ready"): group_state(d, g) == s)
        operator = [(r["command"], r["source"]) for r in records if r["event"] == "operator"]
        assert operator == [("start", "studio"), *[("pause", "studio"), ("resume", "studio")] * attempt]
        for group in ("left_arm", "right_arm"):  # paused in a motion, resumed into it, and that function finished
            moves = [r for r in records if r["event"] == "transition" and r["group"] == group]
            paused = [i for i, r in enumerate(moves) if r["to"] == "Pause"][-1]
            assert moves[paused + 1]["from"] == "Pause" and moves[paused + 1]["to"] == moves[paused]["from"]
            request = moves[paused]["request_id"]
            assert any(r["event"] == "function_end" and r.get("request_id") == request and r["outcome"] == "succeeded" for r in records)

        press(driver, "tab-timeline")
        until(driver, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-timeline-records") == str(len(records)))
        timeline = build_timeline(records)
        bars = driver.find_elements(By.CSS_SELECTOR, "#timeline-svg g.bar")
        shown = sorted((b.get_attribute("data-group"), b.get_attribute("data-operation"), b.get_attribute("data-function")) for b in bars)
        assert shown == sorted((g, bar.operation, bar.function) for g, lane in timeline.lanes.items() for bar in lane.bars)
        assert len(driver.find_elements(By.CSS_SELECTOR, "#timeline-svg line.op-boundary")) == len(timeline.operations)
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]  # no error in the page's console
    finally:
        served.close()


def test_a_bad_edit_shows_the_validators_message_at_its_cell_and_nothing_runs(driver: Any, folder: Path) -> None:
    served = open_station(driver, folder, file="rivet_installation.xml")
    try:
        until(driver, lambda d: validated(d) == "valid")
        until(driver, lambda d: cell(d, 1, "left_arm").click() or True)  # debur_drilling(drill_1) in operation 2
        type_into(driver, "param-0", "drill_99")
        until(driver, lambda d: "has-error" in (cell(d, 1, "left_arm").get_attribute("class") or ""))
        until(driver, lambda d: "unknown frame 'drill_99'" in cell(d, 1, "left_arm").text)
        until(driver, lambda d: cell(d, 0, "left_arm").click() or True)  # set_speed(0.8): a fraction, given an angle's unit
        type_into(driver, "param-0", "0.8 deg")
        assert "deg" in text(driver, "param-problem-0")  # the page's own unit check, at once
        until(driver, lambda d: "has-error" in (cell(d, 0, "left_arm").get_attribute("class") or "") and "deg" in cell(d, 0, "left_arm").text)
        until(driver, lambda d: "has-error" not in (cell(d, 0, "right_arm").get_attribute("class") or ""))
        press(driver, "ctl-start")
        until(driver, lambda d: "not run" in text(d, "control-answer"))
        assert served.station.feed.snapshot.run == 0 and not served.station.session.running  # type: ignore[union-attr]
    finally:
        served.close()


def test_the_safety_stop_is_cleared_only_through_the_confirm_dialog_and_resume_needs_the_clear(driver: Any, folder: Path) -> None:
    """Raise from the page; a click on the raised stop asks first: Cancel leaves it raised (the engine still refuses
    Resume), Confirm clears it through /api/safety/clear and says who and when; then Resume runs the robot again."""
    served = open_station(driver, folder, file="rivet_installation.xml", speed=1.0, no_check=True)
    station = served.station
    try:
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "ctl-start")
        until(driver, lambda d: text(d, "engine-state") == "running")
        press(driver, "safety-stop")
        until(driver, lambda d: text(d, "engine-state") == "paused" and "ACTIVE" in text(d, "safety-stop"))
        dialog = driver.find_element(By.ID, "safety-dialog")
        press(driver, "safety-stop")  # asks first
        until(driver, lambda d: dialog.get_attribute("open") is not None)
        press(driver, "safety-dialog-cancel")
        until(driver, lambda d: dialog.get_attribute("open") is None and text(d, "control-answer") == "safety stop: not cleared")
        assert [e["action"] for e in station.audit] == ["safety stop raised"]
        press(driver, "ctl-resume")  # the engine refuses while the stop is raised
        until(driver, lambda d: text(d, "control-answer") == "resume: the safety stop is still active")
        assert text(driver, "engine-state") == "paused"

        press(driver, "safety-stop")
        until(driver, lambda d: dialog.get_attribute("open") is not None)
        press(driver, "safety-dialog-confirm")
        until(driver, lambda d: "safety stop cleared: resume to continue (logged: session " in text(d, "control-answer"))
        assert " from 127.0.0.1:" in text(driver, "control-answer") and text(driver, "safety-stop") == "SAFETY STOP"
        assert [e["action"] for e in station.audit] == ["safety stop raised", "safety stop cleared"]
        # the same session raised and cleared it (its address may name another of the browser's connections)
        assert station.audit[1]["who"].split(" from ")[0] == station.audit[0]["who"].split(" from ")[0] and station.audit[1]["who"].startswith("session ")
        until(driver, lambda d: "safety stop cleared" in ((station.feed.snapshot.status or {}).get("message") or ""))
        press(driver, "ctl-resume")
        until(driver, lambda d: text(d, "engine-state") == "running")
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        served.close()  # stops the run through the engine


def test_a_for_each_block_added_in_the_page_is_saved_as_a_loop_of_its_iterations(driver: Any, folder: Path) -> None:
    """The studio's blocks (issue 24): a loop added around a new operation, its fields typed, saved as a file that expands."""
    def block_field(css: str, value: str) -> None:
        def typed(d: Any) -> bool:
            field = d.find_element(By.CSS_SELECTOR, f'.blk-row[data-block="for_each"] {css}')
            if field.get_attribute("value") != value:
                field.send_keys(Keys.CONTROL, "a", Keys.NULL, value, Keys.TAB)  # a change is taken when the field is left
            return bool(d.find_element(By.CSS_SELECTOR, f'.blk-row[data-block="for_each"] {css}').get_attribute("value") == value)
        until(driver, typed)

    served = open_station(driver, folder, file="rivet_installation.xml")
    try:
        until(driver, lambda d: validated(d) == "valid")
        until(driver, lambda d: cell(d, 0, "torso_head").click() or True)  # after the first operation
        press(driver, "add-for-each")
        until(driver, lambda d: Select(d.find_element(By.CSS_SELECTOR, ".blk-row .blk-mode")).select_by_value("list") or True)
        block_field(".blk-list", "drill_1 drill_2")
        block_field(".blk-var", "h")
        until(driver, lambda d: "→ 2 iteration(s)" in d.find_element(By.CSS_SELECTOR, ".blk-row").text)
        type_into(driver, "doc-path", "looped.xml")
        def renamed(d: Any) -> bool:  # the operation inside the loop: one id per iteration
            field = d.find_element(By.CSS_SELECTOR, '.ops-row[data-op="1"] .op-id')
            if field.get_attribute("value") != "look_{h}":
                field.send_keys(Keys.CONTROL, "a", Keys.NULL, "look_{h}", Keys.TAB)
            return bool(d.find_element(By.CSS_SELECTOR, '.ops-row[data-op="1"] .op-id').get_attribute("value") == "look_{h}")
        until(driver, renamed)
        choose(driver, 1, "torso_head", "move_to_joint_pose", "look_at_part")
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "save-btn")
        until(driver, lambda d: text(d, "validation-summary") == "saved looped.xml")
        app = load_application(folder / "looped.xml", full_catalog())
        assert [(op.id, op.origin) for op in app.operations][:4] == [
            ("1", ""), ("look_drill_1", "for_each h=drill_1"), ("look_drill_2", "for_each h=drill_2"), ("2", "")]
        assert len(app.operations) == 12 and not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        served.close()
