"""Which role each route of the station needs: declared once, at the route, checked in one place.

A route that changes anything declares its role and its action's name with :func:`requires`::

    Route("/api/save", requires(ENGINEER, "save")(save_endpoint), methods=["POST"])

An operator's session calling it gets a 403 with one line (``save: needs the engineer role; this
session is operator 'anna'``), nothing happens, and the refusal is audited.  :func:`secure` goes
over a station's whole route table as the app is made: a state-changing route (or a WebSocket
other than the read-only feed) that declares no role is given the engineer's -- a route someone
forgot to declare is refused to operators rather than open to them -- and logged as undeclared,
so a test can list them (:func:`undeclared`).
"""
from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable, Sequence
from typing import Any

from starlette.responses import JSONResponse
from starlette.routing import BaseRoute, Route, WebSocketRoute

from operator_station.access import ENGINEER, OPERATOR, Who, role_allows
from operator_station.audit import record, requester

log = logging.getLogger(__name__)

#: Methods that change nothing and so need only a session (any role).
READ_METHODS = frozenset({"GET", "HEAD"})
#: The attribute a declared endpoint carries: (role, action).
DECLARED = "studio_role"

Endpoint = Callable[[Any], Awaitable[Any]]


def refusal(who: Who | None, needed: str, action: str) -> str | None:
    """The one line refusing ``who`` the ``action`` that needs ``needed``; None when allowed."""
    if who is not None and role_allows(who.role, needed):
        return None
    if who is None:
        return f"{action}: needs the {needed} role; this request has no session"
    holder = "session" if who.kind == "session" else "token"
    return f"{action}: needs the {needed} role; this {holder} is {who.role} {who.name or who.ident!r}"


def requires(role: str, action: str) -> Callable[[Endpoint], Endpoint]:
    """Declare that ``action`` (the name the refusal and the audit use) needs ``role``: the endpoint runs only for it."""
    if role not in (OPERATOR, ENGINEER):
        raise ValueError(f"unknown role {role!r}")

    def declare(endpoint: Endpoint) -> Endpoint:
        async def checked(connection: Any) -> Any:
            refused = refusal(requester(connection), role, action)
            if refused is None:
                return await endpoint(connection)
            record(connection, action, ok=False, answer=refused, refused=True, path=connection.scope.get("path", ""))
            log.warning("studio refused %s: %s", connection.scope.get("path", ""), refused)
            if connection.scope["type"] == "websocket":
                await connection.close(code=1008)
                return None
            return JSONResponse({"ok": False, "error": refused}, status_code=403)

        checked.__name__ = getattr(endpoint, "__name__", action)
        checked.__doc__ = endpoint.__doc__
        setattr(checked, DECLARED, (role, action))
        return checked

    return declare


def public(action: str) -> Callable[[Endpoint], Endpoint]:
    """Declare a route open to anyone the guard let through, with no role (logging in: there is no session yet)."""

    def declare(endpoint: Endpoint) -> Endpoint:
        setattr(endpoint, DECLARED, ("anyone", action))
        return endpoint

    return declare


def declared(endpoint: Any) -> tuple[str, str] | None:
    """The (role, action) an endpoint declares, None if it declares none."""
    found = getattr(endpoint, DECLARED, None)
    return found if isinstance(found, tuple) else None


def changes_state(route: BaseRoute, read_only_sockets: Sequence[str]) -> bool:
    """A route that may change anything: any method but GET/HEAD, or a WebSocket that is not read-only."""
    if isinstance(route, WebSocketRoute):
        return route.path not in read_only_sockets
    if isinstance(route, Route):
        return bool(set(route.methods or ()) - READ_METHODS)
    return False


def undeclared(routes: Sequence[BaseRoute], read_only_sockets: Sequence[str] = ("/ws",)) -> list[str]:
    """The paths of state-changing routes whose endpoint declares no role."""
    return [getattr(r, "path", "?") for r in routes if changes_state(r, read_only_sockets) and declared(getattr(r, "endpoint", None)) is None]


def secure(routes: Sequence[BaseRoute], read_only_sockets: Sequence[str] = ("/ws",)) -> list[BaseRoute]:
    """``routes`` with every undeclared state-changing route made to need the engineer role (and said so in the log)."""
    made: list[BaseRoute] = []
    for route in routes:
        if not changes_state(route, read_only_sockets) or declared(getattr(route, "endpoint", None)) is not None:
            made.append(route)
            continue
        log.warning("studio: route %s declares no role: it needs the engineer role", getattr(route, "path", "?"))
        if isinstance(route, WebSocketRoute):
            made.append(WebSocketRoute(route.path, requires(ENGINEER, route.path)(route.endpoint), name=route.name))
        elif isinstance(route, Route):
            made.append(Route(route.path, requires(ENGINEER, route.path)(route.endpoint), methods=sorted(route.methods or ()), name=route.name))
    return made


def whoami(who: Who | None) -> dict[str, Any]:
    """What the page shows of its session (and disables by): name, role, kind and session id."""
    if who is None:
        return {"name": "", "role": "", "kind": "", "session": ""}
    return {"name": who.name or str(who), "role": who.role, "kind": who.kind, "session": who.ident}

