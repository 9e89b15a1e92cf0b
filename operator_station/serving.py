"""Serving a station with uvicorn: bounded connections, and a shutdown that stops the robot first and ends within 2 s.

uvicorn turns SIGTERM and SIGINT into a graceful shutdown, which waits for every connection and
task of the application to end.  The live feed is such a task, and a page that closed its
socket used to leave it waiting on the next record for ever: one SIGTERM no longer stopped the
station.  :class:`StationServer` orders the shutdown itself:

1. the run the station started is stopped through the engine (``stop``, as the Stop button does:
   every group is told to stop, the trace gets its ``run_end``), waiting at most
   :data:`STOP_BOUND` seconds for the run's thread to end; a cell the station only watches is
   left running and the station leaves its graph;
2. every page's feed is told to end (:meth:`Station.stop`);
3. uvicorn closes the connections and cancels what has not ended after :data:`GRACE` seconds.

Every connection is bounded: at most :data:`MAX_CONNECTIONS` at once (503 beyond), WebSocket
messages from a page of at most :data:`WS_MAX_SIZE` bytes (the page sends none), idle
keep-alive connections closed after 5 s; ``X-Forwarded-*`` headers are not believed (no proxy
is in front of a station), so the log's client addresses are the peers'.  uvicorn's own log goes
through the command's console like every other record (no handlers of uvicorn's): a warning it
repeats -- a scanner's invalid requests -- is one counted line a second
(:mod:`node_transport.console_log`), not one line per request.
"""
from __future__ import annotations

import asyncio
import logging
from typing import Any

import uvicorn

from node_transport.clock import Clock, real_clock

log = logging.getLogger(__name__)

#: Wall seconds the run may take to come to its controlled stop when the station ends.
STOP_BOUND = 0.9
#: Wall seconds uvicorn gives connections and tasks to end before it cancels them.
GRACE = 0.3
#: Connections and tasks served at once (pages, API calls, feeds); more are answered 503.
MAX_CONNECTIONS = 64
#: Largest WebSocket message a page may send (it sends none; the feed only goes out).
WS_MAX_SIZE = 64 << 10


def server_config(app: Any, host: str, port: int) -> uvicorn.Config:
    """uvicorn's settings for a station: the bounds above, nothing from proxies, no lifespan, its log
    through the root logger (``log_config=None``: uvicorn's loggers get no handlers and propagate)."""
    return uvicorn.Config(
        app, host=host, port=port, log_level="warning", log_config=None, lifespan="off", ws="websockets-sansio",
        proxy_headers=False, server_header=False, limit_concurrency=MAX_CONNECTIONS, ws_max_size=WS_MAX_SIZE,
        timeout_keep_alive=5, timeout_graceful_shutdown=GRACE,  # type: ignore[arg-type] - uvicorn takes float seconds
    )


class StationServer(uvicorn.Server):
    """uvicorn's server, whose shutdown brings the station's run to a controlled stop first."""

    def __init__(self, config: uvicorn.Config, station: Any) -> None:
        super().__init__(config)
        self.station = station
        self.clock: Clock = real_clock()  # bound to the server's loop at the first wait

    async def shutdown(self, sockets: Any = None) -> None:
        await stop_station(self.station, self.clock, STOP_BOUND)
        await super().shutdown(sockets)


async def stop_station(station: Any, clock: Clock, bound: float) -> None:
    """Stop the station's own run through its engine (bounded), leave an attached cell, end every feed."""
    session = station.session
    try:
        if session is not None and session.running:
            deadline = clock.now() + bound
            try:
                ok, answer = await clock.wait_for(session.command("stop"), bound)
            except asyncio.TimeoutError:
                ok, answer = False, f"the engine did not answer within {bound:g} s"
            log.warning("studio: stopping the run as the station ends: %s", answer if ok else f"stop refused: {answer}")
            await asyncio.to_thread(session.join, max(0.0, deadline - clock.now()))
            if session.running:
                log.error("studio: the run had not ended %g s after the stop; the station ends anyway", bound)
        elif session is not None:  # a cell the station watches goes on; the station leaves its graph
            await asyncio.to_thread(session.join, bound)
    finally:
        station.stop()
