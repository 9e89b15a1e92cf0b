"""``studio --users FILE --operator-token-file FILE`` as a process: it says how to get in and where the audit log
goes, a page gets the login form, an operator logged in or holding the operators' token is refused a save, and
the audit file beside --trace holds each of those, mode 600, appended on the next start.  Loopback, bounded."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("uvicorn", reason="the studio extra (starlette, uvicorn) is not installed")
import httpx  # noqa: E402

from operator_station.testing import free_port  # noqa: E402
from operator_station.users import hash_password  # noqa: E402
from test_studio_signals import START_WITHIN, STOP_WITHIN, first_line, wait_serving  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OPERATOR_TOKEN = "o" * 43


def start(folder: Path, port: int) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "studio", "rivet_installation.xml", "--port", str(port), "--users", "cell.users",
         "--operator-token-file", "operators.token", "--trace", "runs/run.jsonl"],
        cwd=folder, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def stop(process: subprocess.Popen[str]) -> str:
    """SIGTERM, the process gone within the station's bound; its stdout after the first line."""
    process.send_signal(signal.SIGTERM)
    try:
        process.wait(STOP_WITHIN + 3.0)  # the bound itself is test_studio_signals'; here: it ends by itself
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10.0)
    out = process.stdout.read() if process.stdout else ""
    for stream in (process.stdout, process.stderr):
        if stream is not None:
            stream.close()
    return out


def test_a_station_with_users_and_an_operators_token_logs_in_refuses_and_audits_to_its_file(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "apps_xml" / "cells", tmp_path / "cells")
    shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", tmp_path / "rivet_installation.xml")
    (tmp_path / "runs").mkdir()
    for name, text in (("cell.users", f"anna:operator:{hash_password('anna-pw')}\n"), ("operators.token", OPERATOR_TOKEN + "\n")):
        (tmp_path / name).write_text(text)
        (tmp_path / name).chmod(0o600)
    original = (tmp_path / "rivet_installation.xml").read_bytes()
    audit = tmp_path / "runs" / "studio.audit.jsonl"
    for attempt in range(2):
        port = free_port()
        process = start(tmp_path, port)
        base = f"http://127.0.0.1:{port}"
        try:
            assert first_line(process).startswith(f"operator station on {base}/")
            wait_serving(process, port)
            with httpx.Client(base_url=base, headers={"Origin": base}, timeout=START_WITHIN) as page:
                assert 'id="login-form"' in page.get("/").text
                assert page.post("/login", json={"name": "anna", "password": "anna-pw"}).json()["role"] == "operator"
                document = page.get("/api/document").json()["document"]
                refused = page.post("/api/save", json={"path": "rivet_installation.xml", "document": document})
                assert refused.status_code == 403 and refused.json()["error"] == "save: needs the engineer role; this session is operator 'anna'"
                script = httpx.post(f"{base}/api/save", json={"path": "rivet_installation.xml", "document": document},
                                    headers={"Authorization": f"Bearer {OPERATOR_TOKEN}"}, timeout=START_WITHIN)
                assert script.status_code == 403 and script.json()["error"].endswith("this token is operator 'operator token'")
        finally:
            out = stop(process)
        assert f"open {base}/ and log in (1 user(s) of cell.users)" in out and f"operators open {base}/?token=TOKEN with the token of operators.token" in out
        assert "audit log: runs/studio.audit.jsonl (appended)" in out
        entries = [json.loads(line) for line in audit.read_text().splitlines()]
        assert [(e["what"], e["who"], e["ok"]) for e in entries] == [("login", "anna", True), ("save", "anna", False), ("save", "operator token", False)] * (attempt + 1)
        assert [e["seq"] for e in entries] == list(range(1, 3 * attempt + 4)) and (audit.stat().st_mode & 0o777) == 0o600  # seq goes on
    assert (tmp_path / "rivet_installation.xml").read_bytes() == original
