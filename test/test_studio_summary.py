"""The monitor's run summary and ETA in a real headless Chromium, live at --speed 10 and in the replay of that run.

Live: the top bar's ETA says the wall seconds left and the run seconds they are at x10 (both, and the one ten
times the other); once the run has ended the summary panel shows what operator_station/run_summary.py makes of
the trace the run wrote -- outcome, cycle against the dry run's prediction, a row per group, the vision fault
the retry recovered with what to do.  Replay: the panel is hidden with the slider mid-run and shown at the
recording's end, and the ETA says what is left of the recording at the cursor.
"""
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

from operator_station.run_summary import ADVICE, summarize  # noqa: E402
from test_studio_browser import driver  # noqa: E402, F401 - the module's headless Chromium, as a fixture
from test_studio_graphs import ROOT, open_station, until  # noqa: E402

ETA = re.compile(r"^(?:(\d+\.\d) s|(\d+) min (\d+) s) \((?:(\d+\.\d) s|(\d+) min (\d+) s) run time at x10\)$")


def seconds(a: str | None, m: str | None, s: str | None) -> float:
    return float(a) if a is not None else 60 * int(m or 0) + int(s or 0)


def panel(driver: Any) -> dict[str, Any]:
    return driver.execute_script("""
      const box = document.getElementById('run-summary');
      return {hidden: box.hidden, outcome: (box.querySelector('.summary-outcome') || {}).textContent,
              cycle: (box.querySelector('.summary-cycle') || {}).textContent, text: box.textContent,
              groups: [...box.querySelectorAll('.summary-groups tbody tr')].map((r) => r.dataset.group),
              errors: [...box.querySelectorAll('.summary-error')].map((e) => [e.dataset.group, e.classList.contains('recovered'),
                        [...e.querySelectorAll('.summary-actions li')].map((li) => li.textContent)])};""")


def test_the_summary_after_a_run_and_at_the_end_of_its_replay_and_the_eta_in_wall_and_run_time(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    trace = tmp_path / "run.jsonl"
    served = open_station(driver, tmp_path, file="rivet_installation.xml", speed=10.0, trace=str(trace), fault=["left_arm:vision"])
    try:
        until(driver, "Builder.state.valid === true")
        driver.find_element("id", "ctl-start").click()
        driver.find_element("id", "tab-monitor").click()
        shown = until(driver, "Store.snapshot.eta && Store.snapshot.eta.operation > 0 && document.getElementById('engine-state').textContent === 'running'"
                              " && document.getElementById('engine-eta').textContent")
        found = ETA.match(shown)
        assert found, shown
        wall, run = seconds(*found.group(1, 2, 3)), seconds(*found.group(4, 5, 6))
        assert run == pytest.approx(10 * wall, abs=10 * 0.05 + 1.0), shown  # each rounded as shown
        assert panel(driver)["hidden"]  # no summary while it runs
        until(driver, "document.body.dataset.summary === 'finished'")
        served.station.session.join(90.0)  # type: ignore[union-attr]
        records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
        expected = summarize(records, driver.execute_script("return Store.snapshot.plan"))
        live = panel(driver)
        assert not live["hidden"] and live["outcome"] == "finished" and expected.predicted is not None
        assert live["cycle"] == summary_seconds(expected.cycle_time) and f"against {summary_seconds(expected.predicted)} predicted" in live["text"]
        assert live["groups"] == [g.group for g in expected.groups]
        (error,) = live["errors"]
        assert error[0] == "left_arm" and error[1] and ADVICE["vision"] in error[2][0]
        assert document_eta(driver) == "–"
    finally:
        served.close()
    replay = open_station(driver, tmp_path, replay=str(trace))
    try:
        until(driver, f"Store.snapshot.mode === 'replay' && Store.records.length === {len(records)}")
        driver.get_log("browser")  # what the page said before this station (the live one closing) is not the replay's
        driver.find_element("id", "tab-monitor").click()
        middle = records[len(records) // 2]["t"]
        driver.execute_script(f"Store.setCursor({middle})")
        until(driver, "document.getElementById('run-summary').hidden === true")
        assert document_eta(driver) == f"{monitor_seconds(records[-1]['t'] - middle)} left in the recording"
        driver.execute_script(f"Store.setCursor({records[-1]['t']})")
        until(driver, "document.getElementById('run-summary').hidden === false")
        at_end = panel(driver)
        assert at_end["outcome"] == "finished" and f"against {summary_seconds(expected.predicted)} predicted" in at_end["text"]  # the trace's plan
        assert [e[:2] for e in at_end["errors"]] == [["left_arm", True]]
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        replay.close()


def summary_seconds(s: float) -> str:
    """As the summary panel writes seconds (summary.js)."""
    return f"{s:.2f} s" if s < 60 else f"{int(s // 60)} min {s % 60:.1f} s"


def monitor_seconds(s: float) -> str:
    """As the top bar writes seconds (monitor.js)."""
    return f"{s:.1f} s" if s < 60 else f"{int(s // 60)} min {s % 60:.0f} s"


def document_eta(driver: Any) -> str:
    return str(driver.execute_script("return document.getElementById('engine-eta').textContent"))
