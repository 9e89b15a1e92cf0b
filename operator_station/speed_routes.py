"""The speed override's route (docs/studio.md, "Speed override"), registered by server.py in one line.

``POST /api/speed`` ``{"percent": P}`` (0..100): the running motion of every group goes on at ``P`` % of the
application's own speed on its path (0: held on the path), or the next run starts at it when none is going.
The engine decides and records it (operator command ``speed_override``, source ``studio``), so the trace, the
run report and the page's log show it as any other command; the audit log gets it too.  An operator may do it
(:mod:`operator_station.roles`).  A station attached to a cell on the ROS graph says how to set the engine's
parameter instead; a replay has no robot to slow.
"""
from __future__ import annotations

from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route

from operator_station.access import OPERATOR
from operator_station.audit import record
from operator_station.session import RunSession
from operator_station.roles import requires


def routes(station: Any) -> list[BaseRoute]:
    async def speed(request: Request) -> Response:
        try:
            body = orjson.loads(await request.body() or b"{}")
        except orjson.JSONDecodeError as error:
            return _error(f"speed: the request is not JSON: {error}")
        percent = body.get("percent") if isinstance(body, dict) else None
        if percent is None:
            return _error('speed: give {"percent": P}, P from 0 to 100 (% of the application\'s own speed; 0 holds on the path)')
        session = station.session
        if session is None:
            return _error("this station replays a trace; there is no robot to slow down", 409)
        if not isinstance(session, RunSession):
            return _error("speed: the cell runs on the ROS graph: set its engine's parameter, e.g. "
                          "ros2 param set /execution_engine speed_override 50", 409)
        before = f"{session.speed_percent:g} %"
        ok, answer = await session.speed_override(percent)
        record(request, "speed override", ok=ok, answer=answer, before=before, after=f"{session.speed_percent:g} %")
        return JSONResponse({"ok": ok, "answer": answer, "percent": session.speed_percent}, status_code=200 if ok else 400)

    return [Route("/api/speed", requires(OPERATOR, "speed override")(speed), methods=["POST"])]


def _error(message: str, status: int = 400) -> JSONResponse:
    return JSONResponse({"ok": False, "error": message}, status_code=status)
