"""The station's users file and audit file (issue 26 item 5): read as strictly as the token file -- owner-only,
bounded, each bad line refused in one line naming the file, the line and the field -- and appended to without ever
touching another file; hypothesis: any text is read or refused in one such line, any users written read back."""
from __future__ import annotations

import errno
import json
import os
import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from operator_station.access import ENGINEER, OPERATOR, ROLES, AccessError, Who
from operator_station.audit import AuditError, AuditLog, check_audit_file, digest, is_entry, record
from operator_station.users import NAME, hash_password, parse_users, read_users_file

HASH = "sha256$" + "ab" * 16 + "$" + "cd" * 32
ANNA = Who("session", "3f9a0c1e", "127.0.0.1:50000", "anna", OPERATOR)


def users_file(folder: Path, text: str | bytes, mode: int = 0o600, name: str = "users") -> Path:
    path = folder / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    path.chmod(mode)
    return path


# ------------------------------------------------------------------------------------------ the users file
def test_a_users_file_gives_each_user_a_role_and_checks_passwords(tmp_path: Path) -> None:
    path = users_file(tmp_path, f"# people\n\nanna:operator:{hash_password('a-pw')}\n  ben:engineer:{hash_password('b-pw', 'sha256')}  \n")
    users = read_users_file(path)
    assert {n: u.role for n, u in users.items()} == {"anna": OPERATOR, "ben": ENGINEER}
    assert users["anna"].checks("a-pw") and not users["anna"].checks("b-pw") and not users["anna"].checks("")
    assert users["ben"].checks("b-pw") and not users["ben"].checks("b-pw ") and not users["ben"].checks("x" * 2000)


@pytest.mark.parametrize(("text", "line"), [
    ("anna:operator\n", "users:1: a line is name:role:hash, got 2 field(s)"),
    (f"# a\nanna:operator:{HASH}:x\n", "users:2: a line is name:role:hash, got 4 field(s)"),
    (f"an na:operator:{HASH}\n", "users:1: name 'an na' must be 1 to 64 letters, digits, '.', '_' or '-'"),
    (f"anna:Operator:{HASH}\n", "users:1: role 'Operator' of 'anna' must be operator or engineer"),
    (f"anna:operator:{HASH}\nanna:engineer:{HASH}\n", "users:2: name 'anna' is given twice (each user once)"),
    ("anna:operator:sha256$zz$00\n", "users:1: hash of 'anna': a sha256 hash's salt and digest are hexadecimal"),
    ("anna:operator:sha256$ab$cd\n", "users:1: hash of 'anna': a sha256 hash has a salt and a digest of 64 hexadecimal digits"),
    ("anna:operator:scrypt$3$8$1$c2FsdA==$" + "A" * 43 + "=\n", "users:1: hash of 'anna': scrypt's N must be a power of two up to 1048576, r and p 1 to 64, within 512 MiB"),
    ("anna:operator:scrypt$16384$8$1$c2FsdA==$c2FsdA==\n", "users:1: hash of 'anna': an scrypt hash has a salt and a 32-byte key"),
    ("anna:operator:plain\n", "users:1: hash of 'anna': the hash must be scrypt$... or sha256$... (make a line: python -m operator_station.users NAME ROLE)"),
    ("# nobody\n\n", "users: no users (lines name:role:hash; make one: python -m operator_station.users NAME ROLE)"),
])
def test_a_bad_line_is_one_line_naming_the_file_the_line_and_the_field(text: str, line: str) -> None:
    with pytest.raises(AccessError) as refused:
        parse_users(text, "users")
    assert str(refused.value) == line


def test_a_users_file_is_refused_unless_its_owner_alone_reads_it_and_it_is_a_small_text_file(tmp_path: Path) -> None:
    good = f"anna:operator:{HASH}\n"
    for mode in (0o640, 0o604, 0o644):
        path = users_file(tmp_path, good, mode)
        with pytest.raises(AccessError, match=re.escape(f"--users {path}: readable by other users (mode {mode:o}): chmod 600 {path}")):
            read_users_file(path)
    with pytest.raises(AccessError, match="no such file"):
        read_users_file(tmp_path / "nowhere")
    with pytest.raises(AccessError, match="not a file"):
        read_users_file(tmp_path)
    with pytest.raises(AccessError, match="over the 65536 a users file may have"):
        read_users_file(users_file(tmp_path, good * 2000))
    with pytest.raises(AccessError, match=re.escape(f"--users {tmp_path / 'users'}:2: not UTF-8 text")):
        read_users_file(users_file(tmp_path, good.encode() + b"ben:engineer:\xff\n"))
    assert set(read_users_file(users_file(tmp_path, good))) == {"anna"}


LINE_TEXT = st.text(st.sampled_from("anbe:$#\n \t.-_" + "0123456789abcdef" + "ABC=+/é\u202e"), max_size=200)


@settings(max_examples=300, deadline=None)
@given(text=st.one_of(LINE_TEXT, st.text(max_size=300)))
def test_any_text_is_read_into_users_or_refused_in_one_line_naming_the_file_and_its_line(text: str) -> None:
    try:
        users = parse_users(text, "--users cell.users")
    except AccessError as refusal:
        message = str(refusal)
        assert "\n" not in message and "\r" not in message.replace("\\r", "")
        assert re.match(r"--users cell\.users(:\d+)?: ", message), message
        number = re.match(r"--users cell\.users:(\d+): ", message)
        if number:
            assert 1 <= int(number.group(1)) <= len(text.splitlines())
        return
    assert users and all(NAME.fullmatch(n) and u.role in ROLES for n, u in users.items())


USERS = st.dictionaries(st.from_regex(NAME, fullmatch=True), st.tuples(st.sampled_from(ROLES), st.text(min_size=1, max_size=40)), min_size=1, max_size=5)


@settings(max_examples=40, deadline=None)
@given(people=USERS, scrypt=st.booleans())
def test_any_users_written_as_documented_are_read_back_with_their_roles_and_passwords(people: dict[str, tuple[str, str]], scrypt: bool) -> None:
    lines = [f"{name}:{role}:{hash_password(password, 'scrypt' if scrypt and i == 0 else 'sha256')}" for i, (name, (role, password)) in enumerate(people.items())]
    users = parse_users("\n".join(lines) + "\n", "users")
    assert {n: u.role for n, u in users.items()} == {n: r for n, (r, _) in people.items()}
    for name, (_, password) in people.items():
        assert users[name].checks(password) and not users[name].checks(password + "x")


# ------------------------------------------------------------------------------------------ the audit file
def test_entries_are_appended_as_json_lines_to_a_file_only_its_owner_reads(tmp_path: Path) -> None:
    path = tmp_path / "audit.jsonl"
    log = AuditLog.open(path, "audit", lambda: 1764230400.0)
    entry = log.append(ANNA, "save", before=digest(b"old"), after=digest(b"new"), details={"path": "app.xml", "when": "spoofed"})
    log.append(None, "pause", ok=False, answer="no run is going")
    log.close()
    assert (path.stat().st_mode & 0o777) == 0o600
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert lines[0] == entry == {
        "seq": 1, "when": "2025-11-27T08:00:00.000+00:00", "who": "anna", "role": OPERATOR, "kind": "session", "session": "3f9a0c1e",
        "address": "127.0.0.1:50000", "what": "save", "ok": True, "before": "sha256:" + __import__("hashlib").sha256(b"old").hexdigest(),
        "after": digest(b"new"), "path": "app.xml", "detail_when": "spoofed"}  # a detail never replaces the station's own keys
    assert (lines[1]["who"], lines[1]["ok"], lines[1]["answer"]) == ("unknown from unknown", False, "no run is going")
    again = AuditLog.open(path, "audit", lambda: 1764230401.0)  # the next start appends; nothing is lost
    assert again.append(ANNA, "login")["seq"] == 3  # and numbers on from the file's last entry
    again.close()
    assert len(path.read_text().splitlines()) == 3 and all(is_entry(line.encode()) for line in path.read_text().splitlines())
    assert [e["what"] for e in log.newest()] == ["pause", "save"] and [e["what"] for e in log.newest(after=1)] == ["pause"]


def test_an_audit_file_is_never_another_file(tmp_path: Path) -> None:
    other = tmp_path / "app.xml"
    other.write_text("<application/>\n")
    for path, why in ((other, "exists and is not an audit log"), (tmp_path, "not a regular file")):
        with pytest.raises(AuditError, match=re.escape(why)):
            AuditLog.open(path, f"--audit {path}")
    assert other.read_text() == "<application/>\n"
    trace = tmp_path / "run.jsonl"
    trace.write_text('{"event": "run_start", "t": 0}\n')  # JSON lines, but no audit entry
    with pytest.raises(AuditError, match="is not an audit log"):
        check_audit_file(trace, "--audit run.jsonl")
    empty = tmp_path / "empty.jsonl"
    empty.touch()
    assert check_audit_file(empty, "--audit empty.jsonl") == 0  # an empty file is the start of one


class FullDisk:
    def write(self, data: bytes) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def close(self) -> None:
        pass


def test_a_write_that_fails_is_said_once_and_the_entries_are_kept(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    log = AuditLog(tmp_path / "audit.jsonl", _file=FullDisk())  # type: ignore[arg-type]
    log.append(ANNA, "save")
    log.append(ANNA, "pause")
    assert log.problem.endswith("could not be written (No space left on device); entries since are kept in memory only")
    assert [r.levelname for r in caplog.records].count("ERROR") == 1 and len(log.entries) == 2


def test_record_takes_who_and_the_log_from_the_scope_the_guard_leaves(tmp_path: Path) -> None:
    log = AuditLog()
    scope: dict[str, Any] = {"studio.who": ANNA, "studio.audit": log}
    entry = record(scope, "teach", before=None, after=digest("cell"), frame="drill_1")
    assert entry["who"] == "anna" and entry["before"] is None and entry["frame"] == "drill_1" and list(log.entries) == [entry]
