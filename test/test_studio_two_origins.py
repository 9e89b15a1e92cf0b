"""A page of another origin, in a real headless Chromium that holds the operator's session, attacks the station.

The station serves on 127.0.0.1:P; the operator's page was loaded from it in this browser (so the
browser holds the station's session cookie).  Then the browser opens pages of three other origins:

* ``http://localhost:Q`` -- another site (the cookie is not sent with its requests);
* ``http://127.0.0.1:Q`` -- the same *site* as the station, another port: a SameSite cookie *is*
  sent, only the Origin check stands between it and the station;
* ``http://rebound.test:P`` -- DNS rebinding: Chromium resolves ``rebound.test`` to 127.0.0.1
  (``--host-resolver-rules``), so that page is "same-origin" with the station's socket.

From each, every way a page has to reach the station -- fetch with JSON (needs a CORS preflight),
fetch no-cors with text/plain, XMLHttpRequest, sendBeacon, form posts of the three form types
into a hidden frame, a WebSocket -- tries to start a run, resume, step, clear the safety stop,
read the live feed and the open application, open a file outside the station's folder and save
over one.  Each attempt fails, and the test checks the *station*: no run started, the paused run
still paused with its safety stop raised (the engine itself refuses the operator's resume
afterwards for that reason), no file read or written outside its folder, no engine command
recorded, nothing in the audit.  The same script from the station's own page does reach it
(the control).  Waits are bounded polls; the attack script bounds every attempt.
"""
from __future__ import annotations

import logging
import os
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
from operator_station import browser  # noqa: E402

if browser.missing() is not None:
    pytest.skip(f"no browser to drive: {browser.missing()}", allow_module_level=True)

import httpx  # noqa: E402

from app_functions.registry import full_catalog  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import ServedStation, serve  # noqa: E402
from test_studio_server import ROOT, cell_dir, station_args, wait_until  # noqa: E402, F401 - cell_dir: the station's folder

REBOUND = "rebound.test"

#: Every way a page has to send to the station, for each target; the results as the page saw them.
ATTACK = r"""
const [station, targets, done] = arguments;
const results = {};
const bounded = (promise, ms) => Promise.race([promise, new Promise((r) => setTimeout(() => r("no answer in time"), ms))]);
const forms = [];  // form posts navigate frames: sent all at once, then waited for together
const attempt = async (name, fn) => { try { results[name] = await bounded(fn(), 8000); } catch (e) { results[name] = `blocked: ${e.name}`; } };
for (const [name, [url, body]] of Object.entries(targets)) {
  const json = JSON.stringify(body);
  await attempt(`${name} fetch json`, async () => {
    const r = await fetch(station + url, {method: "POST", credentials: "include", headers: {"Content-Type": "application/json"}, body: json});
    return `read ${r.status}: ${await r.text()}`;
  });
  await attempt(`${name} fetch no-cors text`, async () => {
    const r = await fetch(station + url, {method: "POST", mode: "no-cors", credentials: "include", headers: {"Content-Type": "text/plain"}, body: json});
    return `sent, answer ${r.type}`;
  });
  await attempt(`${name} xhr`, () => new Promise((resolve) => {
    const x = new XMLHttpRequest();
    x.open("POST", station + url);
    x.withCredentials = true;
    x.setRequestHeader("Content-Type", "text/plain");
    x.onload = () => resolve(`read ${x.status}: ${x.responseText}`);
    x.onerror = () => resolve("blocked: error");
    x.send(json);
  }));
  await attempt(`${name} beacon`, async () => navigator.sendBeacon(station + url, new Blob([json], {type: "text/plain"})) ? "queued" : "not queued");
  for (const enctype of ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data"]) {
    forms.push(attempt(`${name} form ${enctype}`, () => new Promise((resolve) => {
      const frame = document.createElement("iframe");
      frame.name = `frame${forms.length}`;
      document.body.appendChild(frame);
      const form = document.createElement("form");
      Object.assign(form, {method: "POST", action: station + url, enctype, target: frame.name});
      const field = document.createElement("input");  // text/plain sends name=value: the JSON smuggled in a field's name
      Object.assign(field, {name: json.slice(0, -1) + ',"pad":"', value: '"}'});
      form.appendChild(field);
      document.body.appendChild(form);
      frame.onload = () => resolve("submitted, frame loaded");
      setTimeout(() => resolve("submitted"), 3000);  // a refused frame may never load: the station's log says what it got
      form.submit();
    })));
  }
}
await Promise.all(forms);
await attempt("feed", () => new Promise((resolve) => {
  const socket = new WebSocket(station.replace(/^http/, "ws") + "/ws");
  socket.onmessage = (event) => { socket.close(); resolve(`message: ${event.data.slice(0, 60)}`); };
  socket.onclose = (event) => resolve(`closed ${event.code}`);
}));
await attempt("read document", async () => {
  const r = await fetch(station + "/api/document", {credentials: "include"});
  return `read ${r.status}: ${await r.text()}`;
});
done(results);
"""


class Attacker(BaseHTTPRequestHandler):
    """The other site: one empty page."""

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        page = b"<!DOCTYPE html><html><head><title>another site</title></head><body>another site</body></html>"
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(page)))
        self.end_headers()
        self.wfile.write(page)

    def log_message(self, *args: Any) -> None:
        """Quiet."""


@pytest.fixture(scope="module")
def attacker() -> Iterator[int]:
    site = ThreadingHTTPServer(("127.0.0.1", 0), Attacker)
    thread = threading.Thread(target=site.serve_forever, kwargs={"poll_interval": 0.05}, name="another site", daemon=True)
    thread.start()
    try:
        yield int(site.server_address[1])
    finally:
        site.shutdown()
        site.server_close()
        thread.join(10.0)


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    chrome = browser.chromium(arguments=(f"--host-resolver-rules=MAP {REBOUND} 127.0.0.1",))
    chrome.set_script_timeout(300)
    try:
        yield chrome
    finally:
        chrome.quit()


@pytest.fixture
def private(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder outside the station's, holding an application no page may read."""
    folder = tmp_path_factory.mktemp("private")
    (folder / "secret.xml").write_text((ROOT / "apps_xml" / "rivet_installation.xml").read_text().replace("rivet_installation", "top_secret_cell"))
    return folder


@pytest.fixture
def refusals() -> Iterator[list[str]]:
    """What the station's guard refused, as it logged it."""
    seen: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            seen.append(record.getMessage())

    guard = logging.getLogger("operator_station.guard")
    handler, level = Keep(logging.INFO), guard.level
    guard.addHandler(handler)
    guard.setLevel(logging.INFO)
    try:
        yield seen
    finally:
        guard.removeHandler(handler)
        guard.setLevel(level)


def targets(document: dict[str, Any], station: Path, private: Path) -> dict[str, list[Any]]:
    return {
        "run": ["/api/run", {"path": "rivet_installation.xml", "document": document}],
        "start": ["/api/operator/start", {}],
        "resume": ["/api/operator/resume", {}],
        "step": ["/api/operator/step", {}],
        "clear safety stop": ["/api/safety/clear", {"confirm": True}],
        "lower safety stop": ["/api/safety", {"active": False}],
        "open outside": ["/api/open", {"path": str(private / "secret.xml")}],
        "save outside": ["/api/save", {"path": os.path.relpath(private / "planted.xml", station), "document": document}],
        "save inside": ["/api/save", {"path": "planted.xml", "document": document}],
    }


def attack(driver: Any, page: str, station: str, aims: dict[str, list[Any]]) -> dict[str, str]:
    driver.get(page)
    return dict(driver.execute_async_script(ATTACK, station, aims))


def operator_client(served: ServedStation) -> httpx.Client:
    """The operator's own tools: a session from loading the page on loopback."""
    client = httpx.Client(base_url=served.url, timeout=60.0)
    assert client.get("/").status_code == 200
    return client


def assert_nothing_got_through(results: dict[str, str], station: Path, private: Path) -> None:
    assert results, "the attack script ran nothing"
    for name, result in results.items():
        assert not result.startswith("read 200"), (name, result)
        assert "top_secret_cell" not in result and "rivet_installation" not in result, (name, result)  # nothing read back
        assert not result.startswith("message"), (name, result)
    assert results["feed"].startswith("closed"), results["feed"]
    assert not (station / "planted.xml").exists() and sorted(p.name for p in private.iterdir()) == ["secret.xml"]


def origins(attacker_port: int, station_port: int) -> list[tuple[str, str]]:
    """(page to attack from, the station's address as that page names it)."""
    station = f"http://127.0.0.1:{station_port}"
    return [(f"http://localhost:{attacker_port}/", station), (f"http://127.0.0.1:{attacker_port}/", station),
            (f"http://{REBOUND}:{station_port}/", "")]  # rebinding: the page names the station by its own, rebound, origin


def test_a_page_of_another_origin_cannot_start_a_run_read_the_feed_or_touch_a_file(driver: Any, attacker: int, cell_dir: Path, private: Path, refusals: list[str]) -> None:
    served = serve(build_station(station_args(file="rivet_installation.xml", speed=1.0, no_check=True), full_catalog(), cell_dir))
    try:
        driver.get(served.url)  # the operator's page: the browser now holds the station's session
        wait_until(lambda: driver.execute_script("return document.body.dataset.ready") == "true", 90.0)
        document = operator_client(served).get("/api/document").json()["document"]
        port = int(served.url.rstrip("/").rsplit(":", 1)[1])
        for page, station in origins(attacker, port):
            refusals.clear()
            results = attack(driver, page, station, targets(document, cell_dir, private))
            assert_nothing_got_through(results, cell_dir, private)
            assert served.station.feed.snapshot.run == 0 and not served.station.session.running  # type: ignore[union-attr]
            assert not served.station.audit
            refused = " ".join(refusals)
            for url in ("/api/run", "/api/operator/start", "/api/safety/clear", "/api/open", "/api/save"):
                assert f"POST {url} " in refused, (page, url, refusals[:5])  # the requests reached the station, which refused them
            assert f"WEBSOCKET /ws " in refused, page
        # the control: the same script from the station's own page does reach it
        own = attack(driver, served.url, "", {"open": ["/api/open", {"path": "rivet_installation.xml"}]})
        assert own["open fetch json"].startswith('read 200: {"ok":true') and own["feed"].startswith("message")
    finally:
        served.close()


def test_a_page_of_another_origin_cannot_clear_a_raised_safety_stop_nor_resume_the_robot(driver: Any, attacker: int, cell_dir: Path, private: Path, refusals: list[str]) -> None:
    served = serve(build_station(station_args(file="rivet_installation.xml", speed=1.0, no_check=True), full_catalog(), cell_dir))
    session = served.station.session
    assert session is not None
    operator = operator_client(served)
    try:
        driver.get(served.url)
        wait_until(lambda: driver.execute_script("return document.body.dataset.ready") == "true", 90.0)
        document = operator.get("/api/document").json()["document"]
        assert operator.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).json()["ok"]
        assert session.wait_started(60.0)
        assert operator.post("/api/safety", json={"active": True}).json()["ok"]
        paused = lambda: (served.station.feed.snapshot.status or {}).get("state") == "paused"  # noqa: E731
        assert wait_until(paused, 60.0)
        run = served.station.feed.snapshot.run
        commands = lambda: [(r["command"], r["source"]) for r in served.station.feed.records if r["event"] == "operator"]  # noqa: E731
        before, audit = commands(), list(served.station.audit)
        port = int(served.url.rstrip("/").rsplit(":", 1)[1])
        for page, station in origins(attacker, port):
            results = attack(driver, page, station, targets(document, cell_dir, private))
            assert_nothing_got_through(results, cell_dir, private)
            assert paused() and served.station.feed.snapshot.run == run and session.running
            assert commands() == before and list(served.station.audit) == audit  # no command reached the engine, nothing cleared
        # the engine itself still holds the safety stop: the operator's own resume is refused for that reason
        assert operator.post("/api/operator/resume", json={}).json() == {"ok": False, "answer": "the safety stop is still active"}
        assert "safety stop on" in " ".join(source for _, source in before)
    finally:
        operator.post("/api/operator/stop", json={})
        session.join(60.0)
        operator.close()
        served.close()
