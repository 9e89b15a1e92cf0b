"""The operator station's web server: Starlette routes and one WebSocket per page, all on loopback by default.

Routes (JSON unless said otherwise):

* ``GET /`` the page; ``/static/...`` its scripts, styles and the vendored libraries (no CDN: the
  page works without a network);
* ``GET /api/catalog`` the function catalog grouped by library (``functions --json`` plus groups);
* ``GET /api/document`` the application the station was started with (or an empty one);
* ``POST /api/open`` ``{path}``; ``POST /api/cell`` ``{path, document}`` the cell's names;
  ``POST /api/validate`` ``{path, document}``; ``POST /api/save`` ``{path, document}`` (only valid
  documents are written); ``POST /api/run`` ``{path, document}`` validates, then starts the run;
* ``POST /api/operator/{command}`` start, pause, resume, step, stop, reset; ``POST /api/safety``
  ``{"active": true}`` raises the safety stop; ``POST /api/safety/clear`` ``{"confirm": true}``
  clears it (its own confirmed action, logged with who and when);
* ``GET /api/timeline`` the timeline model of the records so far (``?until=T`` for a replay's slider);
* ``WS /ws`` the live feed: a snapshot, then every record and joint sample, in order, batched.

Everything passes the guard first (:mod:`operator_station.guard`: Host, Origin, a session or the
token, JSON bodies bounded while they stream).  Paths the page names are resolved, links
followed, and must lie in the station's folders (:mod:`operator_station.folders`); only ``.xml``
files are opened or written.
"""
from __future__ import annotations

import asyncio
import logging
import os
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import orjson
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from core_functions.catalog import Catalog
from execution_engine.app_model.document import DocumentError
from node_transport.wire import ENGINE_SERVICES
from operator_station import builder
from operator_station import accounts
from operator_station.access import ENGINEER, OPERATOR, Access, role_allows
from operator_station.audit import AuditLog, digest, file_digest, record
from operator_station.feed import Feed
from operator_station.folders import Folders
from operator_station.guard import WHO, BodyTooLarge, Guard, page
from operator_station.paused_edit import operations_json
from operator_station.attach import AttachedSession
from operator_station.blocks import BlockDocument, calls_inside
from operator_station.roles import requires, secure
from operator_station.run_audit import watch_run
from operator_station.cell_audit import CellAudit
from operator_station.scene3d_routes import routes as scene3d_routes
from operator_station.jog_routes import routes as jog_routes
from operator_station.speed_routes import routes as speed_routes
from operator_station.breakpoint_routes import routes as breakpoint_routes
from operator_station.jog_station import JogStation
from operator_station.edit_routes import routes as edit_routes
from operator_station.session import SOURCE, RunSession
from operator_station.timeline_view import TimelineView

log = logging.getLogger(__name__)
#: Who did what to the cell's safety stop, and when: its own logger, so it can be kept apart.
audit_log = logging.getLogger("operator_station.audit")

STATIC = Path(__file__).resolve().parent / "static"
#: Largest request body taken (a 10,000-operation application as JSON is ~3 MB).
MAX_BODY = 32 << 20
#: Wall seconds between two pushes to a page: batches records at --speed max, keeps the page fluid.
PUSH_PERIOD = 0.05
#: Records sent in one WebSocket message at most.
MAX_BATCH = 5000
#: Pages watching the live feed at once; one more is refused (close code 1013, try again later).
MAX_PAGES = 16
#: Safety-stop actions kept in :attr:`Station.audit`.
MAX_AUDIT = 1000


class Station:
    """The state one station serves: catalog, the application file, the feed and the run."""

    def __init__(
        self, catalog: Catalog, feed: Feed, session: RunSession | AttachedSession | None, root: Path, app_path: Path | None, replay: bool = False,
        access: Access | None = None, wall: Callable[[], float] = time.time, audit_log: AuditLog | None = None,
    ) -> None:
        self.catalog = catalog
        self.catalog_json = builder.catalog_view(catalog)
        self.feed = feed
        self.session = session
        self.root = root
        self.folders = Folders([root, *([app_path.parent] if app_path is not None else [])])
        self.app_path = app_path
        self.replay = replay
        self.access = access or Access.for_address("127.0.0.1")
        self.wall = wall  # seconds since 1970, for the audit's "when"
        self.timeline = TimelineView(feed)
        self.stopped = False  # set when the server ends: every page's feed loop stops
        self.pages = 0  # live feeds open now
        self.audit: deque[dict[str, str]] = deque(maxlen=MAX_AUDIT)  # the safety stop's actions (all actions: audit_log)
        self.audit_log = audit_log or AuditLog(wall=lambda: self.wall())  # operator_station/audit.py: every action, --audit FILE
        self._opened: tuple[tuple[float, int], bytes] | None = None  # the start file's answer, by (mtime, size)
        self.jog = JogStation()  # jogging and teaching (operator_station/jog_routes.py): its own back end, thread and clock
        self.cell_audit = CellAudit(lambda: self.audit_log, SOURCE, lambda: self.wall(), ends=isinstance(session, AttachedSession))  # not from the page
        if session is not None:
            self.cell_audit.attach(feed)

    def stop(self) -> None:
        """End every page's feed (from any thread): the station is going away."""
        self.stopped = True
        self.feed.wake()
        self.jog.close()

    def note(self, action: str, who: Any, answer: str) -> dict[str, str]:
        """Log a safety-stop action with who took it and when (UTC)."""
        when = datetime.fromtimestamp(self.wall(), timezone.utc).isoformat(timespec="milliseconds")
        entry = {"when": when, "who": str(who or "unknown"), "action": action, "answer": answer}
        self.audit.append(entry)
        audit_log.warning("studio: %s by %s at %s: %s", action, entry["who"], when, answer)
        self.audit_log.append(who, action, ok="refused" not in action, answer=answer, quiet=True)
        return entry

    def opened(self) -> bytes:
        """The ``/api/document`` answer for the start file, read once per change of the file (a 10,000-operation
        file takes a second to read; every page load would pay it)."""
        path = self.app_path
        if path is None:
            return orjson.dumps({"ok": True, "path": "", "document": None, "replay": self.replay})
        try:
            info = os.stat(path)
            key = (info.st_mtime, info.st_size)
        except OSError:
            key = (0.0, -1)
        if self._opened is None or self._opened[0] != key:
            doc, problems = builder.open_document(path)
            shown = _shown(self, path)
            answer = ({"ok": True, "path": shown, "document": doc.to_json(), "replay": self.replay} if doc is not None
                      else {"ok": False, "path": shown, "error": "; ".join(map(str, problems)), "replay": self.replay})
            self._opened = (key, orjson.dumps(answer))
        return self._opened[1]

    def resolve(self, text: Any) -> Path:
        """The application file the page names, inside the station's folders (ValueError, one line, if not)."""
        return self.folders.resolve(text)


class FastJSON(JSONResponse):
    """orjson instead of json: a 10,000-operation application is 4 MB of JSON, five times faster."""

    def render(self, content: Any) -> bytes:
        return orjson.dumps(content)


def _error(message: str, status: int = 400) -> JSONResponse:
    return FastJSON({"ok": False, "error": message}, status_code=status)


async def _body(request: Request) -> dict[str, Any]:
    """The request's JSON object; the guard has checked its type and counts its bytes as they stream in."""
    data = bytearray()
    async for chunk in request.stream():
        data += chunk
        if len(data) > MAX_BODY:  # the guard's own bound is the same: this one only if the guard was left out
            raise BodyTooLarge(MAX_BODY)
    try:
        body = orjson.loads(data or b"{}")
    except orjson.JSONDecodeError as error:
        raise ValueError(f"the request is not JSON: {error}") from None
    if not isinstance(body, dict):
        raise ValueError("the request must be a JSON object")
    return body


async def _run_field(station: Station, request: Request, name: str) -> tuple[Any, Response | None]:
    """One field of a command's JSON body, or the refusal: a replay has no run, a bad body is a 400."""
    if station.session is None:
        return None, _error("this station replays a trace; there is no run to command", 409)
    try:
        return (await _body(request)).get(name), None
    except ValueError as error:
        return None, _error(str(error))


def _with_document(station: Station, handler: Callable[..., Awaitable[Response]], with_request: bool = False) -> Callable[[Request], Awaitable[Response]]:
    """A POST route taking ``{path, document}`` (a flat one's ``operations`` or a tree's ``body``): bad input
    is one clear line and a 400, nothing else happens -- what XML cannot carry is found before anything is written.
    ``with_request``: the handler takes the request first (to audit who did it)."""

    async def route(request: Request) -> Response:
        try:
            body = await _body(request)
            path = station.resolve(body.get("path"))
            document = BlockDocument.from_json(body.get("document"))
            calls_inside(station.resolve, path, document)
        except (ValueError, DocumentError) as error:  # JSONDecodeError is a ValueError
            return _error(str(error))
        try:
            return await (handler(request, path, document) if with_request else handler(path, document))
        except DocumentError as error:
            return _error(str(error))

    return route


def create_app(station: Station) -> Starlette:
    async def index(request: Request) -> Response:
        return page(request, station.access, STATIC / "index.html")

    async def catalog(request: Request) -> Response:
        return FastJSON(station.catalog_json)

    async def document(request: Request) -> Response:
        return Response(await asyncio.to_thread(station.opened), media_type="application/json")

    async def open_(request: Request) -> Response:
        try:
            path = station.resolve((await _body(request)).get("path"))
        except ValueError as error:
            return _error(str(error))
        doc, problems = await asyncio.to_thread(builder.open_document, path)
        if doc is None:
            return _error("; ".join(map(str, problems)))
        return FastJSON({"ok": True, "path": _shown(station, path), "document": doc.to_json()})

    async def cell(path: Path, doc: BlockDocument) -> Response:
        return FastJSON({"ok": True, **builder.cell_names(doc.head, path)})

    async def validate(path: Path, doc: BlockDocument) -> Response:
        app, messages, _ = await asyncio.to_thread(builder.validate, doc, path, station.catalog)
        return FastJSON({"ok": app is not None, "messages": [m.to_json() for m in messages]})

    async def save(request: Request, path: Path, doc: BlockDocument) -> Response:
        before = await asyncio.to_thread(file_digest, path)
        try:
            outputs = station.session.outputs() if isinstance(station.session, RunSession) else []  # never over a run's files
            saved, messages = await asyncio.to_thread(builder.save_document, doc, path, station.catalog, outputs)
        except OSError as error:
            record(request, "save", ok=False, answer=f"cannot write: {error.strerror or error}", path=_shown(station, path))
            return _error(f"{station.folders.shown(path)}: cannot write: {error.strerror or error}")
        errors = [m.message for m in messages if m.severity == "error"][:3]
        record(request, "save", ok=saved, answer="saved" if saved else "not saved: " + "; ".join(errors), path=_shown(station, path),
               before=before, after=await asyncio.to_thread(file_digest, path))
        return FastJSON({"ok": saved, "path": _shown(station, path), "messages": [m.to_json() for m in messages]})

    async def run(request: Request, path: Path, doc: BlockDocument) -> Response:
        if station.session is None:
            return _error("this station replays a trace; it runs nothing", 409)
        edited = await asyncio.to_thread(_edited_for, request, path, doc)
        if edited:  # an operator runs the applications as engineers saved them
            record(request, "run start", ok=False, answer=edited, path=_shown(station, path))
            return FastJSON({"ok": False, "error": edited, "messages": []}, status_code=403)
        if isinstance(station.session, AttachedSession):  # the cell runs elsewhere: its engine's start service
            station.cell_audit.expect("start")  # the engine records the call under the service's name: this one is audited here
            ok, answer = await station.session.command("start")
            record(request, "run start", ok=ok, answer=answer, path=_shown(station, path), application=await asyncio.to_thread(file_digest, path))
            return FastJSON({"ok": ok, "answer": answer, "messages": []}, status_code=200 if ok else 409)
        app, messages, text = await asyncio.to_thread(builder.validate, doc, path, station.catalog)
        if app is None:
            record(request, "run start", ok=False, answer="not run: the application has errors", path=_shown(station, path), application=digest(text))
            return FastJSON({"ok": False, "error": "not run: the application has errors", "messages": [m.to_json() for m in messages]})
        operations = operations_json(app, station.catalog)
        await station.jog.release("a run starts")  # the run drives the robot: the jog's back end lets go of it first
        ok, answer = station.session.start(app, operations)
        entry = record(request, "run start", ok=ok, answer=answer, path=_shown(station, path), application=digest(text))
        if ok:
            watch_run(station, request, entry)
        return FastJSON({"ok": ok, "answer": answer, "messages": [m.to_json() for m in messages]}, status_code=200 if ok else 409)

    async def operator(request: Request) -> Response:
        command = request.path_params["command"]
        if command not in ENGINE_SERVICES:
            return _error(f"unknown command {command!r} (commands: {', '.join(ENGINE_SERVICES)})", 404)
        if station.session is None:
            return _error("this station replays a trace; there is no run to command", 409)
        if isinstance(station.session, AttachedSession):  # the engine records the call under the service's name: audited here
            station.cell_audit.expect(command)
        ok, answer = await station.session.command(command)
        record(request, command if command != "start" else "run start", ok=ok, answer=answer)
        return FastJSON({"ok": ok, "answer": answer})

    async def safety(request: Request) -> Response:
        active, refusal = await _run_field(station, request, "active")
        if refusal is not None:
            return refusal
        if active is False:
            return _error("safety: clearing the safety stop is its own confirmed action: POST /api/safety/clear {\"confirm\": true}")
        if active is not True:
            return _error("safety: give {\"active\": true} to raise the safety stop (clear it with /api/safety/clear)")
        jogged = await station.jog.safety_stop(True)  # a jog stops at once, and jogging is refused until the clear
        unsaid = station.cell_audit.publishing(True)  # audited here, with the user, not again when heard on the topic
        ok, answer = station.session.safety_stop(True)  # type: ignore[union-attr] - _run_field checked it
        if not ok:
            unsaid()
        ok, answer = (ok, answer) if ok else (True, f"safety stop raised with no run going: {jogged}")
        station.note("safety stop raised" if ok else "safety stop raise refused", request.scope.get(WHO), answer)
        return FastJSON({"ok": ok, "answer": answer})

    async def safety_clear(request: Request) -> Response:
        """Clearing lets the robot move again once resumed: never a side effect of a toggle, always confirmed."""
        confirm, refusal = await _run_field(station, request, "confirm")
        if refusal is not None:
            return refusal
        if confirm is not True:
            return _error("safety clear: confirm it with {\"confirm\": true} once the cell is safe; the robot moves again on Resume")
        jogged = await station.jog.safety_stop(False)
        unsaid = station.cell_audit.publishing(False)
        ok, answer = station.session.safety_stop(False)  # type: ignore[union-attr]
        if not ok:
            unsaid()
        ok, answer = (ok, answer) if ok else (True, f"safety stop cleared with no run going: {jogged}")
        entry = station.note("safety stop cleared" if ok else "safety stop clear refused", request.scope.get(WHO), answer)
        return FastJSON({"ok": ok, "answer": answer, "who": entry["who"], "when": entry["when"]})

    async def timeline(request: Request) -> Response:
        until = request.query_params.get("until")
        try:
            limit = float(until) if until not in (None, "") else None
        except ValueError:
            return _error(f"until must be a time in seconds, got {until!r}")
        return FastJSON(await asyncio.to_thread(station.timeline.model, limit))

    async def feed(socket: WebSocket) -> None:
        if station.pages >= MAX_PAGES or station.stopped:
            await socket.close(code=1013)  # try again later
            return
        await socket.accept()
        station.pages += 1
        waiter = station.feed.waiter()
        listener = asyncio.ensure_future(_until_gone(socket, waiter))
        run, sent, joints, last_state = -1, 0, 0, ""
        try:
            while not station.stopped and not listener.done():
                waiter.clear()
                if station.feed.snapshot.run != run:  # a new run or replay: the page starts over
                    run, sent, joints, last_state = station.feed.snapshot.run, 0, 0, ""
                    await socket.send_text(orjson.dumps({"type": "snapshot", "snapshot": asdict(station.feed.snapshot)}).decode())
                snapshot, records, samples, joint_total = station.feed.read(sent, joints)
                if snapshot.run != run:
                    continue
                state = orjson.dumps({"type": "state", "state": _live_state(snapshot)}).decode()
                if state != last_state:
                    await socket.send_text(state)
                    last_state = state
                for start in range(0, len(records), MAX_BATCH):
                    batch = records[start:start + MAX_BATCH]
                    await socket.send_text(orjson.dumps({"type": "records", "from": sent, "records": batch}).decode())
                    sent += len(batch)
                if samples:
                    await socket.send_text(orjson.dumps({"type": "joints", "names": snapshot.joint_names, "samples": samples}).decode())
                joints = joint_total
                await asyncio.sleep(PUSH_PERIOD)
                await waiter.wait()  # a change, the page gone (the listener) or the station ending (Station.stop)
            if station.stopped and not listener.done():
                await socket.close(code=1001)  # going away
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the page went away (RuntimeError: sending on a socket already closed)
        finally:
            listener.cancel()
            station.feed.forget(waiter)
            station.pages -= 1

    async def refused(request: Request, error: Exception) -> Response:
        assert isinstance(error, HTTPException)
        return _error(str(error.detail), error.status_code)

    return Starlette(middleware=[Middleware(Guard, access=station.access, max_body=MAX_BODY, audit=station.audit_log)], exception_handlers={HTTPException: refused}, routes=secure([
        Route("/", index),
        Route("/favicon.ico", lambda request: Response(status_code=204)),  # no icon: say so, not 404 in the console
        Route("/api/catalog", catalog),
        Route("/api/document", document),
        Route("/api/open", requires(OPERATOR, "open")(open_), methods=["POST"]),
        Route("/api/cell", requires(OPERATOR, "cell")(_with_document(station, cell)), methods=["POST"]),
        Route("/api/validate", requires(OPERATOR, "validate")(_with_document(station, validate)), methods=["POST"]),
        Route("/api/save", requires(ENGINEER, "save")(_with_document(station, save, with_request=True)), methods=["POST"]),
        Route("/api/run", requires(OPERATOR, "run")(_with_document(station, run, with_request=True)), methods=["POST"]),
        Route("/api/operator/{command}", requires(OPERATOR, "operator command")(operator), methods=["POST"]),
        Route("/api/safety", requires(OPERATOR, "safety stop")(safety), methods=["POST"]),
        Route("/api/safety/clear", requires(OPERATOR, "safety stop clear")(safety_clear), methods=["POST"]),
        *accounts.routes(station.access, lambda: station.wall()),
        Route("/api/timeline", timeline),
        *scene3d_routes(station),  # the 3D view (operator_station/scene3d_routes.py)
        *jog_routes(station),  # jog and teach (operator_station/jog_routes.py)
        *speed_routes(station),  # the speed override (operator_station/speed_routes.py)
        *breakpoint_routes(station),  # breakpoints and run to here (operator_station/breakpoint_routes.py)
        *edit_routes(station),  # edit the paused run (operator_station/edit_routes.py)
        WebSocketRoute("/ws", feed),
        Mount("/static", app=StaticFiles(directory=STATIC), name="static"),
    ]))


async def _until_gone(socket: WebSocket, waiter: asyncio.Event) -> None:
    """Read the page's side until it closes (the page sends nothing else), then wake the feed loop to end it."""
    try:
        while (await socket.receive())["type"] != "websocket.disconnect":
            pass
    except (WebSocketDisconnect, RuntimeError, OSError):
        pass
    finally:
        waiter.set()


def _live_state(snapshot: Any) -> dict[str, Any]:
    """What changes during a run (the rest of the snapshot is sent once per run)."""
    return {"status": snapshot.status, "messages": snapshot.messages, "ended": snapshot.ended, "structures": snapshot.structures,
            "joint_names": snapshot.joint_names, "plan": snapshot.plan, "eta": snapshot.eta, "summary": snapshot.summary}


def _edited_for(request: Request, path: Path, doc: BlockDocument) -> str | None:
    """Why the requester may not run ``doc`` (None if they may): an operator runs an application only as it is
    saved at ``path`` -- running the page's edits would be editing by another name."""
    who = request.scope.get(WHO)
    if who is None or role_allows(who.role, ENGINEER):
        return None
    saved, _ = builder.open_document(path)
    if saved is not None and saved.to_json() == doc.to_json():
        return None
    holder = "session" if who.kind == "session" else "token"
    return (f"run: the builder's application differs from {path.name} as saved; running an edited application needs the engineer role; "
            f"this {holder} is {who.role} {who.name or who.ident!r} (open the saved file again to run it)")


def _shown(station: Station, path: Path) -> str:
    """A path as the page shows it: relative to the station's directory when it is below it."""
    return station.folders.shown(path)
