"""Who may use the station: the token, the page sessions, and the host names a page may reach it by.

The station moves a robot, so a web page of another site must not be able to drive it through
the operator's browser.  Two ways in, nothing else:

* a **session**: an HttpOnly, SameSite=Strict cookie the station sets when its own page is loaded
  from it -- on a station bound to loopback by any page load from loopback, otherwise only by a
  load that carries the token (``/?token=...``, then redirected to ``/`` so the token leaves the
  address bar);
* the **token** itself, as ``Authorization: Bearer <token>``, for scripts.

The token is made with :mod:`secrets` when the station starts, or read from a file the
integrator keeps (:func:`read_token_file`).  Sessions are kept by the SHA-256 of the cookie, so
a lookup does not leak the cookie through timing, and the log names a session by the first
hex digits of that digest, never the cookie.  The host names decide which ``Host`` headers the
guard accepts (:mod:`operator_station.guard`): a DNS-rebinding page reaches the station under
its own domain name, which is never among them.
"""
from __future__ import annotations

import hashlib
import ipaddress
import os
import re
import secrets
import socket
import stat
import threading
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

#: Names that always mean "this computer" and cannot be a rebinding attacker's domain.
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
#: What a token may hold: the alphabet of ``secrets.token_urlsafe`` (fits a URL and a header as is).
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9_-]{32,256}")
#: Random bytes of a token the station makes (43 characters).
TOKEN_BYTES = 32
#: Sessions kept at most; the oldest is forgotten first (its page must be loaded again).
MAX_SESSIONS = 256
#: How a host name given with ``--allowed-host`` may look (a DNS name or an address).
HOST_NAME = re.compile(r"[a-z0-9]([a-z0-9-]{0,61}[a-z0-9])?(\.[a-z0-9]([a-z0-9-]{0,61}[a-z0-9])?)*\.?")
#: The scope key the guard leaves the requester (:class:`Who`) in, for the routes' role checks and audit.
WHO = "studio.who"
#: May run, pause, resume, step, stop, reset, change the speed, continue at breakpoints, raise and clear the safety stop.
OPERATOR = "operator"
#: Everything an operator may, and edit, save, teach, jog, set breakpoints in the file, edit a paused run.
ENGINEER = "engineer"
#: The roles, least first: a role may do what every role before it may.
ROLES = (OPERATOR, ENGINEER)


class AccessError(Exception):
    """A token file or host setting the station refuses: one line for the operator."""


def is_loopback(address: str) -> bool:
    """Whether ``address`` (a name or an IP, IPv6 with or without brackets) is this computer only."""
    name = address.strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def is_wildcard(address: str) -> bool:
    """``0.0.0.0`` or ``::``: every address of the computer."""
    try:
        return ipaddress.ip_address(address.strip("[]")).is_unspecified
    except ValueError:
        return False


def new_token() -> str:
    return secrets.token_urlsafe(TOKEN_BYTES)


def read_token_file(path: Path, option: str = "--token-file") -> str:
    """The token kept in ``path``: one line of at least 32 URL-safe characters, readable by its owner only."""
    shown = f"{option} {path}"
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise AccessError(f"{shown}: not a file")
        if info.st_size > 4096:
            raise AccessError(f"{shown}: {info.st_size} bytes is not a token (one line of 32 to 256 characters)")
        text = path.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        raise AccessError(f"{shown}: no such file") from None
    except UnicodeDecodeError:
        raise AccessError(f"{shown}: the token must be ASCII (letters, digits, - and _)") from None
    except OSError as error:
        raise AccessError(f"{shown}: cannot read: {error.strerror or error}") from None
    if not TOKEN_PATTERN.fullmatch(text):
        raise AccessError(f"{shown}: the token must be one line of 32 to 256 letters, digits, - or _ "
                          "(make one: python3 -c 'import secrets; print(secrets.token_urlsafe(32))' > FILE; chmod 600 FILE)")
    if os.name == "posix" and info.st_mode & 0o077:
        raise AccessError(f"{shown}: readable by other users (mode {stat.S_IMODE(info.st_mode):o}): chmod 600 {path}")
    return text


def normal_host(name: str) -> str:
    """A host name as compared: lower case, no trailing dot; an address in its one canonical form (IPv6 without brackets)."""
    plain = name.strip("[]").lower().rstrip(".")
    try:
        return str(ipaddress.ip_address(plain))
    except ValueError:
        return plain


def check_host_name(name: str) -> str:
    """An ``--allowed-host`` value, normalised; AccessError if it is neither a DNS name nor an address."""
    plain = normal_host(name)
    if is_address(plain):
        return plain
    if not plain or len(plain) > 253 or not HOST_NAME.fullmatch(plain):
        raise AccessError(f"--allowed-host {name!r}: not a host name or an address (give the name pages use, without port or scheme)")
    return plain


def host_names(bound: str, extra: tuple[str, ...] = ()) -> frozenset[str]:
    """The names a page may use for the station: loopback's, the bound address, this computer's name, ``extra``.

    The address a connection arrived on is accepted too (by the guard, per connection): an
    address literal is never a rebinding attacker's domain.
    """
    names = {normal_host(n) for n in LOOPBACK_NAMES}
    if not is_wildcard(bound):
        names.add(normal_host(bound))
    computer = normal_host(socket.gethostname())
    if computer:
        names.update({computer, computer.split(".")[0]})
    names.update(check_host_name(n) for n in extra)
    return frozenset(names)


def role_allows(role: str, needed: str) -> bool:
    """Whether ``role`` may do what ``needed`` may (an unknown role may do nothing)."""
    return role in ROLES and needed in ROLES and ROLES.index(role) >= ROLES.index(needed)


@dataclass(frozen=True)
class Who:
    """Who made a request, for the log: a session's short id or the token, and the client's address; the user's
    name and role (a station without users: the token's holder and loopback pages are engineers, as before roles)."""

    kind: str  # "session" or "token"
    ident: str
    address: str
    name: str = ""  # a user of --users, "token", "operator token", "loopback"
    role: str = ENGINEER

    def __str__(self) -> str:
        return f"{self.kind} {self.ident} from {self.address}" if self.ident else f"{self.kind} from {self.address}"


@dataclass(frozen=True)
class Session:
    """A page's session: its short id (the log's name for it), whose it is and the role it acts in."""

    ident: str
    name: str
    role: str


class Credential(Protocol):
    """A user of ``--users`` (:class:`operator_station.users.User`) as the gate sees one."""

    name: str
    role: str

    def checks(self, password: str) -> bool: ...


@dataclass
class Access:
    """The station's token, its sessions and the host names it answers to."""

    token: str  # the station's own: the engineer role
    token_needed: bool  # False: bound to loopback, a page loaded from loopback gets a session without it
    hosts: frozenset[str]
    operator_token: str | None = None  # --operator-token-file: the operator role
    users: Mapping[str, Credential] = field(default_factory=dict)  # --users: a page must log in (loopback too)
    _sessions: OrderedDict[str, Session] = field(default_factory=OrderedDict)  # sha256(cookie) -> the session
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @classmethod
    def for_address(cls, bound: str, token: str | None = None, extra_hosts: tuple[str, ...] = (), operator_token: str | None = None,
                    users: Mapping[str, Credential] | None = None) -> Access:
        """Loopback without a token file or users: sessions for loopback page loads.  Anything else: a token or a login."""
        if token is not None and operator_token is not None and secrets.compare_digest(token.encode(), operator_token.encode()):
            raise AccessError("--operator-token-file holds the station's own token (--token-file): give the operators a token of their own")
        needed = token is not None or operator_token is not None or bool(users) or not is_loopback(bound)
        return cls(token or new_token(), needed, host_names(bound, extra_hosts), operator_token, dict(users or {}))

    def shown_hosts(self, port: int | None = None) -> str:
        """The names as a page writes them in an address (IPv6 in brackets), with ``port`` if given."""
        names = (f"[{n}]" if ":" in n else n for n in sorted(self.hosts))
        return ", ".join(f"{n}:{port}" if port is not None else n for n in names)

    def token_matches(self, given: str | None) -> bool:
        """Whether ``given`` is one of the station's tokens (either role)."""
        return self.token_role(given) is not None

    def token_role(self, given: str | None) -> str | None:
        """The role of the token ``given`` (engineer: the station's own, operator: the operators'), None if neither;
        both are compared, in constant time, whatever matches."""
        if given is None:
            return None
        raw = given.encode("utf-8", "replace")
        station = secrets.compare_digest(raw, self.token.encode())
        operator = self.operator_token is not None and secrets.compare_digest(raw, self.operator_token.encode())
        return ENGINEER if station else OPERATOR if operator else None

    def login(self, name: str, password: str) -> Credential | None:
        """The user of ``name`` if ``password`` is theirs (a missing name costs a check too: no hint it is missing)."""
        user = self.users.get(name)
        if user is None:
            if self.users:
                next(iter(self.users.values())).checks(password)  # the same work as a wrong password
            return None
        return user if user.checks(password) else None

    def new_session(self, name: str = "loopback", role: str = ENGINEER) -> tuple[str, str]:
        """A new session of ``name`` in ``role``: the cookie value (secret) and its short id (for the log)."""
        cookie = secrets.token_urlsafe(TOKEN_BYTES)
        digest = hashlib.sha256(cookie.encode()).hexdigest()
        with self._lock:
            self._sessions[digest] = Session(digest[:8], name, role)
            while len(self._sessions) > MAX_SESSIONS:
                self._sessions.popitem(last=False)
        return cookie, digest[:8]

    def session(self, cookie: str | None) -> str | None:
        """The short id of the session of ``cookie``, None if it is not one of ours."""
        found = self.session_of(cookie)
        return found.ident if found else None

    def session_of(self, cookie: str | None) -> Session | None:
        """The session of ``cookie`` (its id, user and role), None if it is not one of ours."""
        if not cookie:
            return None
        digest = hashlib.sha256(cookie.encode("utf-8", "replace")).hexdigest()
        with self._lock:
            return self._sessions.get(digest)

    def end_session(self, cookie: str | None) -> Session | None:
        """Forget the session of ``cookie`` (logging out); the session it was, if any."""
        if not cookie:
            return None
        digest = hashlib.sha256(cookie.encode("utf-8", "replace")).hexdigest()
        with self._lock:
            return self._sessions.pop(digest, None)
