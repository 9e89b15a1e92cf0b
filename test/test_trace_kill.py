"""``kill -9`` of a run at 20 moments: the trace survives whole up to the kill.

The rivet demonstrator runs as ``python -m execution_engine run ... --trace T`` in a child
process; the test reads its console line by line and takes what a kill leaves after the k-th line,
for 20 values of k spread over the run (seeded, one in each twentieth of the console output, so
the moments are chosen by progress, not by sleeps): one run, stopped and its trace copied at each
moment, killed with SIGKILL at the last (the ``killed`` fixture says why a stop's copy is a kill's).  Each trace must parse, end at a complete
record, be reported as cut (no ``run_end``), and hold every state change the console had
printed before the kill -- the trace is written, and flushed, before the console line.
"""
from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from execution_engine.trace_report import read_trace

pytestmark = pytest.mark.xdist_group("trace_kill")  # one worker runs the two runs its fixtures make, once

ROOT = Path(__file__).resolve().parents[1]
MOMENTS = 20
#: Fast enough that a run takes a few seconds, slow enough that the console has a few hundred
#: lines to choose from while the run is still going (the demonstrator is 86 s of robot time).
SPEED = "40"
BOUND = 120.0  # wall seconds any one run may take before the test gives up on it
#: A group's state change on the console: "[   12.345 s] left_arm    Ready -> MoveArm (start)  op 1 ..."
TRANSITION = re.compile(r"^\[\s*(?P<t>-?[\d.]+) s\] (?P<group>\S+)\s+(?P<from>\w+) -> (?P<to>\w+) \((?P<signal>[^)]*)\)")


def command(trace: Path) -> list[str]:
    return [sys.executable, "-m", "execution_engine", "run", "apps_xml/rivet_installation.xml", "--speed", SPEED, "--no-check", "--trace", str(trace)]


def start(trace: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(command(trace), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, bufsize=1)


def transitions(lines: list[str]) -> list[tuple[float, str, str, str, str]]:
    found = []
    for line in lines:
        match = TRANSITION.match(line)
        if match:
            found.append((float(match["t"]), match["group"], match["from"], match["to"], match["signal"]))
    return found


@pytest.fixture(scope="module")
def whole_run(tmp_path_factory: pytest.TempPathFactory) -> int:
    """A run left to finish: how many state-change lines the console shows; its trace is whole."""
    trace = tmp_path_factory.mktemp("whole") / "trace.jsonl"
    done = subprocess.run(command(trace), cwd=ROOT, capture_output=True, text=True, timeout=BOUND)
    assert done.returncode == 0, done.stderr
    summary = read_trace(trace)
    assert not summary.cut and summary.end is not None and summary.end["outcome"] == "finished"
    count = len(transitions(done.stdout.splitlines()))
    assert count > 100
    return count


def moments(total: int) -> list[int]:
    """One kill moment (a number of transition lines read) in each twentieth of the first 90 % of the run."""
    rng = random.Random(13)
    span = 0.9 * total
    return [1 + int(span * (i + rng.random()) / MOMENTS) for i in range(MOMENTS)]


@pytest.fixture(scope="module")
def killed(whole_run: int, tmp_path_factory: pytest.TempPathFactory) -> list[tuple[Path, list[str], str]]:
    """One run, read line by line, with what a kill -9 leaves at each of the 20 moments: the trace as it is then, the
    console lines read, and how the process was taken there.

    At each moment but the last the run is stopped (SIGSTOP, waited for until the kernel reports it stopped), its
    trace copied and the run continued (SIGCONT); at the last it is killed with SIGKILL. A kill leaves the file as it is
    at that instant (what the process had written; nothing of what it still held), and so does a stop: each copy is
    what a kill at that moment leaves, for one run instead of twenty."""
    folder = tmp_path_factory.mktemp("killed")
    trace = folder / "trace.jsonl"
    child = start(trace)
    taken: list[tuple[Path, list[str], str]] = []
    shown: list[str] = []
    seen = 0
    try:
        assert child.stdout is not None
        for index, after in enumerate(moments(whole_run)):
            while seen < after:
                line = child.stdout.readline()
                if not line:  # the run ended
                    break
                shown.append(line.rstrip("\n"))
                if TRANSITION.match(line):
                    seen += 1
            last = index == MOMENTS - 1
            os.kill(child.pid, signal.SIGKILL if last else signal.SIGSTOP)
            if last:
                child.wait(timeout=BOUND)
                how = "killed" if child.returncode == -signal.SIGKILL else f"ended before the kill ({child.returncode})"
            else:
                _, status = os.waitpid(child.pid, os.WUNTRACED)  # returns once it is stopped (does not reap it)
                how = "stopped" if os.WIFSTOPPED(status) else f"ended before the kill ({status})"
            copy = folder / f"trace_{index}.jsonl"
            copy.write_bytes(trace.read_bytes())
            taken.append((copy, list(shown), how))
            if not last:
                os.kill(child.pid, signal.SIGCONT)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    return taken


@pytest.mark.parametrize("moment", range(MOMENTS))
def test_a_run_killed_at_any_moment_leaves_a_whole_trace_up_to_the_kill(moment: int, whole_run: int, killed: list[tuple[Path, list[str], str]]) -> None:
    after = moments(whole_run)[moment]
    trace, shown, how = killed[moment]
    assert how == ("killed" if moment == MOMENTS - 1 else "stopped"), "the run ended before the kill"
    summary = read_trace(trace)
    assert summary.cut, "a killed run's trace must not look whole"
    assert not summary.incomplete_tail and summary.problem_count == 0, summary.lines()
    assert summary.last is not None and summary.last["event"] != "run_end"
    records: dict[tuple[str, str, str, str], list[float]] = {}
    for record in map(json.loads, trace.read_text().splitlines()):
        if record["event"] == "transition":
            records.setdefault((record["group"], record["from"], record["to"], record["signal"]), []).append(record["t"])
    printed = transitions(shown)
    assert len(printed) >= after

    def traced(t: float, *key: str) -> bool:  # the console shows t to the millisecond
        return any(abs(t - at) <= 0.0005 + 1e-9 for at in records.get(key, ()))  # type: ignore[arg-type]

    missing = [p for p in printed if not traced(*p)]
    assert not missing, f"printed on the console before the kill but not in the trace: {missing[:5]}"
    assert "CUT: no run_end record" in "\n".join(summary.lines())
