"""Must show (issue 26): in a real headless Chromium, moving the control bar's speed slider to 50 % halves the
running motion's joint velocities, measured from the joint states the page received; on the same path.  In the
replay of that run's trace, the slider (disabled) shows 100 % before the change and 50 % after it as the time
slider moves.

The run is paced (``--speed 0.5``: a robot second takes two wall seconds), so the page has time to act while the
arm cruises; every time compared is the run's clock, stamped on each joint sample.  Waits are bounded polls of
what the page shows.
"""
from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from app_functions.registry import full_catalog  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import serve  # noqa: E402
from speed_override_checks import Samples, distance_to_path, settle_time  # noqa: E402
from test_studio_browser import driver, press, text, until, validated  # noqa: E402,F401 - driver: the fixture
from test_studio_server import station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
INITIAL = [math.radians(v) for v in (0.6, 0.0, -100.0, -15.2, 9.4, -3.2)]
START, GOAL = [-1.3, *INITIAL[1:]], [0.8, *INITIAL[1:]]  # LARM_JOINT0 at 1 rad/s from 0.67 s to 2.1 s of the move, clear of the torso


def move(joints: list[float]) -> str:
    values = ",".join(f"{v:.6f}" for v in joints)
    return f"<left_arm><function name='move_joints'><params><param value='{values}'/></params></function></left_arm>"


APP = f"""<?xml version="1.0" encoding="UTF-8"?>
<application name="slow_down" robot="nextage" cell="cells/rivet_cell.xml">
  <operation id="1">{move(START)}</operation>
  <operation id="2">{move(GOAL)}</operation>
</application>
"""


def joint_samples(driver: Any) -> Samples:
    """LARM_JOINT0..5 as the page received them (Store.joints), with their run times."""
    names, samples = driver.execute_script("return [Store.joints.names, Store.joints.samples];")
    columns = [1 + names.index(f"LARM_JOINT{k}") for k in range(6)]
    rows = np.array(samples, dtype=float)
    return Samples(rows[:, 0], rows[:, columns])


def test_moving_the_speed_slider_to_50_percent_halves_the_running_motions_joint_velocities(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    (tmp_path / "slow_down.xml").write_text(APP, encoding="utf-8")
    trace = tmp_path / "slow_down.jsonl"
    served = serve(build_station(station_args(file="slow_down.xml", speed=0.5, no_check=True, trace=str(trace)), full_catalog(), tmp_path))
    station = served.station
    try:
        driver.get(served.url)
        until(driver, lambda d: d.find_element("tag name", "body").get_attribute("data-ready") == "true")
        until(driver, lambda d: validated(d) == "valid")
        assert text(driver, "speed-value") == "100 %"
        press(driver, "ctl-start")

        def cruising(d: Any) -> bool:  # the second move, well past its ramp (cruise from -0.97 rad): LARM_JOINT0 on its way up at 1 rad/s
            samples = d.execute_script("const s = Store.joints; const i = s.names.indexOf('LARM_JOINT0');"
                                       "return s.samples.slice(-2).map(x => x[1 + i]);")
            return len(samples) == 2 and samples[1] > samples[0] and -0.6 < samples[1] < -0.2

        until(driver, cruising)
        driver.execute_script("const s = document.getElementById('speed-override'); s.value = '50';"
                              "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));")
        until(driver, lambda d: text(d, "speed-value") == "50 %" and "speed override 50 %" in text(d, "control-answer"))
        until(driver, lambda d: text(d, "engine-state") == "finished")
        changed = driver.execute_script(
            "return Store.records.filter(r => r.event === 'operator' && r.command === 'speed_override').map(r => [r.t, r.source, r.accepted, r.answer]);")
        samples = joint_samples(driver)
    finally:
        served.close()
    replay = serve(build_station(station_args(replay=str(trace)), full_catalog(), tmp_path))
    try:
        driver.get(replay.url)
        until(driver, lambda d: d.find_element("tag name", "body").get_attribute("data-ready") == "true")
        until(driver, lambda d: d.execute_script("return Store.records.length") > 0)
        shown = {}
        for at in (changed[0][0] - 0.5, changed[0][0] + 0.5):
            driver.execute_script("Store.setCursor(arguments[0]);", at)
            until(driver, lambda d: text(d, "speed-value") in ("100 %", "50 %"))
            shown[at] = (text(driver, "speed-value"), driver.find_element("id", "speed-override").get_attribute("disabled"))
    finally:
        replay.close()
    assert list(shown.values()) == [("100 %", "true"), ("50 %", "true")]
    assert len(changed) == 1 and changed[0][1:] == ["studio", True, "speed override 50 % (was 100 %)"]
    t = changed[0][0]  # the change on the run's clock, as the engine recorded it
    settle = settle_time(0.5, np.array([1.0]), np.array([1.5]))  # 1 rad/s, 1.5 rad/s^2: the rate halves within 0.33 s
    before = samples.window(t - 0.3, t).speed()[0]
    after = samples.window(t + settle + 0.1, t + settle + 1.0).speed()[0]
    assert before == pytest.approx(1.0, rel=0.05)
    assert after == pytest.approx(0.5 * before, rel=0.05)
    assert distance_to_path(samples.window(t - 0.3, samples.t[-1]).q, np.array([START, GOAL])) < 1e-6  # the same joint-space line
    audited = [e for e in station.audit_log.entries if e["what"] == "speed override"]
    assert [(e["ok"], e["before"], e["after"]) for e in audited] == [(True, "100 %", "50 %")]
    assert station.session is not None and station.session.speed_percent == 50.0
