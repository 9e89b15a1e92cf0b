"""A run killed with SIGKILL at a chosen moment, and the trace it leaves: shared by the resume tests."""
from __future__ import annotations

import json
import os
import shutil
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


def run_and_freeze(app: str | Path, folder: Path, points: list[Callable[[bytes], bool]]) -> list[Path]:
    """Run ``app`` once in a process of its own and take what a kill -9 would leave at each of ``points`` in turn.

    At each point but the last the process is stopped (SIGSTOP, waited for until the kernel reports it stopped), its
    folder -- trace, checkpoint with its -wal and -shm, home -- copied to ``folder/cut_<i>``, and the process continued
    (SIGCONT); at the last point it is killed with SIGKILL and its folder copied the same way. A kill leaves a
    process's files as they are at that instant (what it had written, nothing of what it still held); a stopped
    process's files are that instant's too, so each copy is what a kill there leaves, for the price of one run instead
    of one per point. The run is given its outputs by names relative to its folder, and its own home and XDG folders
    there, so a copy is whole by itself: run a resume with the copy as the working directory and ``env(copy)``.
    Returns the copies' folders, in the order of ``points``."""
    live = folder / "live"
    (live / "home").mkdir(parents=True)  # some programs want the home to exist
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "run", str(Path(app).resolve()), "--speed", "max", "-q", "--no-check",
         "--trace", "run.jsonl", "--checkpoint", "run.sqlite"],
        cwd=live, env={**os.environ, **env(live), "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    cuts: list[Path] = []
    try:
        deadline = time.monotonic() + 120
        for index, ready in enumerate(points):
            while process.poll() is None and time.monotonic() < deadline:
                try:
                    if ready((live / "run.jsonl").read_bytes()):
                        break
                except FileNotFoundError:  # not created yet
                    pass
                time.sleep(0.002)  # polling the file the run writes, not waiting for a guess
            assert process.poll() is None, f"the run ended before the kill: {process.stderr.read().decode() if process.stderr else ''}"
            last = index == len(points) - 1
            os.kill(process.pid, signal.SIGKILL if last else signal.SIGSTOP)
            if last:
                process.wait(30)
            else:
                _, status = os.waitpid(process.pid, os.WUNTRACED)  # returns once it is stopped (does not reap it)
                assert os.WIFSTOPPED(status), f"the run ended before the kill: status {status}"
            cuts.append(shutil.copytree(live, folder / f"cut_{index}", symlinks=True))
            if not last:
                os.kill(process.pid, signal.SIGCONT)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(30)
    assert process.returncode == -signal.SIGKILL
    return cuts


def env(folder: Path) -> dict[str, str]:
    """The home and XDG folders of a run made by ``run_and_freeze`` (the trajectory database, kept verdicts)."""
    base = folder.resolve()
    return {"HOME": str(base / "home"), "XDG_CACHE_HOME": str(base / "cache"), "XDG_DATA_HOME": str(base / "data"),
            "XDG_CONFIG_HOME": str(base / "config"), "XDG_STATE_HOME": str(base / "state")}
