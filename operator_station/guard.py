"""The station's gate: every HTTP request and WebSocket upgrade passes these checks before any route runs.

A page of another site can make the operator's browser send requests to the station (forms,
``fetch``, WebSockets, a DNS name rebound to 127.0.0.1); it cannot make the browser lie about
``Host`` and ``Origin``, attach a SameSite=Strict cookie to a cross-site request, or send
``application/json`` across origins without a CORS preflight, which the station never answers.
So, in this order:

1. ``Host`` must name the station (:attr:`Access.hosts`, or the address the connection came in
   on) with its port: a rebound domain is refused;
2. ``Origin``, when the browser sends one, must be the station's own origin (``http://`` + that
   ``Host``), and ``Sec-Fetch-Site``, when sent to the API or the feed, ``same-origin`` or
   ``none``;
3. the API and the live feed need a session cookie or a token (:mod:`operator_station.access`); the
   requester (:class:`~operator_station.access.Who`, with the user's name and role) and the station's
   audit log are left in the scope for the routes, which check the role they need
   (:mod:`operator_station.roles`) and record what they do (:mod:`operator_station.audit`);
4. a request that may change state (any method but GET and HEAD) must be JSON
   (``Content-Type: application/json``): no ``text/plain``, no form types;
5. a body is bounded while it streams: a ``Content-Length`` over the limit is refused before a
   byte is read, and a chunked body is counted as it arrives and refused at the limit (413).

Refusals are one JSON line (``{"ok": false, "error": ...}``) and logged; a refused WebSocket is
closed before it is accepted (the browser sees a failed handshake).  Every HTTP answer carries
headers that keep the page out of other sites' frames and never any ``Access-Control-*``.
"""
from __future__ import annotations

import logging
import re
from collections.abc import Awaitable, Callable, MutableMapping
from email.message import Message
from pathlib import Path
from typing import Any

from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.requests import HTTPConnection, Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, RedirectResponse, Response
from starlette.websockets import WebSocketClose

from operator_station.access import ENGINEER, WHO, Access, Who, is_loopback, normal_host
from operator_station.audit import AUDIT, AuditLog, log_of

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
AsgiMessage = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[AsgiMessage]]
Send = Callable[[AsgiMessage], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: Methods that change nothing (everything else needs a JSON body).
SAFE_METHODS = ("GET", "HEAD")
#: Paths that need a session or the token (the page itself hands out the session; its assets are public).
PROTECTED = ("/api/", "/ws")
#: A Host header: a name or an IPv4 address, or an IPv6 address in brackets, and maybe a port (RFC 9110 7.2).
HOST_HEADER = re.compile(r"(?P<name>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(?::(?P<port>[0-9]{1,5}))?")
#: The station's login form, served instead of the page to a browser without a session when users are configured.
LOGIN_PAGE = "login.html"
#: Where the form posts: outside PROTECTED (there is no session yet), under every other rule, Sec-Fetch-Site too.
LOGIN_PATH = "/login"
#: Headers on every HTTP answer: no framing by other sites, no sniffing, no referrer (the token is in a URL once).
SECURITY_HEADERS = (
    (b"x-frame-options", b"DENY"),
    (b"content-security-policy", b"default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; connect-src 'self'; "
                                 b"frame-ancestors 'none'; base-uri 'none'; form-action 'none'"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-resource-policy", b"same-origin"),
)


class BodyTooLarge(HTTPException):
    """A body that went past the limit while it streamed in; the route never sees the rest, the connection is closed
    (uvicorn would otherwise read the rest of the body to keep the connection)."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"the request body is over the limit of {limit} bytes")


def cookie_name(scope: Scope) -> str:
    """The session cookie's name: one per port, since browsers share cookies between ports of a host."""
    server = scope.get("server") or ("", 0)
    return f"studio_session_{server[1]}"


def media_type(value: str | None) -> str:
    """The media type of a Content-Type header, without parameters; ``text/plain`` when absent or malformed."""
    message = Message()
    message["content-type"] = value or ""
    return message.get_content_type()


def host_problem(host: str | None, scope: Scope, access: Access) -> str | None:
    """Why ``Host`` does not name this station (None when it does)."""
    if not host:
        return "a request without a Host header"
    match = HOST_HEADER.fullmatch(host)
    if match is None:
        return f"Host {host!r} is not a host and port"
    server = scope.get("server") or ("", 0)
    port = int(match["port"]) if match["port"] else (443 if scope.get("scheme") in ("https", "wss") else 80)
    name = normal_host(match["name"])
    if port != server[1] or not (name in access.hosts or name == normal_host(str(server[0]))):
        return f"Host {host!r} is not this station's (it answers to {access.shown_hosts(server[1])}; add a name with --allowed-host)"
    return None


def origin_problem(headers: Headers, scope: Scope) -> str | None:
    """Why the request comes from another site (None when it does not, or the browser did not say)."""
    origin = headers.get("origin")
    scheme = "https" if scope.get("scheme") in ("https", "wss") else "http"
    own = f"{scheme}://{headers.get('host', '').lower()}"
    if origin is not None and origin.lower() != own:
        return f"Origin {origin!r} is not this station's ({own}): requests from other sites are refused"
    fetch_site = headers.get("sec-fetch-site")
    if fetch_site is not None and fetch_site not in ("same-origin", "none") and (scope["path"].startswith(PROTECTED) or scope["path"] == LOGIN_PATH):
        return f"a {fetch_site} request (Sec-Fetch-Site): requests from other sites are refused"
    return None


def requester(connection: HTTPConnection, access: Access) -> Who | None:
    """The session or token-holder making this request, None if neither."""
    client = connection.client
    address = f"{client.host}:{client.port}" if client else "unknown"
    kind, _, credential = connection.headers.get("authorization", "").partition(" ")
    role = access.token_role(credential.strip()) if kind.lower() == "bearer" else None
    if role is not None:
        return Who("token", "", address, "token" if role == ENGINEER else "operator token", role)
    found = access.session_of(connection.cookies.get(cookie_name(connection.scope)))
    return Who("session", found.ident, address, found.name, found.role) if found else None


class Guard:
    """Pure ASGI middleware in front of the whole station (routes, static files, the feed)."""

    def __init__(self, app: ASGIApp, access: Access, max_body: int, audit: AuditLog | None = None) -> None:
        self.app = app
        self.access = access
        self.max_body = max_body
        self.audit = audit or AuditLog()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        connection = HTTPConnection(scope)
        headers = connection.headers
        status, problem = 0, host_problem(headers.get("host"), scope, self.access)
        if problem:
            status = 400
        else:
            problem = origin_problem(headers, scope)
            status = 403 if problem else 0
        who = requester(connection, self.access)
        if not problem and scope["path"].startswith(PROTECTED) and who is None:
            status, problem = 401, "no session: load the station's page first (with ?token=... when it serves the network) or send the token"
        if not problem and scope["type"] == "http" and scope["method"] not in SAFE_METHODS:
            status, problem = self._body_problem(headers)
        if problem:
            await self._refuse(scope, receive, send, status, problem)
            return
        scope[WHO] = who
        scope[AUDIT] = self.audit
        if scope["type"] == "websocket":
            await self.app(scope, receive, send)
            return
        body = CountedBody(receive, self.max_body)
        await self.app(scope, body.receive, _with_headers(send, lambda: body.over))

    def _body_problem(self, headers: Headers) -> tuple[int, str | None]:
        kind = media_type(headers.get("content-type"))
        if kind != "application/json":
            shown = headers.get("content-type")
            return 415, f"the request must be JSON (Content-Type: application/json), got {shown!r}" if shown else "the request must be JSON (Content-Type: application/json)"
        length = headers.get("content-length")
        if length is not None:
            if not length.isdigit():
                return 400, f"Content-Length {length!r} is not a number"
            if int(length) > self.max_body:
                return 413, f"the request body is {int(length)} bytes, over the limit of {self.max_body}"
        return 0, None

    async def _refuse(self, scope: Scope, receive: Receive, send: Send, status: int, problem: str) -> None:
        client = scope.get("client") or ("unknown", 0)
        log.info("studio refused %s %s from %s: %s", scope.get("method", "WEBSOCKET"), scope["path"], client[0], problem)
        if scope["type"] == "websocket":
            await WebSocketClose(code=1008)(scope, receive, send)
            return
        unread = scope.get("method") not in SAFE_METHODS  # its body was not read: hang up rather than drain it
        await JSONResponse({"ok": False, "error": problem}, status_code=status)(scope, receive, _with_headers(send, lambda: unread))


class CountedBody:
    """A request's ``receive`` counting the body's bytes: past the limit the route gets a 413 and nothing more is read."""

    def __init__(self, receive: Receive, limit: int) -> None:
        self._receive = receive
        self.limit = limit
        self.seen = 0
        self.over = False

    async def receive(self) -> AsgiMessage:
        message = await self._receive()
        if message["type"] == "http.request":
            self.seen += len(message.get("body", b""))
            if self.seen > self.limit:
                self.over = True
                raise BodyTooLarge(self.limit)
        return message


def _with_headers(send: Send, hang_up: Callable[[], bool]) -> Send:
    """``send`` adding the security headers (and dropping any CORS header); ``Connection: close`` when ``hang_up()``."""

    async def sending(message: AsgiMessage) -> None:
        if message["type"] == "http.response.start":
            kept = [h for h in message.get("headers", []) if not h[0].lower().startswith(b"access-control-") and not (hang_up() and h[0].lower() == b"connection")]
            message["headers"] = [*kept, *SECURITY_HEADERS, *([(b"connection", b"close")] if hang_up() else [])]
        await send(message)

    return sending


def page(request: Request, access: Access, index: Path) -> Response:
    """The station's page, and with it the session: for a page loaded from loopback when the station serves
    loopback only, or for a load carrying a token (then sent on to ``/`` so the token leaves the address bar),
    in that token's role.  With users (``--users``) a browser without a session gets the login form instead."""
    name = cookie_name(request.scope)
    if access.session(request.cookies.get(name)):
        return FileResponse(index, headers={"Cache-Control": "no-store"})
    token = request.query_params.get("token")
    client = request.client.host if request.client else ""
    role = access.token_role(token)
    if token is not None and role is None:
        log.warning("studio: a page load from %s with a wrong token", client)
        return PlainTextResponse("wrong token: open the address the station printed when it started\n", status_code=401)
    if token is None and access.users:
        return FileResponse(index.parent / LOGIN_PAGE, headers={"Cache-Control": "no-store"})
    if token is None and (access.token_needed or not is_loopback(client)):
        return PlainTextResponse("this station needs its token: open the address it printed when it started (http://HOST:PORT/?token=...)\n", status_code=401)
    who = "loopback" if token is None else "token" if role == ENGINEER else "operator token"
    cookie, ident = access.new_session(who, role or ENGINEER)
    log.info("studio: session %s (%s, %s) for a page loaded from %s", ident, who, role or ENGINEER, client)
    address = f"{client}:{request.client.port}" if request.client else "unknown"
    audit = log_of(request)
    if audit is not None:
        audit.append(Who("session", ident, address, who, role or ENGINEER), "login", answer=f"a page loaded {'with a token' if token is not None else 'from loopback'}")
    response: Response = (RedirectResponse("/", status_code=303) if token is not None
                          else FileResponse(index, headers={"Cache-Control": "no-store"}))
    response.set_cookie(name, cookie, httponly=True, samesite="strict", path="/")
    return response
