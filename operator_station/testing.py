"""Serving a station for tests, the screenshot script and the page benches: uvicorn on a free loopback port, in a
thread that stops by itself; the settings ``studio`` would parse, a folder holding copies of shipped applications,
and a bounded poll of a page expression.

The server thread is bounded: :meth:`ServedStation.close` asks uvicorn to exit and joins it; a
server that would not start within ``start_timeout`` wall seconds is an error, not a hang.
"""
from __future__ import annotations

import argparse
import math
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from operator_station.server import Station, create_app
from operator_station.serving import StationServer, server_config


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@dataclass
class ServedStation:
    station: Station
    url: str
    server: Any
    thread: threading.Thread

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(15.0)
        if self.station.session is not None and self.station.session.running:
            self.station.session.join(30.0)


def serve(station: Station, start_timeout: float = 15.0) -> ServedStation:
    """Serve ``station`` on 127.0.0.1 at a free port; returns once it accepts connections."""
    port = free_port()
    server = StationServer(server_config(create_app(station), "127.0.0.1", port), station)
    thread = threading.Thread(target=server.run, name="studio server", daemon=True)
    thread.start()
    deadline = time.monotonic() + start_timeout  # wall time: a real server on a real socket
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            raise RuntimeError(f"the station did not start on 127.0.0.1:{port} within {start_timeout} s")
        time.sleep(0.02)
    return ServedStation(station, f"http://127.0.0.1:{port}/", server, thread)


ROOT = Path(__file__).resolve().parent.parent


def station_args(**changes: Any) -> argparse.Namespace:
    """``studio``'s parsed options with their defaults (``--speed max``, trajectories in memory), ``changes`` applied."""
    args = argparse.Namespace(file=None, replay=None, controller_host=None, controller_port=None, rsi_listen=None, fault=None, seed=0,
                              backend_option=None, robot=None, speed=math.inf, trace=None, trajectory_db=":memory:", no_check=False)
    vars(args).update(changes)
    return args


@contextmanager
def shipped_apps(*apps: str, prefix: str = "studio_shots_") -> Iterator[Path]:
    """A temporary folder with copies of ``apps_xml/cells`` and of each named application of ``apps_xml``: a station
    started there may save and write beside them without touching the shipped files."""
    with tempfile.TemporaryDirectory(prefix=prefix) as name:
        folder = Path(name)
        shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
        for app in apps:
            shutil.copy(ROOT / "apps_xml" / app, folder / app)
        yield folder


def until(driver: Any, script: str, timeout: float = 120.0) -> Any:
    """Poll a page expression until it is truthy and return its value (bounded; wall time: the page is real)."""
    deadline = time.monotonic() + timeout
    while True:
        value = driver.execute_script(f"try {{ return ({script}); }} catch (e) {{ return null; }}")
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"the page never showed: {script}")
        time.sleep(0.02)
