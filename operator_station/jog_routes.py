"""The jog and teach routes of the station (docs/studio.md, "Jog and teach"), registered by server.py in one line.

* ``POST /api/jog/open`` ``{path, document}``: the jog's back end for that application's robot and cell (made
  the first time), its groups, joints, limits, the cell's frames, the speed caps and the jog's state;
* ``WS /ws/jog``: the button.  The page sends ``{"type": "start", group, mode, axis, direction, frame, speed}``
  when a button goes down, ``{"type": "beat"}`` every ~100 ms while it is held and ``{"type": "stop"}`` when it
  comes up; the station answers every change of the jog as ``{"type": "state", ...}``.  The socket closing (the
  page gone, the network down) stops the jog it started at once; a lapsed heartbeat stops it within its lease;
* ``POST /api/teach`` ``{path, document, group, name, parent}``: the group's TCP now as frame ``name`` under
  ``parent`` in the application's cell -- the diff and what validation says, nothing written;
* ``POST /api/teach/save`` ``{id, confirm: true}``: write that very diff, if the cell is unchanged since.

All of them are the engineer's (:mod:`operator_station.roles`) and every one that moves or writes is audited
(:mod:`operator_station.audit`).  Jogging is refused while a run is active (paused included), during the safety
stop, in a replay and when the station only watches a cell on the ROS graph.
"""
from __future__ import annotations

import asyncio
import itertools
import logging
from collections import OrderedDict
from pathlib import Path
from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from execution_engine.app_model import Application
from execution_engine.app_model.cell import read_cell
from execution_engine.app_model.document import DocumentError
from operator_station import builder
from operator_station.access import ENGINEER
from operator_station.attach import AttachedSession
from operator_station.audit import digest, hex_digest, log_of, record, requester
from operator_station.blocks import BlockDocument
from operator_station.jog_station import JogStation
from operator_station.roles import requires
from operator_station.session import RunSession
from robot_bridges.backend import BridgeError
from operator_station.teach import TeachPlan, TeachRefused, check_taught, plan_teach, save_taught

log = logging.getLogger(__name__)

#: Teach plans kept for their confirmation (the newest; an older one must be taught again).
MAX_PLANS = 16
#: Bytes of one message from the page on the jog socket.
MAX_MESSAGE = 4096


def refusal(station: Any) -> str | None:
    """Why the station may not jog now (None: it may)."""
    session = station.session
    if session is None:
        return "jog: this station replays a recording; there is no robot to jog"
    if isinstance(session, AttachedSession):
        return "jog: the cell runs on the ROS graph; the station jogs only a robot it drives itself"
    if isinstance(session, RunSession) and session.running:
        return "jog: a run is active (paused too): stop it before jogging"
    if station.jog.safety:
        return "jog: the safety stop is raised: clear it before jogging"
    return None


def routes(station: Any) -> list[BaseRoute]:
    """The routes, for a :class:`~operator_station.server.Station` that has a ``jog`` (:class:`JogStation`)."""
    jog: JogStation = station.jog
    plans: OrderedDict[str, tuple[TeachPlan, Path, str]] = OrderedDict()
    numbers = itertools.count(1)

    def noted(owner: object | None, what: str, ok: bool, answer: str, details: dict[str, Any]) -> None:
        """A jog's start or stop, from the jog's loop: audited under whoever holds the button (its socket)."""
        audit = log_of(owner) or station.audit_log
        audit.append(requester(owner), what, ok=ok, answer=answer, details=details)

    jog.note = noted

    async def validated(request: Request) -> tuple[dict[str, Any], Path, Application, str]:
        body = await _body(request)
        path = station.resolve(body.get("path"))
        document = BlockDocument.from_json(body.get("document"))
        app, messages, text = await asyncio.to_thread(builder.validate, document, path, station.catalog)
        if app is None:
            first = next((m.to_json().get("message", "") for m in messages if m.severity == "error"), "")
            raise ValueError(f"the application has errors; fix them first ({first})" if first else "the application has errors; fix them first")
        return body, path, app, text

    async def open_(request: Request) -> Response:
        refused = refusal(station)
        if refused:
            record(request, "jog open", ok=False, answer=refused)
            return _error(refused, 409)
        path: Path | None = None
        try:
            _, path, app, text = await validated(request)
            session = station.session
            described = await jog.open(app, session.backend_name(app), session.settings.backend.backend_options(app))
        except (ValueError, KeyError, DocumentError, ConnectionError, OSError, BridgeError) as error:  # OSError: a timeout too
            text = str(error).strip("'")
            text = text if text.startswith("jog: ") else f"jog: {text}"
            record(request, "jog open", ok=False, answer=text, **({"path": station.folders.shown(path)} if path is not None else {}))
            return _error(text)
        record(request, "jog open", answer=f"jogging {app.robot.name} on {described['backend']}", path=station.folders.shown(path),
               application=digest(text), backend=described["backend"])
        return JSONResponse({"ok": True, **described})

    async def state(request: Request) -> Response:
        return JSONResponse({"ok": True, "ready": jog.ready, "refusal": refusal(station), "state": jog.state.to_json()})

    async def socket(ws: WebSocket) -> None:
        await ws.accept()
        owner = ws  # the socket holds the button: its requester is who the jog's audit names
        record(ws, "jog connect", answer="the page's jog connection opened")
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=64)

        def heard(shown: dict[str, Any]) -> None:
            if not queue.full():
                queue.put_nowait({"type": "state", "state": shown})

        async def send() -> None:
            while True:
                await ws.send_text(orjson.dumps(await queue.get()).decode())

        listening = (asyncio.get_running_loop(), heard)
        jog.listeners.append(listening)
        sender = asyncio.ensure_future(send())
        try:
            while True:
                text = await ws.receive_text()
                if len(text) > MAX_MESSAGE:
                    await jog.stop("jog stopped: a message from the page over its size", owner, True)
                    await ws.close(code=1009)
                    return
                try:
                    message = orjson.loads(text)
                    kind = message.get("type") if isinstance(message, dict) else None
                except orjson.JSONDecodeError:
                    kind = None
                if kind == "beat":
                    jog.beat(owner)
                elif kind == "stop":
                    await jog.stop("jog released", owner)
                elif kind == "start":
                    await queue.put(await _start(station, jog, ws, message, owner))
                else:
                    await jog.stop("jog stopped: a message from the page that is not start, beat or stop", owner, True)
                    await queue.put({"type": "answer", "ok": False, "answer": "jog: messages are {type: start|beat|stop}"})
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            try:
                await jog.disconnect(owner, "jog stopped: the page's connection closed")  # audited there, after the stop
            finally:
                jog.listeners.remove(listening)
                sender.cancel()

    async def teach(request: Request) -> Response:
        try:
            body, path, app, text = await validated(request)
            if app.cell is None or app.cell.path is None:
                raise TeachRefused("teach: the application names no cell model to teach into")
            cell_path = station.resolve(str(app.cell.path))
            group, name, parent = body.get("group"), body.get("name"), body.get("parent", "world")
            if group not in app.robot.group_names:
                raise TeachRefused(f"teach: group must be one of {', '.join(app.robot.group_names)}, got {group!r}")
            tcp = await jog.tcp(group, app)
            if tcp is None:
                raise TeachRefused(f"teach: {group} has no TCP to teach")
            data = await asyncio.to_thread(cell_path.read_bytes)
            cell, _ = await asyncio.to_thread(read_cell, cell_path)
            if cell is None:
                raise TeachRefused(f"teach: {station.folders.shown(cell_path)} has errors: fix them first")
            plan = plan_teach(cell_path, station.folders.shown(cell_path), data, cell, name, str(parent), tcp)
            problems = await asyncio.to_thread(check_taught, plan, path, text, station.catalog)
        except (ValueError, DocumentError, OSError) as error:
            return _error(str(error))
        except BridgeError as error:  # the back end could not say where the TCP is
            return _error(f"teach: {error}", 409)
        key = f"t{next(numbers)}"
        plans[key] = (plan, path, text)
        while len(plans) > MAX_PLANS:
            plans.popitem(last=False)
        record(request, "teach", ok=not problems, answer=f"frame {plan.frame} shown as a diff of {plan.shown}", before=hex_digest(plan.digest),
               frame=plan.frame, parent=plan.parent, cell=plan.shown, group=group, proposed=digest(plan.text))  # the save's after, if saved
        return JSONResponse({"ok": not problems, "id": key, "problems": problems, **plan.to_json()})

    async def teach_save(request: Request) -> Response:
        try:
            body = await _body(request)
        except ValueError as error:
            return _error(str(error))
        if body.get("confirm") is not True:
            return _error("teach save: confirm it with {\"confirm\": true} once the diff is right")
        found = plans.get(str(body.get("id")))
        if found is None:
            return _error("teach save: no such taught frame (teach it again: the station keeps the newest 16)", 404)
        plan, path, text = found
        outputs = station.session.outputs() if isinstance(station.session, RunSession) else []
        try:
            await asyncio.to_thread(save_taught, plan, path, text, station.catalog, outputs)
        except TeachRefused as refused:
            record(request, "teach save", ok=False, answer=str(refused), before=hex_digest(plan.digest), frame=plan.frame, cell=plan.shown)
            return _error(str(refused), 409)
        except OSError as error:
            return _error(f"teach save: {plan.shown}: cannot write: {error.strerror or error}")
        plans.pop(str(body.get("id")), None)
        answer = f"frame {plan.frame} {'added to' if plan.created else 'updated in'} {plan.shown}"
        record(request, "teach save", answer=answer, before=hex_digest(plan.digest), after=digest(plan.text), frame=plan.frame, cell=plan.shown)
        return JSONResponse({"ok": True, "answer": answer, **plan.to_json()})

    return [
        Route("/api/jog", state),
        Route("/api/jog/open", requires(ENGINEER, "jog")(open_), methods=["POST"]),
        WebSocketRoute("/ws/jog", requires(ENGINEER, "jog")(socket)),
        Route("/api/teach", requires(ENGINEER, "teach")(teach), methods=["POST"]),
        Route("/api/teach/save", requires(ENGINEER, "teach save")(teach_save), methods=["POST"]),
    ]


async def _start(station: Any, jog: JogStation, ws: WebSocket, message: dict[str, Any], owner: object) -> dict[str, Any]:
    """A button went down: the jog starts unless something refuses it (said in one line)."""
    refused = refusal(station)
    if refused:
        record(ws, "jog start", ok=False, answer=refused)
        return {"type": "answer", "ok": False, "answer": refused}
    try:
        request = jog.request(message)
    except ValueError as error:
        record(ws, "jog start", ok=False, answer=str(error))
        return {"type": "answer", "ok": False, "answer": str(error)}
    ok, answer = await jog.start(request, owner)  # audited on the jog's loop, in order with its stop (JogStation.note)
    return {"type": "answer", "ok": ok, "answer": answer}


async def _body(request: Request) -> dict[str, Any]:
    try:
        body = orjson.loads(await request.body() or b"{}")
    except orjson.JSONDecodeError as error:
        raise ValueError(f"the request is not JSON: {error}") from None
    if not isinstance(body, dict):
        raise ValueError("the request must be a JSON object")
    return body


def _error(message: str, status: int = 400) -> JSONResponse:
    return JSONResponse({"ok": False, "error": message}, status_code=status)
