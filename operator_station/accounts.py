"""The station's routes of people: log in and out, who this page is, and the audit trail it may read.

* ``POST /login`` ``{name, password}`` (``--users``): a session in the user's role, audited either way;
  wrong passwords for one name are bounded (:data:`MAX_FAILURES` a minute, then 429 until the minute
  is over), and a missing name costs the same work as a wrong password;
* ``POST /api/logout``: the session ends (audited);
* ``GET /api/whoami``: the page's name, role and session id, and whether users are configured (the
  page disables what its role may not do, with the reason, and offers Log out);
* ``GET /api/audit?after=SEQ&limit=N``: the newest entries first (the page's Audit panel polls it
  with the last ``seq`` it has), the audit file's name and any problem writing it.

``/login`` lies outside ``/api/`` because a browser without a session must reach it; the guard's
other rules (Host, Origin, JSON bodies, bounds) apply to it as to every route.
"""
from __future__ import annotations

import asyncio
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route

from operator_station.access import OPERATOR, Access, Who
from operator_station.audit import AuditLog, MAX_ANSWER, log_of, record, requester
from operator_station.guard import LOGIN_PATH, cookie_name
from operator_station.roles import public, requires, whoami

#: Wrong passwords one name may be given within :data:`FAILURE_WINDOW` seconds.
MAX_FAILURES = 5
FAILURE_WINDOW = 60.0
#: Names whose failures are remembered at most (the oldest forgotten first).
MAX_REMEMBERED = 1024
#: Longest name and password a login body may carry (longer: refused before any hashing).
MAX_NAME = 64
MAX_PASSWORD = 1024


class Failures:
    """Recent wrong passwords per name, bounded in names kept; ``wall`` is the station's clock."""

    def __init__(self, wall: Callable[[], float] = time.time) -> None:
        self.wall = wall
        self._seen: OrderedDict[str, list[float]] = OrderedDict()

    def wait(self, name: str) -> float:
        """Seconds until ``name`` may try again (0: now)."""
        now = self.wall()
        recent = [t for t in self._seen.get(name, []) if now - t < FAILURE_WINDOW]
        return FAILURE_WINDOW - (now - recent[0]) if len(recent) >= MAX_FAILURES else 0.0

    def failed(self, name: str) -> None:
        now = self.wall()
        self._seen[name] = [t for t in self._seen.pop(name, []) if now - t < FAILURE_WINDOW][-MAX_FAILURES:] + [now]
        while len(self._seen) > MAX_REMEMBERED:
            self._seen.popitem(last=False)

    def forget(self, name: str) -> None:
        self._seen.pop(name, None)


def _answer(content: dict[str, Any], status: int = 200) -> Response:
    return Response(orjson.dumps(content), status_code=status, media_type="application/json")


def _client(request: Request) -> str:
    return f"{request.client.host}:{request.client.port}" if request.client else "unknown"


def routes(access: Access, wall: Callable[[], float]) -> list[BaseRoute]:
    """The routes above for a station of ``access``; ``wall`` its clock (seconds since 1970)."""
    failures = Failures(wall)

    @public("login")
    async def login(request: Request) -> Response:
        try:
            body = orjson.loads(await request.body() or b"{}")
        except orjson.JSONDecodeError:
            return _answer({"ok": False, "error": "login: the request is not JSON"}, 400)
        name, password = (body.get("name"), body.get("password")) if isinstance(body, dict) else (None, None)
        if not access.users:
            return _answer({"ok": False, "error": "login: this station has no users (--users); open the address it printed"}, 404)
        if not isinstance(name, str) or not isinstance(password, str) or not 0 < len(name) <= MAX_NAME or len(password) > MAX_PASSWORD:
            return _answer({"ok": False, "error": f"login: give a name (1 to {MAX_NAME} characters) and a password"}, 400)
        audit = log_of(request) or AuditLog()
        stranger = Who("login", "", _client(request), name, "")
        wait = failures.wait(name)
        if wait > 0:
            refusal = f"login: too many wrong passwords for {name!r}; try again in {wait:.0f} s"
            audit.append(stranger, "login", ok=False, answer=refusal)
            return _answer({"ok": False, "error": refusal}, 429)
        user = await asyncio.to_thread(access.login, name, password)  # scrypt: tens of milliseconds, off the loop
        if user is None:
            failures.failed(name)
            audit.append(stranger, "login", ok=False, answer="wrong name or password")
            return _answer({"ok": False, "error": "login: wrong name or password"}, 401)
        failures.forget(name)
        access.end_session(request.cookies.get(cookie_name(request.scope)))  # a session the browser had is over: never two at once
        cookie, ident = access.new_session(user.name, user.role)
        entry = audit.append(Who("session", ident, _client(request), user.name, user.role), "login", answer="name and password")
        response = _answer({"ok": True, "name": user.name, "role": user.role, "session": ident, "when": entry["when"]})
        response.set_cookie(cookie_name(request.scope), cookie, httponly=True, samesite="strict", path="/")
        return response

    @requires(OPERATOR, "logout")
    async def logout(request: Request) -> Response:
        name = cookie_name(request.scope)
        ended = access.end_session(request.cookies.get(name))
        record(request, "logout", ok=ended is not None, answer="" if ended else "no session to end (a token)")
        response = _answer({"ok": ended is not None, "users": bool(access.users)})
        response.delete_cookie(name, path="/", httponly=True, samesite="strict")
        return response

    async def who(request: Request) -> Response:
        return _answer({**whoami(requester(request)), "users": bool(access.users)})

    async def trail(request: Request) -> Response:
        try:
            after = int(request.query_params.get("after", "0"))
            limit = int(request.query_params.get("limit", str(MAX_ANSWER)))
        except ValueError:
            return JSONResponse({"ok": False, "error": "after and limit must be whole numbers"}, status_code=400)
        audit = log_of(request) or AuditLog()
        return _answer({"ok": True, "entries": audit.newest(after, limit), "file": str(audit.path or ""), "problem": audit.problem})

    return [
        Route(LOGIN_PATH, login, methods=["POST"]),
        Route("/api/logout", logout, methods=["POST"]),
        Route("/api/whoami", who),
        Route("/api/audit", trail),
    ]
