"""Editing the paused run from the builder (docs/studio.md, "Editing a paused run"), registered by server.py in one line.

``POST /api/edit`` ``{path, document}`` -- the builder's application, as ``/api/validate`` takes it -- is
validated by the project's validator, then handed to the engine of the station's run, which swaps the
operations not yet started for the document's only when the run is paused, the done and running ones are
unchanged and the dry run of the new remainder from where the robot is finds nothing
(:mod:`execution_engine.engine.remainder_swap`).  The answer carries the engine's one line, the validator's
messages and the dry run's findings placed at their cells, and after a swap the run's operations as they now
are.  Anything refused changes nothing: the run stays paused with its own remainder.  It is an engineer's
action (:mod:`operator_station.roles`) and goes to the audit log with both applications' digests.  Scripts
call it with the token (``Authorization: Bearer``) as the page does.
"""
from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route

from execution_engine.app_model.document import DocumentError
from execution_engine.engine.remainder_swap import application_digest
from operator_station import builder
from operator_station.access import ENGINEER, WHO, Who
from operator_station.audit import hex_digest, record
from operator_station.blocks import BlockDocument, calls_inside
from operator_station.paused_edit import operations_json, placer
from operator_station.roles import requires
from operator_station.session import SOURCE, RunSession


def routes(station: Any) -> list[BaseRoute]:
    async def edit(request: Request) -> Response:
        try:
            body = orjson.loads(await request.body() or b"{}")
            if not isinstance(body, dict):
                raise ValueError("the request must be a JSON object")
            path = station.resolve(body.get("path"))
            document = BlockDocument.from_json(body.get("document"))
            calls_inside(station.resolve, path, document)
        except (ValueError, DocumentError) as error:  # JSONDecodeError is a ValueError
            return _error(f"edit: {error}")
        session = station.session
        if session is None:
            return _error("edit: this station replays a record; there is no run to edit", 409)
        if not isinstance(session, RunSession):
            return _error("edit: the cell runs on the ROS graph; its run is edited where it was started (stop it, start the edited application)", 409)
        target = session.edit_target
        if target is None:
            return _refused(request, "edit: no run is going: Start runs the builder's application as it is", [], path)
        try:
            app, messages, _ = await asyncio.to_thread(builder.validate, document, path, station.catalog)
        except DocumentError as error:
            return _error(f"edit: {error}")
        shown = [m.to_json() for m in messages]
        if app is None:
            return _refused(request, "edit: the edited application has errors (listed at their cells); nothing changed", shown, path)
        before = hex_digest(application_digest(target.engine.app)) if target.engine.app is not None else None  # as the trace's, sha256:
        answer = await target.swap(app, station.folders.shown(path), f"{SOURCE} ({_who(request)})")
        shown += [m.to_json() for m in placer(document, path)(list(answer.findings))]
        if not answer.ok:
            return _refused(request, answer.message, shown, path, before)
        assert answer.swap is not None
        operations = operations_json(app, station.catalog)
        session.feed.update(operations=operations)  # pages that connect from now on list the run's operations as they are
        record(request, "edit paused run", ok=True, answer=answer.message, before=hex_digest(answer.swap.old_digest), after=hex_digest(answer.swap.new_digest),
               path=station.folders.shown(path), from_operation=answer.swap.frontier + 1)
        return JSONResponse({"ok": True, "answer": answer.message, "messages": shown, "operations": operations, "from_operation": answer.swap.frontier + 1})

    return [Route("/api/edit", requires(ENGINEER, "edit")(edit), methods=["POST"])]


def _refused(request: Request, why: str, messages: list[dict[str, Any]], path: Path, before: str | None = None) -> JSONResponse:
    """Nothing changed: the one line, the messages at their cells, and the audit's entry."""
    record(request, "edit paused run", ok=False, answer=why, before=before, path=str(path))
    return JSONResponse({"ok": False, "answer": why, "error": why, "messages": messages}, status_code=409)


def _who(request: Request) -> str:
    who: Who | None = request.scope.get(WHO)
    name = (who.name or who.ident) if who is not None else ""
    return f"edit by {name}" if name else "edit"


def _error(message: str, status: int = 400) -> JSONResponse:
    return JSONResponse({"ok": False, "error": message}, status_code=status)
