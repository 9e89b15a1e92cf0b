"""Start-up: how soon a command does its work, against starting Python and importing lxml.

Usage: python bench/startup.py [--repeat 5] [--app apps_xml/rivet_installation.xml] [--before DIR] [--whole]

Each case is a fresh process, as a person starts it (``python -m execution_engine ...`` from the source
tree), timed from its start by wall clock and by the CPU it used (children's rusage):

* ``lxml``: ``python -c "import lxml.etree"``, the floor of any Python program that reads XML (the baseline);
* ``validate``, ``functions --json``: the whole process;
* ``run checked (kept verdict)``: ``run APP --speed max``, its dry run's verdict already kept (a first run
  fills the cache in a folder of this bench's own), until the first state transition is printed (a round in
  which the verdict was not found, because the program's files changed meanwhile, is counted and said);
* ``run checked (fresh)``: the same with an empty cache: the dry run first (its own cost is bench/dry_run.py's);
* ``run --no-check``: until the first state transition;
* with ``--whole``, ``run checked, whole (kept verdict)`` and ``run checked, whole (fresh)``: the same run to its
  end (the demonstrator finished), its total CPU -- with the dry run first in the fresh case.

A run is stopped (SIGTERM: the operator's stop) once its first transition is printed.  Cases are
interleaved, round by round, so a machine shared with other work weighs on each alike; the figures are
the medians over ``--repeat`` rounds, and each case's ratio to ``lxml`` is taken within a round, then the
median of those.  The aim (issue 22): the first transition of a checked run within 1 s; validate within
3x lxml.  Last line: JSON.
"""
from __future__ import annotations

import argparse
import compileall
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = [sys.executable, "-m", "execution_engine"]
TRANSITION = " -> "  # a live line of a state transition: "[    0.000 s] left_arm    Ready -> Motion (...)"
TIMEOUT = 120.0
KEPT = "dry run: unchanged since the check of "


@dataclass(frozen=True)
class Case:
    name: str
    argv: list[str]
    until_transition: bool = False
    fresh_cache: bool = False
    root: Path = ROOT  # the tree it runs from (--before: another)


@dataclass(frozen=True)
class Sample:
    wall_ms: float
    cpu_ms: float
    kept: bool = False  # the run said its dry run's verdict was kept ("dry run: unchanged since ...")


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(case: Case, env: dict[str, str]) -> Sample:
    """One fresh process of ``case``: wall time to its exit or first transition, and its CPU time."""
    env = {**env, "PYTHONPATH": str(case.root)}
    if case.fresh_cache:
        env = {**env, "XDG_CACHE_HOME": tempfile.mkdtemp(prefix="startup_cache_")}
    cpu = children_cpu()
    start = time.perf_counter()
    child = subprocess.Popen(case.argv, cwd=case.root, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert child.stdout is not None
    elapsed: float | None = None
    kept = False
    for line in child.stdout:
        kept = kept or line.startswith(KEPT)
        if case.until_transition and TRANSITION in line:
            elapsed = time.perf_counter() - start
            child.send_signal(signal.SIGTERM)  # the operator's stop: the run ends at once
            break
    child.stdout.read()
    code = child.wait(TIMEOUT)
    if elapsed is None:
        elapsed = time.perf_counter() - start
        if case.until_transition:
            raise SystemExit(f"{case.name}: no state transition printed (exit {code})")
        if code != 0:
            raise SystemExit(f"{case.name}: exit {code}")
    return Sample(1000 * elapsed, 1000 * (children_cpu() - cpu), kept)


def rounds(cases: list[Case], repeat: int, env: dict[str, str], say: Callable[[str], None]) -> dict[str, list[Sample]]:
    """``repeat`` rounds of every case, the order turning from round to round."""
    found: dict[str, list[Sample]] = {c.name: [] for c in cases}
    for k in range(repeat):
        turn = cases[k % len(cases):] + cases[:k % len(cases)]
        for case in turn:
            found[case.name].append(measure(case, env))
        say(f"round {k + 1}/{repeat}: " + ", ".join(f"{c.name} {found[c.name][-1].wall_ms:.0f} ms" for c in cases))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--app", default="apps_xml/rivet_installation.xml")
    parser.add_argument("--before", metavar="DIR", type=Path, help="another tree (git archive COMMIT | tar -x -C DIR): its validate and runs, interleaved")
    parser.add_argument("--whole", action="store_true", help="also the checked run to its end: its total CPU, verdict kept and fresh")
    args = parser.parse_args()
    cache = tempfile.mkdtemp(prefix="startup_kept_")
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "XDG_CACHE_HOME": cache}  # unbuffered: as on a terminal
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: the bytecode compiled once, not at every start
    run = [*PROGRAM, "run", args.app, "--speed", "max"]
    cases = [
        Case("lxml", [sys.executable, "-c", "import lxml.etree"]),
        Case("validate", [*PROGRAM, "validate", args.app]),
        Case("functions --json", [*PROGRAM, "functions", "--json"]),
        Case("run checked (kept verdict)", run, until_transition=True),
        Case("run --no-check", [*run, "--no-check"], until_transition=True),
        Case("run checked (fresh)", run, until_transition=True, fresh_cache=True),
    ]
    if args.whole:
        cases += [Case("run checked, whole (kept verdict)", run), Case("run checked, whole (fresh)", run, fresh_cache=True)]
    if args.before is not None:
        before = args.before.resolve()
        cases += [
            Case("before: validate", [*PROGRAM, "validate", args.app], root=before),
            Case("before: run checked", run, until_transition=True, fresh_cache=True, root=before),
            Case("before: run --no-check", [*run, "--no-check"], until_transition=True, root=before),
        ]
    for tree in {case.root for case in cases}:  # bytecode as an install has it, written once before anything is timed
        for package in ("core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges", "cell_runner", "operator_station"):
            compileall.compile_dir(str(tree / package), quiet=1)
    filled = subprocess.run([*run, "-q"], cwd=ROOT, env={**env, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=600, check=False)
    if filled.returncode != 0:
        raise SystemExit(f"the first run (filling the cache) failed: {filled.stderr.strip()[-300:]}")
    found = rounds(cases, args.repeat, env, print)
    kept_cases = [name for name in found if "kept verdict" in name]
    missed = sum(1 for name in kept_cases for s in found[name] if not s.kept)  # the program's files changed meanwhile (a tree being edited): checked again
    if missed:
        print(f"{', '.join(kept_cases)}: {missed} of {sum(len(found[n]) for n in kept_cases)} found no kept verdict (the sources changed meanwhile) and dry-ran")
    base = found["lxml"]
    summary: dict[str, object] = {"app": args.app, "repeat": args.repeat, "kept_verdict_missed": missed}
    print(f"\n{'case':<34} {'wall ms (median)':>17} {'cpu ms (median)':>16} {'x lxml wall':>12} {'x lxml cpu':>11}")
    for name, every in found.items():
        pairs = [(s, b) for s, b in zip(every, base) if s.kept or name not in kept_cases] or list(zip(every, base))
        samples = [s for s, _ in pairs]
        wall = statistics.median(s.wall_ms for s in samples)
        cpu = statistics.median(s.cpu_ms for s in samples)
        ratio_wall = statistics.median(s.wall_ms / b.wall_ms for s, b in pairs)
        ratio_cpu = statistics.median(s.cpu_ms / max(b.cpu_ms, 1e-3) for s, b in pairs)
        print(f"{name:<34} {wall:17.0f} {cpu:16.0f} {ratio_wall:12.1f} {ratio_cpu:11.1f}")
        summary[name] = {"wall_ms": round(wall, 1), "cpu_ms": round(cpu, 1), "ratio_wall": round(ratio_wall, 2), "ratio_cpu": round(ratio_cpu, 2),
                         "wall_ms_range": [round(min(s.wall_ms for s in samples), 1), round(max(s.wall_ms for s in samples), 1)]}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
