"""``studio`` as a process: SIGTERM and SIGINT end it within 2 s, the robot brought to a controlled stop first,
whatever its pages did with the live feed (one connected and went away, one is still open).

The station runs the rivet demonstrator in real time; the test starts the run from the page's
side (a session from loading the page, JSON), watches the feed until both arms work, closes that
feed, opens another, and sends the signal.  The process must be gone 2 s later, the trace must end
with the engine's ``run_end`` (outcome ``stopped``: the run was stopped through the engine, not
cut), and the open feed must have been closed by the station.  Everything on loopback; every wait
bounded.
"""
from __future__ import annotations

import json
import os
import selectors
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from socket import create_connection

import pytest

pytest.importorskip("uvicorn", reason="the studio extra (starlette, uvicorn) is not installed")
import httpx  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402
from websockets.sync.client import ClientConnection, connect  # noqa: E402

from operator_station.testing import free_port  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: The bound the station must meet from the signal to the end of the process.
STOP_WITHIN = 2.0
#: Wall seconds the station may take to start (imports, the catalog) on a loaded machine.
START_WITHIN = 90.0


@pytest.fixture
def station(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], str, Path]]:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    trace = tmp_path / "run.jsonl"
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's code, run from the integrator's folder
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "studio", "rivet_installation.xml", "--port", str(port), "--speed", "1", "--no-check",
         "--trace", str(trace)],
        cwd=tmp_path, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        line = first_line(process)
        assert line.startswith(f"operator station on http://127.0.0.1:{port}/"), line
        wait_serving(process, port)  # start-up over: the bound measured after a signal is the stop's alone
        yield process, f"http://127.0.0.1:{port}", trace
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(10.0)
        assert process.stdout is not None and process.stderr is not None
        process.stdout.close()
        process.stderr.close()


def first_line(process: subprocess.Popen[str]) -> str:
    """The station's first line of output, waited for at most START_WITHIN wall seconds."""
    assert process.stdout is not None
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        if not selector.select(START_WITHIN):
            raise AssertionError(f"the station printed nothing within {START_WITHIN} s")
    return process.stdout.readline()


def wait_serving(process: subprocess.Popen[str], port: int) -> None:
    """Until the station accepts a connection, within START_WITHIN wall seconds.  Its first line comes before
    uvicorn listens and takes SIGTERM and SIGINT over; on a loaded machine the imports and the binding after
    it take long, and a page (or a signal) then met a station still starting.  Nothing of that start-up may
    count in the 2 s a stop is given, which are measured from the signal on."""
    deadline = time.monotonic() + START_WITHIN  # wall time: a real process starting
    for _ in range(int(START_WITHIN / 0.05)):
        assert process.poll() is None, "the station ended while starting"
        try:
            with create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:  # not listening yet
            time.sleep(max(0.0, min(0.05, deadline - time.monotonic())))
        if time.monotonic() >= deadline:
            break
    raise AssertionError(f"the station did not accept a connection within {START_WITHIN} s")


def feed(base: str, cookie: str) -> ClientConnection:
    """The live feed as the page opens it: its own origin, its session cookie."""
    return connect(base.replace("http", "ws") + "/ws", additional_headers={"Origin": base, "Cookie": cookie}, open_timeout=10.0, close_timeout=1.0)


def watch_until_both_arms_work(socket: ClientConnection, bound: float = 60.0) -> None:
    """Read the feed until the left and the right arm are both in a working state (bounded in count and time)."""
    deadline = time.monotonic() + bound  # wall time: a real process on a real socket
    for _ in range(100_000):
        message = json.loads(socket.recv(timeout=max(0.01, deadline - time.monotonic())))
        status = message.get("state", {}).get("status") if message["type"] == "state" else None
        groups = (status or {}).get("groups", {})
        if all(groups.get(g, {}).get("state") not in (None, "Ready", "Finish") for g in ("left_arm", "right_arm")):
            return
    raise AssertionError("both arms never worked")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_the_run_through_the_engine_and_the_station_within_2_s(station: tuple[subprocess.Popen[str], str, Path], signum: int) -> None:
    process, base, trace = station
    with httpx.Client(base_url=base, timeout=60.0) as client:
        assert client.get("/").status_code == 200
        cookie = "; ".join(f"{name}={value}" for name, value in client.cookies.items())
        document = client.get("/api/document").json()["document"]
        assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).json()["ok"]
    with feed(base, cookie) as first:
        watch_until_both_arms_work(first)
    with feed(base, cookie) as second:  # that page went away; another is still watching
        assert json.loads(second.recv(timeout=10.0))["type"] == "snapshot"
        process.send_signal(signum)  # the bound is measured from here: the station has long finished starting
        try:
            code = process.wait(STOP_WITHIN)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the station was still running {STOP_WITHIN} s after {signal.Signals(signum).name}")
        with pytest.raises(ConnectionClosed):
            for _ in range(10_000):  # the station closed the feed that was still open
                second.recv(timeout=1.0)
    assert process.stderr is not None
    err = process.stderr.read()
    assert code in (0, -signum), (code, err)  # SIGINT: exit 0 (Ctrl-C); SIGTERM: ended by the signal, as uvicorn re-raises it
    assert "Traceback" not in err, err
    records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
    assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "stopped", records[-3:]
    assert ("stop", "studio") in [(r.get("command"), r.get("source")) for r in records if r["event"] == "operator"]
    assert "stopping the run as the station ends" in err


def test_sigterm_ends_an_idle_station_whose_page_closed_its_feed(station: tuple[subprocess.Popen[str], str, Path]) -> None:
    """The case found: after a page closed its live feed, one SIGTERM no longer stopped the station."""
    process, base, _ = station
    with httpx.Client(base_url=base, timeout=60.0) as client:
        assert client.get("/").status_code == 200
        cookie = "; ".join(f"{name}={value}" for name, value in client.cookies.items())
    with feed(base, cookie) as socket:
        assert json.loads(socket.recv(timeout=10.0))["type"] == "snapshot"
    process.send_signal(signal.SIGTERM)
    try:
        process.wait(STOP_WITHIN)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the station was still running {STOP_WITHIN} s after SIGTERM")
