"""The breakpoint and run-to routes (docs/studio.md, "Breakpoints"), registered by server.py in one line.

``POST /api/breakpoint`` ``{"action": "set"|"clear"|"toggle"|"clear_all", "operation": ID or "#N"}`` sets or
clears a breakpoint of the run going on, without changing the file (the builder's gutter changes the file's
``break="true"``); ``POST /api/run_to`` ``{"operation": ...}`` runs on to an operation and pauses before it.
The engine decides and records each (operator commands ``break``, ``unbreak``, ``unbreak_all``, ``run_to``,
source ``studio``, with the operation they name), so the trace, the recording and the run report show them; the
audit log gets them too.  An operator may do them (:mod:`operator_station.roles`): they move no robot beyond what
resume does.  A station attached to a cell calls the engine's services; a replay has no run to command.
"""
from __future__ import annotations

from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route

from execution_engine.engine.breakpoint_set import ACTIONS
from operator_station.access import OPERATOR
from operator_station.attach import AttachedSession
from operator_station.audit import record
from operator_station.roles import requires

#: Longest operation text taken (an id is at most 64 characters; a number fewer).
MAX_OPERATION = 128


def routes(station: Any) -> list[BaseRoute]:
    async def breakpoint_(request: Request) -> Response:
        return await _command(station, request, "breakpoint")

    async def run_to(request: Request) -> Response:
        return await _command(station, request, "run_to")

    return [
        Route("/api/breakpoint", requires(OPERATOR, "breakpoint")(breakpoint_), methods=["POST"]),
        Route("/api/run_to", requires(OPERATOR, "run to")(run_to), methods=["POST"]),
    ]


async def _command(station: Any, request: Request, route: str) -> Response:
    try:
        body = orjson.loads(await request.body() or b"{}")
    except orjson.JSONDecodeError as error:
        return _error(f"{route}: the request is not JSON: {error}")
    if not isinstance(body, dict):
        return _error(f"{route}: the request must be a JSON object")
    operation = body.get("operation", "")
    action = "run_to" if route == "run_to" else body.get("action", "toggle")
    if not isinstance(operation, str) or len(operation) > MAX_OPERATION:
        return _error(f"{route}: operation must be an operation's id or #N (text of at most {MAX_OPERATION} characters)")
    if route == "breakpoint" and action not in ACTIONS:
        return _error(f"breakpoint: action must be one of {', '.join(ACTIONS)}")
    if route == "run_to" and not operation.strip():
        return _error('run_to: give {"operation": ID or "#N"}: the operation to pause before')
    session = station.session
    if session is None:
        return _error("this station replays a trace; there is no run to command", 409)
    if isinstance(session, AttachedSession):  # on a ROS graph the engine records the call under the service's name: audited here
        station.cell_audit.expect(route)
    ok, answer, breakpoints = await session.breakpoint(action, operation)
    record(request, "run to" if route == "run_to" else f"breakpoint {action}", ok=ok, answer=answer, operation=operation)
    return JSONResponse({"ok": ok, "answer": answer, "breakpoints": breakpoints}, status_code=200 if ok else 409)


def _error(message: str, status: int = 400) -> JSONResponse:
    return JSONResponse({"ok": False, "error": message}, status_code=status)
