"""The studio's guard rule by rule (Starlette's TestClient and the ASGI app itself): what a foreign page or a
stranger on the network runs into, and that the station's state and files are unchanged after each refusal."""
from __future__ import annotations

import asyncio
import ipaddress
import logging
import os
import shutil
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")
import httpx  # noqa: E402
import orjson  # noqa: E402
from starlette.testclient import TestClient  # noqa: E402
from starlette.websockets import WebSocketDisconnect  # noqa: E402

from operator_station import server  # noqa: E402
from operator_station.access import TOKEN_PATTERN, Access, AccessError, read_token_file  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.guard import host_problem, media_type, origin_problem  # noqa: E402
from operator_station.server import Station, create_app  # noqa: E402
from operator_station.testing import serve  # noqa: E402
from starlette.datastructures import Headers  # noqa: E402
from test_studio_server import BASE, CATALOG, FEED, ROOT, cell_dir, client_for, rivet, station_args, wait_until  # noqa: E402, F401

#: A fixed "now" for the audit (2025-11-27 08:00:00 UTC).
NOW = 1764230400.0


def bare(station: Station, client: tuple[str, int] = ("127.0.0.1", 50000), base_url: str = BASE) -> TestClient:
    """A client that never loaded the page: no session."""
    return TestClient(create_app(station), base_url=base_url, client=client, follow_redirects=False)


def save(client: TestClient, document: dict[str, Any], path: str, **kwargs: Any) -> Any:
    return client.post("/api/save", json={"path": path, "document": document}, **kwargs)


def feed_refused(client: TestClient, url: str = FEED, **kwargs: Any) -> bool:
    """True if the live feed's upgrade is refused (closed before it is accepted)."""
    try:
        with client.websocket_connect(url, **kwargs) as socket:
            socket.receive_text()
    except WebSocketDisconnect as closed:
        return closed.code == 1008
    return False


def feed_accepted(client: TestClient) -> bool:
    """True if the live feed opens and sends its snapshot."""
    try:
        with client.websocket_connect(FEED) as socket:
            return '"snapshot"' in socket.receive_text()
    except WebSocketDisconnect:
        return False


# ------------------------------------------------------------------------------------------------ Host
@pytest.mark.parametrize("host", ["attacker.example:8080", "attacker.example", "127.0.0.1:9999", "localhost", "127.0.0.1:8080.evil.example",
                                  "user@127.0.0.1:8080", "127.0.0.1:8080/x", "[::1", "127.0.0.1:80a"])
def test_a_host_that_is_not_the_station_is_refused_on_every_route_and_the_feed(cell_dir: Path, host: str) -> None:
    """DNS rebinding: a page of attacker.example whose name now points at 127.0.0.1 reaches the station under its own name."""
    station, client, document = rivet(cell_dir)
    for method, url, extra in (("GET", "/", {}), ("GET", "/api/document", {}), ("POST", "/api/save", {"json": {"path": "rebound.xml", "document": document}}),
                               ("POST", "/api/operator/start", {"json": {}}), ("GET", "/static/js/store.js", {})):
        answer = client.request(method, url, headers={"Host": host}, **extra)
        assert answer.status_code == 400, (method, url, answer.text)
        assert answer.json()["error"].startswith(f"Host {host!r} is not")
    assert feed_refused(client, headers={"Host": host})
    assert not (cell_dir / "rebound.xml").exists() and station.feed.snapshot.run == 0


@pytest.mark.parametrize("host", ["127.0.0.1:8080", "localhost:8080", "LOCALHOST:8080", "[::1]:8080", "cell-pc.example:8080"])
def test_the_station_answers_to_its_own_names_with_its_port(cell_dir: Path, host: str) -> None:
    access = Access.for_address("127.0.0.1", extra_hosts=("cell-pc.example",))
    station = build_station(station_args(file="rivet_installation.xml"), CATALOG, cell_dir, access)
    client = bare(station)
    assert client.get("/", headers={"Host": host}).status_code == 200
    assert client.get("/api/document", headers={"Host": host}).json()["ok"]


@given(st.one_of(st.text(max_size=40), st.from_regex(r"[a-z0-9.:\[\]@/-]{0,30}", fullmatch=True),
                 st.sampled_from(["127.0.0.1:8080", "localhost:8080", "[::1]:8080", "localhost.:8080", "127.0.0.1:08080", "127.0.0.1:8080 "])))
def test_any_host_header_is_accepted_only_when_it_names_the_station_and_its_port(host: str) -> None:
    access = Access(token="t" * 43, token_needed=False, hosts=frozenset({"127.0.0.1", "localhost", "::1"}))
    problem = host_problem(host, {"server": ("127.0.0.1", 8080), "scheme": "http"}, access)
    assert problem is None or problem.startswith("Host ") or (problem == "a request without a Host header" and not host)
    if problem is None:
        name, _, port = host.rpartition(":")
        assert port.isdigit() and int(port) == 8080
        name = name.lower().rstrip(".")
        if name.startswith("["):
            name = str(ipaddress.ip_address(name[1:-1]))
        assert name in access.hosts


# ---------------------------------------------------------------------------------------------- Origin
@pytest.mark.parametrize("origin", ["http://localhost:9000", "http://127.0.0.1:9000", "null", "http://127.0.0.1:8080.evil.example",
                                    "https://127.0.0.1:8080", "http://localhost:8080", "http://attacker.example"])
def test_a_request_from_another_origin_is_refused_even_with_the_session(cell_dir: Path, origin: str) -> None:
    """127.0.0.1:9000 is the same *site* as the station (a SameSite cookie goes with it): Origin tells them apart."""
    station, client, document = rivet(cell_dir)
    for url, body in (("/api/save", {"path": "planted.xml", "document": document}), ("/api/run", {"path": "rivet_installation.xml", "document": document}),
                      ("/api/operator/start", {}), ("/api/safety/clear", {"confirm": True}), ("/api/open", {"path": "rivet_installation.xml"})):
        answer = client.post(url, json=body, headers={"Origin": origin})
        assert answer.status_code == 403 and "requests from other sites are refused" in answer.json()["error"], (url, answer.text)
    assert client.get("/api/document", headers={"Origin": origin}).status_code == 403
    assert feed_refused(client, headers={"Origin": origin})
    assert not (cell_dir / "planted.xml").exists() and station.feed.snapshot.run == 0 and not station.audit


def test_the_stations_own_origin_and_a_request_without_one_are_served(cell_dir: Path) -> None:
    _, client, document = rivet(cell_dir)
    assert save(client, document, "a.xml", headers={"Origin": BASE}).json()["ok"]
    assert save(client, document, "b.xml").json()["ok"]  # scripts send no Origin; they need the session or the token all the same
    with client.websocket_connect(FEED, headers={"Origin": BASE}) as socket:
        assert '"snapshot"' in socket.receive_text()


@pytest.mark.parametrize("site", ["cross-site", "same-site"])
def test_a_fetch_the_browser_marks_as_from_another_site_is_refused(cell_dir: Path, site: str) -> None:
    """Sec-Fetch-Site is set by the browser alone; no-cors requests (an <img>, a <script>) carry it without an Origin."""
    _, client, _ = rivet(cell_dir)
    assert client.get("/api/document", headers={"Sec-Fetch-Site": site}).status_code == 403
    assert client.get("/api/document", headers={"Sec-Fetch-Site": "same-origin"}).status_code == 200


@given(st.binary(max_size=40) | st.sampled_from([b"http://127.0.0.1:8080", b"HTTP://127.0.0.1:8080", b"http://127.0.0.1:8080/"]), st.sampled_from(["/api/save", "/", "/ws"]))
def test_any_origin_but_the_stations_own_is_a_refusal(origin: bytes, path: str) -> None:
    headers = Headers(raw=[(b"host", b"127.0.0.1:8080"), (b"origin", origin)])  # as a server hands them over: any bytes, latin-1
    problem = origin_problem(headers, {"scheme": "http", "path": path})
    assert (problem is None) == (origin.decode("latin-1").lower() == "http://127.0.0.1:8080")


# ----------------------------------------------------------------------------------------- content types
@pytest.mark.parametrize("kind", ["text/plain", "text/plain; charset=utf-8", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x",
                                  None, "application/jsonp", "text/json", "application/json-seq", "application/json,text/plain", "garbage"])
def test_a_body_that_is_not_declared_json_is_refused_before_it_is_read(cell_dir: Path, kind: str | None) -> None:
    """What a form or a no-cors fetch can send without a preflight (text/plain, form types) is never taken, JSON inside or not."""
    station, client, document = rivet(cell_dir)
    headers = {"Content-Type": kind} if kind is not None else {}
    body = orjson.dumps({"path": "planted.xml", "document": document})
    answer = client.post("/api/save", content=body, headers=headers)
    assert answer.status_code == 415 and answer.json()["error"].startswith("the request must be JSON")
    assert client.post("/api/operator/start", content=b"{}", headers=headers).status_code == 415
    assert not (cell_dir / "planted.xml").exists() and station.feed.snapshot.run == 0


def test_json_with_a_charset_is_json(cell_dir: Path) -> None:
    _, client, document = rivet(cell_dir)
    answer = client.post("/api/save", content=orjson.dumps({"path": "c.xml", "document": document}), headers={"Content-Type": "application/json; charset=utf-8"})
    assert answer.json()["ok"] and (cell_dir / "c.xml").is_file()


@given(st.text(max_size=60))
def test_any_content_type_is_json_only_when_its_media_type_is(value: str) -> None:
    kind = media_type(value)
    assert kind == kind.lower() and "/" in kind
    if kind == "application/json":
        assert value.split(";")[0].strip().lower() == "application/json"


def test_no_answer_ever_carries_cors_headers_and_every_one_keeps_the_page_out_of_frames(cell_dir: Path) -> None:
    _, client, document = rivet(cell_dir)
    preflight = client.options("/api/save", headers={"Origin": "http://localhost:9000", "Access-Control-Request-Method": "POST",
                                                     "Access-Control-Request-Headers": "content-type"})
    same_origin_preflight = client.options("/api/save", headers={"Access-Control-Request-Method": "POST"})
    answers = [preflight, same_origin_preflight, client.get("/"), client.get("/api/document"), save(client, document, "d.xml"),
               client.post("/api/save", content=b"x"), client.get("/static/js/store.js"), client.get("/api/document", headers={"Host": "evil.example"})]
    assert preflight.status_code == 403 and same_origin_preflight.status_code >= 400
    for answer in answers:
        assert not [h for h in answer.headers if h.lower().startswith("access-control-")], answer.headers
        assert answer.headers["x-frame-options"] == "DENY" and "frame-ancestors 'none'" in answer.headers["content-security-policy"]


# ---------------------------------------------------------------------------------------------- sessions
def test_without_a_session_the_api_and_the_feed_are_refused(cell_dir: Path) -> None:
    station = build_station(station_args(file="rivet_installation.xml"), CATALOG, cell_dir)
    client = bare(station)
    document = client_for(station).get("/api/document").json()["document"]  # a page elsewhere has a session; this client has none
    assert client.get("/api/document").status_code == 401
    assert save(client, document, "planted.xml").status_code == 401
    assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).status_code == 401
    assert feed_refused(client)
    client.cookies.set("studio_session_8080", "forged")
    assert client.get("/api/document").status_code == 401
    other = build_station(station_args(file="rivet_installation.xml"), CATALOG, cell_dir)
    stolen = client_for(other).cookies["studio_session_8080"]  # a session of another station on the same port
    client.cookies.set("studio_session_8080", stolen)
    assert client.get("/api/document").status_code == 401
    assert not (cell_dir / "planted.xml").exists() and station.feed.snapshot.run == 0


def test_the_session_cookie_is_httponly_samesite_strict_and_per_port(cell_dir: Path) -> None:
    station = build_station(station_args(), CATALOG, cell_dir)
    cookie = bare(station).get("/").headers["set-cookie"]
    attributes = {part.strip().split("=")[0].lower(): part.strip() for part in cookie.split(";")}
    assert cookie.startswith("studio_session_8080=") and "httponly" in attributes and attributes["samesite"].lower() == "samesite=strict"
    assert "domain" not in attributes and attributes["path"] == "Path=/"


def test_a_loopback_station_gives_no_session_to_a_page_loaded_from_elsewhere(cell_dir: Path) -> None:
    station = build_station(station_args(), CATALOG, cell_dir)
    answer = bare(station, client=("192.0.2.7", 50000)).get("/")
    assert answer.status_code == 401 and "set-cookie" not in answer.headers


def test_off_loopback_the_page_and_the_api_need_the_token(cell_dir: Path) -> None:
    access = Access.for_address("0.0.0.0")  # noqa: S104 - the point of the test
    station = build_station(station_args(file="rivet_installation.xml"), CATALOG, cell_dir, access)
    network = "http://192.0.2.10:8080"  # the address the connection came in on (a wildcard bind serves every address)
    stranger = bare(station, client=("192.0.2.20", 50000), base_url=network)
    for client in (stranger, bare(station, base_url=network)):  # from the network, and from loopback too: the token is the key
        for url in ("/", "/?token=", f"/?token={access.token[:-1]}x", "/api/document"):
            answer = client.get(url)
            assert answer.status_code == 401 and "set-cookie" not in answer.headers, url
        assert client.post("/api/operator/start", json={}).status_code == 401
        assert client.get("/api/document", headers={"Authorization": f"Bearer {access.token}x"}).status_code == 401
        assert feed_refused(client, "ws://192.0.2.10:8080/ws")
    assert station.feed.snapshot.run == 0
    assert stranger.get("/api/document", headers={"Authorization": f"Bearer {access.token}"}).json()["ok"]  # a script with the token
    entered = stranger.get(f"/?token={access.token}")
    assert entered.status_code == 303 and entered.headers["location"] == "/" and "httponly" in entered.headers["set-cookie"].lower()
    assert stranger.get("/").status_code == 200 and stranger.get("/api/document").json()["ok"]
    with stranger.websocket_connect("ws://192.0.2.10:8080/ws") as socket:
        assert '"snapshot"' in socket.receive_text()


def test_a_token_file_is_read_and_checked(tmp_path: Path) -> None:
    good = tmp_path / "token"
    good.write_text("A" * 20 + "b-_c" * 5 + "\n")
    good.chmod(0o600)
    assert read_token_file(good) == "A" * 20 + "b-_c" * 5
    assert Access.for_address("127.0.0.1", read_token_file(good)).token_needed  # a token file asks for it on loopback too
    assert not Access.for_address("127.0.0.1").token_needed and Access.for_address("::").token_needed
    cases = {"short": ("secret", 0o600, "must be one line of 32 to 256"), "spaced": ("A" * 20 + " " + "B" * 20, 0o600, "must be one line"),
             "shared": ("C" * 43, 0o644, "readable by other users (mode 644): chmod 600"), "group": ("C" * 43, 0o640, "readable by other users (mode 640)")}
    for name, (text, mode, message) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        path.chmod(mode)
        with pytest.raises(AccessError, match=message.replace("(", r"\(").replace(")", r"\)")):
            read_token_file(path)
    with pytest.raises(AccessError, match="no such file"):
        read_token_file(tmp_path / "none")
    with pytest.raises(AccessError, match="not a file"):
        read_token_file(tmp_path)


def test_live_feeds_are_bounded_in_number(cell_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One page more than MAX_PAGES is told to come back later (1013); a feed that ends frees its place."""
    monkeypatch.setattr(server, "MAX_PAGES", 2)
    _, client, _ = rivet(cell_dir)
    with client.websocket_connect(FEED) as first, client.websocket_connect(FEED) as second:
        assert '"snapshot"' in first.receive_text() and '"snapshot"' in second.receive_text()
        with pytest.raises(WebSocketDisconnect) as busy:
            with client.websocket_connect(FEED) as third:
                third.receive_text()
        assert busy.value.code == 1013
    assert wait_until(lambda: feed_accepted(client), 30.0)  # both gone: a page gets in again


@given(st.binary(max_size=300) | st.from_regex(r"[A-Za-z0-9_-]{30,40}\n?", fullmatch=True).map(str.encode))
def test_any_token_file_gives_a_token_of_the_documented_form_or_one_line(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    path = tmp_path_factory.mktemp("token") / "token"
    path.write_bytes(data)
    path.chmod(0o600)
    try:
        token = read_token_file(path)
    except AccessError as refusal:
        assert str(refusal).startswith(f"--token-file {path}: ") and "\n" not in str(refusal)
    else:
        assert TOKEN_PATTERN.fullmatch(token) and token == data.decode("ascii").strip()


# ---------------------------------------------------------------------------------------------- bodies
def asgi_post(app: Any, path: str, headers: list[tuple[bytes, bytes]], chunks: Any) -> tuple[int, int, bytes]:
    """POST to the ASGI app directly; ``chunks`` is an iterator of body parts.  The status, the parts the app pulled, the body."""
    pulled = 0
    sent: list[dict[str, Any]] = []

    async def receive() -> dict[str, Any]:
        nonlocal pulled
        pulled += 1
        chunk = next(chunks, None)
        return {"type": "http.request", "body": chunk or b"", "more_body": chunk is not None}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST", "scheme": "http", "path": path, "raw_path": path.encode(),
             "root_path": "", "query_string": b"", "headers": headers, "server": ("127.0.0.1", 8080), "client": ("127.0.0.1", 50000)}
    asyncio.run(app(scope, receive, send))
    start = next(m for m in sent if m["type"] == "http.response.start")
    return start["status"], pulled, b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")


def endless(size: int) -> Any:
    while True:
        yield b" " * size


def test_a_body_is_counted_as_it_streams_and_nothing_past_the_limit_is_read(cell_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An endless chunked body: the station pulls parts only up to the limit, answers 413, and never holds more."""
    monkeypatch.setattr(server, "MAX_BODY", 1 << 20)
    station = build_station(station_args(), CATALOG, cell_dir)
    app = create_app(station)
    cookie, _ = station.access.new_session()
    headers = [(b"host", b"127.0.0.1:8080"), (b"content-type", b"application/json"), (b"cookie", f"studio_session_8080={cookie}".encode())]
    part = 64 << 10
    for path in ("/api/validate", "/api/save", "/api/open", "/api/safety/clear"):
        status, pulled, body = asgi_post(app, path, headers, endless(part))
        assert status == 413 and b"over the limit of 1048576 bytes" in body, (path, body)
        assert pulled == (1 << 20) // part + 1, (path, pulled)  # 16 parts make the limit; the 17th goes past it: no 18th
    status, pulled, body = asgi_post(app, "/api/operator/start", headers, endless(part))
    assert (status, pulled) == (200, 0) and b"no run is going" in body  # a command takes no body: none is read
    announced = [*headers, (b"content-length", str((1 << 20) + 1).encode())]
    status, pulled, body = asgi_post(app, "/api/save", announced, endless(part))
    assert (status, pulled) == (413, 0) and b"is 1048577 bytes, over the limit" in body  # refused on the header: not a byte read
    assert station.feed.snapshot.run == 0 and not list(cell_dir.glob("*.xml.studio-*"))


def test_a_station_on_a_socket_stops_reading_a_huge_body(cell_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Over a real loopback connection: the client can push the limit plus what the sockets buffer, then the station hangs up."""
    monkeypatch.setattr(server, "MAX_BODY", 1 << 20)
    served = serve(build_station(station_args(), CATALOG, cell_dir))
    pushed = 0

    def body() -> Any:
        nonlocal pushed
        for _ in range(4096):  # 256 MiB at most
            pushed += 64 << 10
            yield b" " * (64 << 10)

    try:
        with httpx.Client(base_url=served.url, timeout=30.0) as client:
            client.get("/")
            try:
                answer = client.post("/api/validate", content=body(), headers={"Content-Type": "application/json"})
                assert answer.status_code == 413
            except httpx.TransportError:
                pass  # the station closed the connection while the client was still writing
            assert client.get("/api/catalog").status_code == 200  # still serving, on a new connection
        assert pushed < 16 << 20, pushed  # the 1 MiB limit and what the two sockets buffer, far from the 256 MiB offered
    finally:
        served.close()


# ------------------------------------------------------------------------------------------------ files
@pytest.fixture
def outside(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder beside the station's, holding an application the page must not reach."""
    folder = tmp_path_factory.mktemp("outside")
    shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", folder / "secret.xml")
    return folder


def test_open_and_save_stay_in_the_station_folders_links_followed(cell_dir: Path, outside: Path) -> None:
    station, client, document = rivet(cell_dir)
    secret = (outside / "secret.xml").read_bytes()
    (cell_dir / "link.xml").symlink_to(outside / "secret.xml")
    (cell_dir / "out").symlink_to(outside, target_is_directory=True)
    (cell_dir / "dangling.xml").symlink_to(outside / "new.xml")
    (cell_dir / "loop.xml").symlink_to(cell_dir / "loop.xml")
    relative = os.path.relpath(outside / "secret.xml", cell_dir)
    assert relative.startswith("..")
    for named in (relative, str(outside / "secret.xml"), "link.xml", "out/secret.xml", f"cells/../{relative}"):
        answer = client.post("/api/open", json={"path": named})
        assert answer.status_code == 400 and answer.json()["error"].startswith(f"{named}: outside the station's folders ("), named
        assert "\n" not in answer.json()["error"]
    for named in (os.path.relpath(outside / "new.xml", cell_dir), str(outside / "new.xml"), "link.xml", "out/new.xml", "dangling.xml"):
        answer = save(client, document, named)
        assert answer.status_code == 400 and "outside the station's folders" in answer.json()["error"], named
    answer = client.post("/api/open", json={"path": "loop.xml"})
    assert answer.status_code == 400 and answer.json()["error"].startswith("loop.xml: ")
    assert (outside / "secret.xml").read_bytes() == secret and not (outside / "new.xml").exists()
    assert sorted(p.name for p in outside.iterdir()) == ["cells", "secret.xml"]
    (cell_dir / "alias.xml").symlink_to(cell_dir / "rivet_installation.xml")  # a link inside the folder is fine
    assert client.post("/api/open", json={"path": "alias.xml"}).json()["ok"]
    assert save(client, document, "cells/../inside.xml").json()["ok"] and (cell_dir / "inside.xml").is_file()


def test_the_folder_of_the_application_the_station_was_started_with_is_one_of_its_folders(cell_dir: Path, outside: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    station = build_station(station_args(file=str(outside / "secret.xml")), CATALOG, tmp_path_factory.mktemp("elsewhere"))
    client = client_for(station)
    document = client.get("/api/document").json()["document"]
    assert client.post("/api/open", json={"path": str(outside / "secret.xml")}).json()["ok"]
    assert save(client, document, str(outside / "copy.xml")).json()["ok"]
    assert save(client, document, str(outside.parent / "copy.xml")).status_code == 400


# ------------------------------------------------------------------------------------------ safety stop
def test_clearing_the_safety_stop_is_its_own_confirmed_action_logged_with_who_and_when(cell_dir: Path, caplog: pytest.LogCaptureFixture) -> None:
    station, client, document = rivet(cell_dir, speed=10.0, no_check=True)
    station.wall = lambda: NOW
    session = station.session
    assert session is not None
    caplog.set_level(logging.WARNING, logger="operator_station.audit")
    assert client.post("/api/run", json={"path": "rivet_installation.xml", "document": document}).json()["ok"]
    try:
        assert session.wait_started(60.0)
        assert client.post("/api/safety", json={"active": True}).json()["ok"]
        assert wait_until(lambda: any(r.get("source", "").startswith("safety stop on") for r in station.feed.records))
        assert wait_until(lambda: (station.feed.snapshot.status or {}).get("state") == "paused")

        def resume() -> dict[str, Any]:
            return dict(client.post("/api/operator/resume", json={}).json())

        assert resume() == {"ok": False, "answer": "the safety stop is still active"}
        refusals = [client.post("/api/safety", json={"active": False}), *(client.post("/api/safety/clear", json=body) for body in ({}, {"confirm": "yes"}, {"confirm": False}, {"confirm": 1}))]
        assert [r.status_code for r in refusals] == [400] * 5
        assert "/api/safety/clear" in refusals[0].json()["error"] and refusals[1].json()["error"].startswith("safety clear: confirm it with {\"confirm\": true}")
        assert resume() == {"ok": False, "answer": "the safety stop is still active"}  # none of them cleared it
        assert (station.feed.snapshot.status or {}).get("state") == "paused"

        ident = client.cookies["studio_session_8080"]
        cleared = client.post("/api/safety/clear", json={"confirm": True}).json()
        assert cleared["ok"] and cleared["answer"] == "safety stop cleared: resume to continue"
        assert cleared["when"] == "2025-11-27T08:00:00.000+00:00" and cleared["who"].startswith("session ") and cleared["who"].endswith(" from 127.0.0.1:50000")
        assert ident not in cleared["who"]  # the log names the session, never its cookie
        assert [(e["action"], e["who"]) for e in station.audit] == [("safety stop raised", cleared["who"]), ("safety stop cleared", cleared["who"])]
        assert f"safety stop cleared by {cleared['who']} at 2025-11-27T08:00:00.000+00:00" in caplog.text
        assert wait_until(lambda: resume()["ok"], 30.0)
        assert wait_until(lambda: (station.feed.snapshot.status or {}).get("state") in ("running", "finished"))
    finally:
        client.post("/api/operator/stop", json={})
        session.join(120.0)
