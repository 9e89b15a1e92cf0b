"""A run killed with SIGKILL at a chosen moment, and the trace it leaves: shared by the resume tests."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def records(path: Path) -> list[dict[str, Any]]:
    """The trace's records, without the line the kill cut."""
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:  # the line the kill cut
            continue
    return out


def run_and_kill(app: str | Path, folder: Path, ready: Callable[[bytes], bool]) -> Path:
    """Run ``app`` in a process of its own (trace and checkpoint in ``folder``) and kill -9 it once ``ready`` holds
    for what its trace holds so far; the trace's path."""
    trace = folder / "run.jsonl"
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "run", str(app), "--speed", "max", "-q", "--no-check",
         "--trace", str(trace), "--checkpoint", str(folder / "run.sqlite")],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 120
    while process.poll() is None and time.monotonic() < deadline:
        try:
            if ready(trace.read_bytes()):
                break
        except FileNotFoundError:  # not created yet
            pass
        time.sleep(0.002)  # polling the file the run writes, not waiting for a guess
    assert process.poll() is None, f"the run ended before the kill: {process.stderr.read().decode() if process.stderr else ''}"
    os.kill(process.pid, signal.SIGKILL)
    process.wait(30)
    return trace
