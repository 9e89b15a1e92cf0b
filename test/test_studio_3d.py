"""The 3D view in a real headless Chromium (Selenium): the robot follows the joint states of a live run, the dry run's
collision of the two arms is shown on the robot (the two hands it names turned red) -- and, run without the dry run, at
the moment the simulator stops it with the hands where they met --, and a recording replayed puts the robot where its
joint states say at each slider position.

Skipped only where no Chromium can be driven (the reason says what is missing).  Waits are bounded polls of what the
page shows (WebDriverWait), never a fixed sleep; the page's hook ``window.view3d`` reads the drawn scene itself (the
URDF robot's joint angles, its TCP through the URDF's chain, the colour a body is drawn in).
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

from selenium.common.exceptions import ElementClickInterceptedException, JavascriptException, NoSuchElementException, StaleElementReferenceException  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.dry_run.collisions import scene_of  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import ServedStation, serve  # noqa: E402
from test_scene3d import arms_meet, cli, demonstrator, dry_run_of, record, recorded_joint_states  # noqa: E402
from test_studio_server import station_args  # noqa: E402

WAIT = 120.0  # wall seconds any one condition may take (a dry run and a run on a loaded CI machine), then the test fails
HANDS = re.compile(r"collision between left_arm hand \((\w+)\) and right_arm hand \((\w+)\), .* \(at (\d+\.\d+) s\)$")


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    chrome = browser.chromium(1280, 860)
    try:
        yield chrome
    finally:
        chrome.quit()


def until(driver: Any, condition: Any, timeout: float = WAIT) -> Any:
    ignored = (NoSuchElementException, StaleElementReferenceException, ElementClickInterceptedException, JavascriptException)
    return WebDriverWait(driver, timeout, poll_frequency=0.05, ignored_exceptions=ignored).until(condition)


def open_3d(driver: Any, folder: Path, **changes: Any) -> ServedStation:
    """Serve a station, load its page, show the 3D tab once its robot is drawn."""
    served = serve(build_station(station_args(**changes), full_catalog(), folder))
    driver.get(served.url)
    until(driver, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "true")
    until(driver, lambda d: d.execute_script("return window.view3d.ready()"))
    show_3d(driver)
    return served


def show_3d(driver: Any) -> None:
    """Show the 3D tab; clicked again while not shown (a started run shows the monitor when the station answers, which
    on a loaded machine can come after the click)."""
    until(driver, lambda d: "active" in d.find_element(By.ID, "view-view3d").get_attribute("class")
          or (d.find_element(By.ID, "tab-view3d").click() or False))


def last_tcps(trace: Path) -> dict[str, dict[str, float]]:
    """Each arm's TCP as the bridge reported it at the end of its last motion."""
    out: dict[str, dict[str, float]] = {}
    for line in trace.read_text(encoding="utf-8").splitlines():
        record = json.loads(line)
        tcp = (record.get("result") or {}).get("tcp") if record["event"] == "primitive_end" else None
        if tcp:
            out[record["group"]] = tcp
    return out


def override(driver: Any, percent: int) -> None:
    """Move the control bar's speed slider to ``percent`` and wait for the station's answer."""
    driver.execute_script("const s = document.getElementById('speed-override'); s.value = String(arguments[0]);"
                          "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));", percent)
    until(driver, lambda d: f"speed override {percent} %" in d.find_element(By.ID, "control-answer").text)


#: % of the speed the arms move at between two holds: 0.4x real time at --speed 4, so a loaded machine's page still
#: sees the next motion under way (at 25 % CI once saw the run end after one hold)
PACE = 10

HELD = """
    const s = Store.joints.samples, views = Store.groupView();
    if (s.length < 2) return null;
    const [a, b] = s.slice(-2);
    return {drawn: view3d.jointValues(), names: Store.joints.names, sample: b.slice(1), still: a.every((v, i) => i === 0 || v === b[i]),
            goals: view3d.goals(), primitives: Object.fromEntries(Object.entries(views).map(([g, v]) => [g, v.primitive]))};"""


def drawn_is_sample(now: dict[str, Any]) -> bool:
    """The drawn joints are the page's last joint sample."""
    return all(abs(now["drawn"][name] - value) <= 1e-9 for name, value in zip(now["names"], now["sample"]))


def moving(now: dict[str, Any]) -> list[dict[str, Any]]:
    """The goals drawn that are the targets of the motions the monitor says the arms are in."""
    return [g for g in now["goals"] if g["kind"] == "pose" and now["primitives"].get(g["group"]) and g["label"] in now["primitives"][g["group"]]]


def test_the_robot_follows_a_live_runs_joint_states(driver: Any, tmp_path: Path) -> None:
    """Mid-run, twice, the run held on its path by the speed override at 0 %: the drawn joints are the joint state the
    page received last, and an arm's goal drawn is the target of the motion the monitor says the arm is in.  At the
    end, each hand drawn through the URDF's chain is where the bridge said it ended."""
    app = demonstrator(tmp_path, "rivet_first_three", 3)
    trace = tmp_path / "run.jsonl"
    served = open_3d(driver, tmp_path, file=app.name, speed=4.0, trace=str(trace))
    try:
        override(driver, PACE)  # for the next run: the arms move at a pace the page's polls follow
        until(driver, lambda d: d.find_element(By.ID, "ctl-start").click() or True)
        show_3d(driver)
        seen: list[dict[str, float]] = []

        def moved_on(d: Any) -> bool:  # an arm in a motion, the arms elsewhere than where they were last held
            now = d.execute_script(HELD)
            return now is not None and bool(moving(now)) and (not seen or max(abs(seen[-1][n] - v) for n, v in zip(now["names"], now["sample"])) > 0.05)

        for _ in range(20):  # each round: wait for a motion elsewhere, hold it, look; bounded
            until(driver, lambda d: d.find_element(By.ID, "engine-state").text == "finished" or moved_on(d))
            assert driver.find_element(By.ID, "engine-state").text != "finished", f"the run ended after {len(seen)} held pose(s) seen"
            override(driver, 0)
            now = until(driver, lambda d: (n := d.execute_script(HELD)) is not None and n["still"] and drawn_is_sample(n) and n)
            if moving(now):  # (the motion ended before the hold: no goal to compare, go on)
                seen.append(dict(zip(now["names"], now["sample"])))
            override(driver, PACE if len(seen) < 2 else 100)
            if len(seen) >= 2:
                break
        assert len(seen) >= 2
        until(driver, lambda d: d.find_element(By.ID, "engine-state").text == "finished")
        # at the end: the robot drawn through the URDF's chain puts each hand where the bridge said it ended
        reported = last_tcps(trace)
        for group in ("left_arm", "right_arm"):
            drawn = until(driver, lambda d, g=group: d.execute_script("view3d.update(); return view3d.tcp(arguments[0])", g))
            assert drawn[:3] == pytest.approx([reported[group][k] for k in ("x", "y", "z")], abs=2e-4), group
        show_3d(driver)  # (a started run shows the monitor: the frames are drawn while the 3D tab is shown)
        stats = driver.execute_script("return view3d.measure(30)")
        assert stats["frames"] >= 30 and stats["render_ms_mean"] > 0  # the frame-time counter the bench reads
    finally:
        served.close()


def test_the_dry_runs_collision_of_the_two_arms_is_shown_on_the_robot(driver: Any, tmp_path: Path) -> None:
    """Must show (issue 25): the dry run refuses the run; the 3D view turns the two bodies it named red, with the robot
    drawn as the dry run had it at the collision's instant: the two hands meet where they stood apart before."""
    app = arms_meet(tmp_path)
    code, _, err = cli("validate", "--simulate", str(app))
    named = [m.groups() for line in err.splitlines() if (m := HANDS.search(line))]
    assert code == 1 and named, err
    finding = next(f for f in dry_run_of(app).findings if f.kind == "collision")
    at_collision = dict(zip(*finding.joints))  # type: ignore[arg-type]
    served = open_3d(driver, tmp_path, file=app.name)
    try:
        assert driver.execute_script("return view3d.highlighted()") == []
        hands = [f"{side}ARM_JOINT5_Link" for side in ("L", "R")]
        assert math.dist(*(driver.execute_script("return view3d.linkPosition(arguments[0])", n) for n in hands)) > 0.2  # apart at the start
        colour = driver.execute_script("return view3d.colour('LARM_JOINT5_Link')")
        until(driver, lambda d: d.find_element(By.ID, "ctl-start").click() or True)
        until(driver, lambda d: "not run" in d.find_element(By.ID, "run-messages").text + d.find_element(By.ID, "alarms").text
              or d.execute_script("return view3d.highlighted().length") > 0)
        show_3d(driver)
        until(driver, lambda d: d.execute_script("return view3d.highlighted().length") == 2)
        assert sorted(driver.execute_script("return view3d.highlighted()")) == sorted(named[0][:2])
        for name in named[0][:2]:
            assert driver.execute_script("return view3d.colour(arguments[0])", name) == "#e0201b" != colour
        found = driver.execute_script("return view3d.findings()")
        assert {(f["kind"], f["source"], tuple(f["bodies"]), round(f["t"], 2)) for f in found} == {("collision", "dry run", tuple(named[0][:2]), float(named[0][2]))}
        assert "collision: left_arm approach" in driver.find_element(By.ID, "view3d-findings").text
        assert driver.execute_script("return view3d.places()") == [f"at drill_1, {float(named[0][2]):.2f} s"]  # the hole both calls work at
        # at its moment: the robot drawn with the joints the dry run found at the collision, the time said above the view
        shown = driver.execute_script("return view3d.shown()")
        assert (shown["source"], shown["bodies"], shown["t"]) == ("dry run", list(named[0][:2]), finding.t)
        drawn = driver.execute_script("return view3d.jointValues()")
        assert set(drawn) == set(at_collision) and all(drawn[n] == pytest.approx(v, abs=1e-9) for n, v in at_collision.items())
        assert driver.find_element(By.ID, "view3d-time").text == f"dry run {finding.t:.2f} s"
        scene = scene_of(load_application(app, full_catalog()))
        assert scene is not None
        pin.framesForwardKinematics(scene.model, scene.data, np.array([at_collision[n] for n in scene.joint_names]))
        left, right = (driver.execute_script("return view3d.linkPosition(arguments[0])", n) for n in hands)
        for name, drawn_at in zip(hands, (left, right)):  # the drawn links are the collision model's at that instant
            assert drawn_at == pytest.approx(list(scene.data.oMf[scene.model.getFrameId(name)].translation), abs=1e-4), name
        assert math.dist(left, right) < 0.01  # the two hands' frames within 10 mm: they meet
        # the finding list: a click on the finding shown draws the robot as it is (apart), on the other finding at its moment
        rows = driver.find_elements(By.CSS_SELECTOR, "#view3d-findings .finding")
        assert len(rows) == 2 and "shown" in rows[0].get_attribute("class")
        until(driver, lambda d: d.find_elements(By.CSS_SELECTOR, "#view3d-findings .finding")[0].click() or True)
        until(driver, lambda d: d.execute_script("return view3d.shown()") is None)
        assert math.dist(*(driver.execute_script("return view3d.linkPosition(arguments[0])", n) for n in hands)) > 0.2
        until(driver, lambda d: d.find_elements(By.CSS_SELECTOR, "#view3d-findings .finding")[1].click() or True)
        until(driver, lambda d: (d.execute_script("return view3d.shown()") or {}).get("joints") == at_collision)  # the right arm's finding, same instant
        assert math.dist(*(driver.execute_script("return view3d.linkPosition(arguments[0])", n) for n in hands)) < 0.01
    finally:
        served.close()


def test_a_collision_the_simulator_stops_is_shown_at_its_moment_with_the_hands_where_they_met(driver: Any, tmp_path: Path) -> None:
    """The same application run without the dry run (--no-check): the simulator's own check stops the right arm as the
    hands meet; the view highlights the two hands from that record's time on, not before, drawn where they met."""
    app = arms_meet(tmp_path)
    served = open_3d(driver, tmp_path, file=app.name, no_check=True)
    try:
        until(driver, lambda d: d.find_element(By.ID, "ctl-start").click() or True)
        until(driver, lambda d: d.find_element(By.ID, "engine-state").text == "failed")
        show_3d(driver)
        until(driver, lambda d: d.execute_script("return view3d.findings().length") > 0)
        found = driver.execute_script("return view3d.findings()")
        assert len(found) == 1 and found[0]["source"] == "run" and found[0]["bodies"] == ["LARM_JOINT5_Link", "RARM_JOINT5_Link"]
        error = next(r for r in driver.execute_script("return Store.records") if r["event"] == "error")
        assert found[0]["t"] == error["t"] and "collision between left_arm hand (LARM_JOINT5_Link) and right_arm hand (RARM_JOINT5_Link)" in error["error"]
        slide = "const s = document.getElementById('view3d-slider'); s.value = arguments[0]; s.dispatchEvent(new Event('input'))"
        driver.execute_script(slide, error["t"] - 0.5)
        until(driver, lambda d: d.execute_script("return view3d.highlighted()") == [])
        driver.execute_script(slide, error["t"])
        until(driver, lambda d: sorted(d.execute_script("return view3d.highlighted()")) == ["LARM_JOINT5_Link", "RARM_JOINT5_Link"])
        left, right = (driver.execute_script("return view3d.linkPosition(arguments[0])", name) for name in ("LARM_JOINT5_Link", "RARM_JOINT5_Link"))
        assert math.dist(left, right) < 0.1  # the two hands' frames a hand's width apart: where they met
    finally:
        served.close()


def test_a_replayed_recording_moves_the_robot_with_the_slider(driver: Any, tmp_path: Path) -> None:
    recording = record(tmp_path, demonstrator(tmp_path, "rivet_first_three", 3))
    states = recorded_joint_states(recording)
    epoch = states[0][0]
    served = open_3d(driver, tmp_path, replay=str(recording))
    try:
        until(driver, lambda d: d.execute_script("return view3d.run()") >= 0 and d.execute_script("return view3d.located().length") > 0)
        picked = [states[len(states) // 3], states[2 * len(states) // 3]]
        drawn = []
        for stamp, values in picked:
            t = (stamp - epoch) * 1e-9
            driver.execute_script("const s = document.getElementById('view3d-slider'); s.value = arguments[0]; s.dispatchEvent(new Event('input'))", t)
            until(driver, lambda d, v=values: all(abs(d.execute_script("return view3d.jointValues()")[n] - x) < 1e-9 for n, x in v.items()))
            drawn.append(driver.execute_script("return view3d.jointValues()"))
            assert driver.find_element(By.ID, "view3d-time").text.startswith("replay ")
        assert max(abs(drawn[0][n] - drawn[1][n]) for n in drawn[0]) > 0.05  # two instants, two poses
    finally:
        served.close()
