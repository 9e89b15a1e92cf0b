"""The timeline to read, in a real headless Chromium (issue 25 items 2 and 3): after a run of the asynchronous rivet
demonstrator the page shows a run-time axis, the critical path, the flag and zone waits by name and the dry run's
plan under each function, zooms and pans; a replay of the run's trace at the slider's time shows only what had
happened by then, on the whole run's axis, with the cursor there, and the planned bars the live run drew (the trace
holds the plan it was checked against).  Waits are bounded polls, never a fixed sleep."""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from execution_engine.timeline import TimelineBuilder, build_timeline  # noqa: E402
from execution_engine.timeline_path import critical_path, path_ids  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import serve  # noqa: E402
from operator_station.timeline_view import planned_of  # noqa: E402
from test_studio_browser import WAIT, driver, open_station, press, text, until, validated  # noqa: E402,F401 - driver: the module's browser
from test_studio_server import station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def page(driver: Any, script: str) -> Any:
    return driver.execute_script(f"return {script}")


def axis(driver: Any) -> list[tuple[float, str]]:
    return [(float(e.get_attribute("data-t")), e.text) for e in driver.find_elements(By.CSS_SELECTOR, "#tl-axis .tick-label")]


def shown_range(driver: Any) -> tuple[float, float]:
    svg = driver.find_element(By.ID, "timeline-svg")
    return float(svg.get_attribute("data-t0")), float(svg.get_attribute("data-t1"))


def clock_label(t: float) -> str:
    """How the axis writes a whole second past the first minute: min:ss."""
    return f"{int(t // 60)}:{int(round(t % 60)):02d}"


def test_the_timeline_reads_the_axis_the_critical_path_the_waits_and_the_plan_and_replays_to_the_slider(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_async.xml", tmp_path / "rivet_async.xml")
    trace = tmp_path / "run.jsonl"
    served = open_station(driver, tmp_path, file="rivet_async.xml", trace=str(trace))
    try:
        until(driver, lambda d: validated(d) == "valid")
        press(driver, "ctl-start")
        until(driver, lambda d: text(d, "engine-state") == "finished")
        served.station.session.join(WAIT)  # type: ignore[union-attr]
        records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
        planned = planned_of(served.station.feed.snapshot)
        assert planned, "the dry run before the run planned each function"
        press(driver, "tab-timeline")
        until(driver, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-timeline-records") == str(len(records)))
        timeline = build_timeline(records, served.station.feed.snapshot.groups, planned)

        # ---- the axis: the whole run, ticks a step apart, past a minute written min:ss
        end = records[-1]["t"]
        assert shown_range(driver) == (0.0, pytest.approx(end, abs=1e-3))
        ticks = axis(driver)
        steps = {round(b[0] - a[0], 6) for a, b in zip(ticks, ticks[1:])}
        assert len(ticks) >= 5 and len(steps) == 1 and end > 60
        assert [label for _, label in ticks] == [clock_label(t) for t, _ in ticks]

        # ---- the critical path: the model's, crossing from one arm to the other through a flag or zone
        expected = critical_path(timeline)
        assert page(driver, "Timeline.model().critical.map((s) => s.id)") == path_ids(expected)
        marked = {e.get_attribute("data-span") for e in driver.find_elements(By.CSS_SELECTOR, "#timeline-svg g.bar.critical")}
        assert marked == set(path_ids(expected)) and {s.bar.group for s in expected} == {"left_arm", "right_arm"}
        assert any(s.via.startswith(("flag ", "zone ")) for s in expected)

        # ---- the waits: named after what they waited for and whom, as the model names them
        labels = sorted(e.get_attribute("data-label") for e in driver.find_elements(By.CSS_SELECTOR, "#timeline-svg g.wait"))
        assert labels == sorted(g.label for lane in timeline.lanes.values() for g in lane.idle if g.waiting)
        assert "waiting for flag deburred_2 set by left_arm" in labels
        assert any(re.fullmatch(r"waiting for zone hands_\w+ held by (left|right)_arm", label) for label in labels)

        # ---- the plan: a thin bar per planned function, both durations on hover
        planned_rects = driver.find_elements(By.CSS_SELECTOR, "#timeline-svg rect.planned")
        assert sorted(float(r.get_attribute("data-planned")) for r in planned_rects) == pytest.approx(sorted(
            bar.planned for lane in timeline.lanes.values() for bar in lane.bars if bar.planned is not None and bar.attempt == 1))
        hover = driver.find_element(By.CSS_SELECTOR, '#timeline-svg g.bar[data-function="debur_drilling"] > title').get_attribute("textContent")
        assert re.search(r"planned \d+\.\d+ s \(dry run\), actual \d+\.\d+ s \([+-]\d+\.\d+ s\)", hover)

        # ---- zoom (buttons, wheel) narrows the axis and refines its step; a drag pans; fit shows the whole run again
        press(driver, "tl-zoom-in")
        press(driver, "tl-zoom-in")
        until(driver, lambda d: shown_range(d)[1] - shown_range(d)[0] == pytest.approx(end / 4, rel=1e-6))
        zoomed = shown_range(driver)
        finer = axis(driver)
        assert finer[1][0] - finer[0][0] < ticks[1][0] - ticks[0][0] and zoomed[0] <= finer[0][0] and finer[-1][0] <= zoomed[1]
        box = driver.find_element(By.ID, "timeline")
        driver.execute_script("arguments[0].dispatchEvent(new WheelEvent('wheel', {deltaY: -300, clientX: arguments[0].getBoundingClientRect().left + 400, bubbles: true, cancelable: true}))", box)
        until(driver, lambda d: shown_range(d)[1] - shown_range(d)[0] < (zoomed[1] - zoomed[0]) * 0.9)
        before = shown_range(driver)
        ActionChains(driver).move_to_element(box).click_and_hold().move_by_offset(-200, 0).release().perform()
        until(driver, lambda d: shown_range(d)[0] > before[0])
        assert shown_range(driver)[1] - shown_range(driver)[0] == pytest.approx(before[1] - before[0])
        press(driver, "tl-fit")
        until(driver, lambda d: shown_range(d) == (0.0, pytest.approx(end, abs=1e-3)))
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        served.close()

    # ---- replay of the trace: the slider at the middle shows what had happened by then, on the whole run's axis
    replay = serve(build_station(station_args(replay=str(trace)), full_catalog(), tmp_path))
    try:
        driver.get(replay.url)
        until(driver, lambda d: page(d, "Store.snapshot && Store.snapshot.mode === 'replay' && Store.records.length") == len(records))
        press(driver, "tab-timeline")
        until(driver, lambda d: page(d, "!!Timeline.model() && Timeline.model().records") == len(records))
        middle = round(end / 2, 2)
        driver.execute_script(f"Store.setCursor({middle})")
        until(driver, lambda d: page(d, "Timeline.model().end") == middle)
        assert shown_range(driver) == (0.0, pytest.approx(end, abs=1e-3))  # the axis stays the recording's
        assert float(driver.find_element(By.CSS_SELECTOR, "#timeline-svg line.cursor").get_attribute("data-t")) == middle
        cut = TimelineBuilder(served.station.feed.snapshot.groups).add_all(r for r in records if r["t"] <= middle).snapshot(middle)
        shown = page(driver, "Object.values(Timeline.model().lanes).flat().map((b) => [b.id, b.end])")
        assert sorted(i for i, _ in shown) == sorted(b.id for lane in cut.lanes.values() for b in lane.bars)
        assert max(e for _, e in shown) <= middle
        assert page(driver, "Timeline.model().critical.map((s) => s.id)") == path_ids(critical_path(cut))
        assert len(shown) < len([b for lane in timeline.lanes.values() for b in lane.bars])
        # the trace's plan record: the same planned bars as the live run drew, for the functions begun by the slider
        replayed = [float(r.get_attribute("data-planned")) for r in driver.find_elements(By.CSS_SELECTOR, "#timeline-svg rect.planned")]
        cut_planned = TimelineBuilder(served.station.feed.snapshot.groups, planned).add_all(r for r in records if r["t"] <= middle).snapshot(middle)
        assert replayed and sorted(replayed) == pytest.approx(sorted(
            bar.planned for lane in cut_planned.lanes.values() for bar in lane.bars if bar.planned is not None and bar.attempt == 1))
    finally:
        replay.close()
