"""Serving a station for tests and the screenshot script: uvicorn on a free loopback port, in a thread that stops by itself.

The server thread is bounded: :meth:`ServedStation.close` asks uvicorn to exit and joins it; a
server that would not start within ``start_timeout`` wall seconds is an error, not a hang.
"""
from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass
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
