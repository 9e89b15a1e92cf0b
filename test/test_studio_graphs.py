"""The monitor's state graphs in a real headless Chromium: laid out to be read, and following the run and the slider.

What an operator relies on, read from the rendered page: every label is at least 11 px on the screen at
the default size; Ready sits at the centre of the working states and the exceptional states (Pause, Stop,
ErrorHandling, Finish) lie outside the working states' hull, as do the edges into and out of them (the
transitions every working state has into Pause/Stop/ErrorHandling are one edge each, not 21 across the
working area); the current state and the last transition (a coloured edge with its trigger) are the ones the
records say -- after a step of a live run, and at several slider positions of its replay.  The expectations
come from the machine's table (Table 2) and the trace, not from the page.
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

from app_functions.registry import full_catalog  # noqa: E402
from execution_engine.machine.table import FINISH, READY, TABLE_2, WORKING_STATES  # noqa: E402
from execution_engine.smach import HISTORY  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import ServedStation, serve  # noqa: E402
from test_studio_browser import driver  # noqa: E402, F401 - the module's headless Chromium, as a fixture
from test_studio_server import station_args  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WAIT = 90.0  # wall seconds any one condition may take (a loaded CI machine), then the test fails
GROUPS = ("left_arm", "right_arm", "torso_head")
MIN_LABEL_PX = 11.0
EXCEPTIONAL = ("Pause", "Stop", "ErrorHandling", FINISH)

Point = tuple[float, float]


def until(driver: Any, script: str, timeout: float = WAIT) -> Any:
    """Poll a page expression (bounded) until it is truthy; its value."""
    from selenium.webdriver.support.ui import WebDriverWait  # optional: selenium, only where a browser is driven

    return WebDriverWait(driver, timeout, poll_frequency=0.05).until(
        lambda d: d.execute_script(f"try {{ return ({script}); }} catch (e) {{ return null; }}"))


def open_station(driver: Any, folder: Path, **changes: Any) -> ServedStation:
    served = serve(build_station(station_args(**changes), full_catalog(), folder))
    driver.get(served.url)
    until(driver, "document.body.dataset.ready === 'true'")
    return served


# ------------------------------------------------------------------------------ what the page drew
READ_GRAPH = """
Monitor.render();  // drawn from the records as they are now, read in the same turn of the page's loop
const out = {records: Store.visible()};
for (const g of arguments[0]) {
  const root = document.querySelector(`svg.state-graph[data-group="${g}"]`);
  if (!root) return null;
  const box = (el) => { const r = el.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; };
  const labels = [...root.querySelectorAll("text")].filter((t) => t.textContent).map((t) =>
    [t.textContent, parseFloat(getComputedStyle(t).fontSize) * t.getScreenCTM().a]);
  const states = {};
  for (const r of root.querySelectorAll("rect.state")) states[r.dataset.state] = box(r);
  const ctm = root.getScreenCTM();
  const edges = {};
  for (const p of root.querySelectorAll("path.edge")) {
    const length = p.getTotalLength(), pts = [];
    for (let i = 0; i <= 40; i++) { const q = p.getPointAtLength(length * i / 40); pts.push([q.x * ctm.a + ctm.e, q.y * ctm.d + ctm.f]); }
    edges[p.dataset.edge] = {points: pts, last: p.classList.contains("last")};
  }
  // the trigger shown: the lit edge's own label, or the trigger label beside a spoke
  const shown = [...root.querySelectorAll("text.edge-label.last[data-trigger], text.trigger[data-edge]")].filter((t) => t.textContent);
  out[g] = {labels, states, edges, active: [...root.querySelectorAll("rect.state.active")].map((r) => r.dataset.state),
            trigger: shown.map((t) => [t.textContent, t.dataset.edge])};
}
return out;
"""


def graphs(driver: Any) -> dict[str, Any]:
    return until(driver, f"(() => {{ {READ_GRAPH} }})()".replace("arguments[0]", json.dumps(list(GROUPS))))


def hull(points: list[Point]) -> list[Point]:
    """Convex hull (monotone chain), counter-clockwise in screen coordinates' sense of the cross product."""
    pts = sorted(set(points))
    cross = lambda o, a, b: (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])  # noqa: E731
    lower: list[Point] = []
    upper: list[Point] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def inside(polygon: list[Point], p: Point) -> bool:
    """Strictly inside the convex ``polygon`` (its vertices in order)."""
    signs = set()
    for (x0, y0), (x1, y1) in zip(polygon, polygon[1:] + polygon[:1]):
        c = (x1 - x0) * (p[1] - y0) - (y1 - y0) * (p[0] - x0)
        if abs(c) < 1e-6:
            return False
        signs.add(c > 0)
    return len(signs) == 1


def corners(box: list[float]) -> list[Point]:
    x0, y0, x1, y1 = box
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def grid(box: list[float], n: int = 6) -> list[Point]:
    x0, y0, x1, y1 = box
    return [(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * j / n) for i in range(n + 1) for j in range(n + 1)]


def expected_edge(record: dict[str, Any]) -> str:
    """The edge a transition is drawn on, by the page's stated rule, from Table 2: Ready and the working states
    are the hub (a spoke between them), the rest the band; hub -> band edges are one per (signal, target)."""
    source, signal = record["from"], record["signal"]
    target = TABLE_2[source][signal] if source in TABLE_2 else record["to"]
    hub = {READY, *WORKING_STATES}
    if source in hub and target in hub:
        return f"spoke:{target if source == READY else source}"
    if source in hub:
        return f"out:{signal}:{target}"
    if target in hub or target == HISTORY:
        return f"in:{source}:{signal}:{target}"
    return f"band:{source}:{signal}:{target}"


def check_layout(drawn: dict[str, Any]) -> None:
    for group in GROUPS:
        g = drawn[group]
        small = [(text, round(px, 2)) for text, px in g["labels"] if px < MIN_LABEL_PX]
        assert not small, f"{group}: labels under {MIN_LABEL_PX} px: {small}"
        assert {t for t, _ in g["labels"]} >= {READY, *WORKING_STATES, *EXCEPTIONAL}, f"{group}: a state has no label"
        centre = lambda b: ((b[0] + b[2]) / 2, (b[1] + b[3]) / 2)  # noqa: E731
        working = [centre(g["states"][s]) for s in WORKING_STATES]
        cx, cy = sum(p[0] for p in working) / len(working), sum(p[1] for p in working) / len(working)
        spread = sum(((p[0] - cx) ** 2 + (p[1] - cy) ** 2) ** 0.5 for p in working) / len(working)
        rx, ry = centre(g["states"][READY])
        assert ((rx - cx) ** 2 + (ry - cy) ** 2) ** 0.5 < 0.2 * spread, f"{group}: Ready is not at the centre of the working states"
        area = hull([c for s in WORKING_STATES for c in corners(g["states"][s])])
        assert inside(area, (rx, ry))
        for state in EXCEPTIONAL:
            assert not any(inside(area, p) for p in grid(g["states"][state])), f"{group}: {state} lies in the working states' hull"
        for state in WORKING_STATES:  # one spoke each, and the 21 exits into the band are 3 edges
            assert f"spoke:{state}" in g["edges"]
        into_band = [e for e in g["edges"] if e.startswith(("out:", "in:"))]
        assert sorted(into_band) == sorted(["out:pause:Pause", "out:stop:Stop", "out:error:ErrorHandling", "out:end:Finish",
                                            f"in:Pause:resume:{HISTORY}", "in:ErrorHandling:ok:Ready"])
        for name in into_band:
            crossing = [p for p in g["edges"][name]["points"] if inside(area, tuple(p))]
            assert not crossing, f"{group}: {name} crosses the working area at {crossing[:3]}"


def check_highlight(drawn: dict[str, Any], records: list[dict[str, Any]], until_t: float | None = None) -> None:
    """Each group's active state and last edge are those of its last transition record (up to ``until_t``)."""
    for group in GROUPS:
        moves = [r for r in records if r["event"] == "transition" and r["group"] == group and (until_t is None or r["t"] <= until_t)]
        g = drawn[group]
        assert g["active"] == [moves[-1]["to"] if moves else READY], group
        lit = sorted(name for name, e in g["edges"].items() if e["last"])
        if not moves:
            assert lit == [] and g["trigger"] == [], group
            continue
        edge = expected_edge(moves[-1])
        assert lit == [edge], f"{group}: lit {lit}, the last transition {moves[-1]['from']} -{moves[-1]['signal']}-> {moves[-1]['to']}"
        ((text, on),) = g["trigger"]  # one trigger shown, on that edge, naming the signal
        assert on == edge and text.split(" ", 1)[0] == moves[-1]["signal"], (group, g["trigger"])


def test_state_graphs_are_legible_laid_out_from_table_2_and_highlight_the_run_live_and_in_replay(driver: Any, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    trace = tmp_path / "run.jsonl"
    served = open_station(driver, tmp_path, file="rivet_installation.xml", speed=10.0, trace=str(trace))
    try:
        until(driver, "Builder.state.valid === true")
        driver.find_element("id", "ctl-start").click()
        driver.find_element("id", "tab-monitor").click()
        until(driver, "document.getElementById('engine-state').textContent === 'running'")
        driver.find_element("id", "ctl-step").click()  # the next operation runs, then the run pauses
        until(driver, "document.getElementById('engine-state').textContent === 'paused'")
        until(driver, "document.querySelectorAll('svg.state-graph path.edge.last').length === 3")
        drawn = graphs(driver)
        check_layout(drawn)
        check_highlight(drawn, drawn["records"])
        driver.find_element("id", "ctl-stop").click()
        until(driver, "Store.snapshot.ended === true")
        served.station.session.join(WAIT)  # type: ignore[union-attr]
    finally:
        served.close()
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    replay = open_station(driver, tmp_path, replay=str(trace))
    try:
        until(driver, f"Store.snapshot.mode === 'replay' && Store.records.length === {len(records)}")
        driver.get_log("browser")  # what the page said before this station (the live one closing) is not the replay's
        driver.find_element("id", "tab-monitor").click()
        moves = [r for r in records if r["event"] == "transition" and r["group"] == "left_arm"]
        for at in (moves[0]["t"] - 1e-3, moves[len(moves) // 2]["t"], moves[-1]["t"]):  # before any transition, mid-run, the end
            driver.execute_script(f"Store.setCursor({at})")
            until(driver, "document.querySelectorAll('svg.state-graph').length === 3")
            drawn = graphs(driver)
            check_highlight(drawn, records, at)
        check_layout(drawn)
        assert not [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        replay.close()
