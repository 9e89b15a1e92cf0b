"""Collision checking, the former way against conservative advancement, side by side in one run.

Usage: python bench/collision_sweep.py [--copies 1 2 4 8] [--repeat 3] [--runs 3]

1. The dry run's sweep (cell_runner/dry_run/collisions.py).  The paper's rivet demonstrator with
   its deburr/pick/insert operations repeated ``copies`` times (every copy the same four holes: the
   same motions again, so only the count grows) is dry-run once in this process; its motions are
   then swept ``repeat`` times each way, alternating, on a fresh collision model each time: the
   former fixed sampling (``sweep(step=0.02)``: every 20 ms of motion) and conservative
   advancement (``sweep()``).  Per size: motions, configurations each way, CPU per motion each
   way and their ratio, the new sweep's share of the whole dry run, and whether both found the
   same (nothing, on this application).
2. The simulator at run time.  ``run apps_xml/rivet_installation.xml --speed max --no-check`` in
   this process (the Nextage simulator checking collisions, as ``run`` has it), ``runs`` times each
   way, alternating: the former check of every control period (``scene.contacts`` per tick) and the
   guard (every running motion swept once when it starts, robot_bridges/nextage_sim/guard.py).
   CPU of the whole run and CPU spent checking collisions, the checks' share of the run, ratios.

The machine's baseline is a bare lxml parse of the demonstrator (CPU), printed with the figures.
Medians; CPU is process time (the machine is shared, so wall time is not reported).  Last line: JSON.
"""
from __future__ import annotations

import argparse
import io
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lxml import etree

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app_functions.registry import full_catalog  # noqa: E402
import cell_runner.dry_run.runner as runner  # noqa: E402
from cell_runner.dry_run import dry_run  # noqa: E402
from cell_runner.cli import main as cli  # noqa: E402
from cell_runner.dry_run.collisions import SAMPLED_STEP, scene_of, sweep  # noqa: E402
from core_functions.primitives import describe  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind  # noqa: E402
from robot_bridges.nextage_sim import checks  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
med = statistics.median


def grown(copies: int, folder: Path) -> Path:
    """The demonstrator with operations 2..9 (debur, pick, insert of four holes) ``copies`` times."""
    tree = etree.parse(str(RIVET))
    root = tree.getroot()
    operations = root.findall("operation")
    body, last = operations[1:-1], operations[-1]
    root.remove(last)
    for k in range(1, copies):
        for op in body:
            clone = etree.fromstring(etree.tostring(op))
            clone.set("id", f"{op.get('id')}-{k}")
            root.append(clone)
    root.append(last)
    root.set("cell", str(RIVET.parent / "cells" / "rivet_cell.xml"))
    path = folder / f"rivet_x{copies}.xml"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


class Findings:
    """A recorder for a sweep run again: the real one's calls (spans), findings kept here."""

    def __init__(self, spans: Any) -> None:
        self.spans = spans
        self.found: list[str] = []

    def add(self, group: str, operation: str, function: str, kind: str, primitive: str, message: str, t: float) -> None:
        self.found.append(f"{group} {operation} {function}: {message}")


def cpu(action: Callable[[], Any]) -> tuple[float, Any]:
    start = time.process_time()
    result = action()
    return time.process_time() - start, result


def baseline(repeat: int = 50) -> float:
    """CPU (s) of a bare lxml parse of the demonstrator: the machine's yardstick."""
    data = RIVET.read_bytes()
    return med([cpu(lambda: etree.fromstring(data))[0] for _ in range(repeat)])


def dry_run_sweeps(path: Path, repeat: int) -> dict[str, Any]:
    """One dry run of ``path`` (its motions kept), then both sweeps on them ``repeat`` times, alternating."""
    app = load_application(path, full_catalog())
    captured: dict[str, Any] = {}
    original = runner.sweep

    def keep(app_: Any, scene: Any, initial: Any, motions: Any, grips: Any, recorder: Any) -> Any:
        captured.update(initial=initial, motions=list(motions), grips=list(grips), spans=list(recorder.spans))
        seconds, stats = cpu(lambda: original(app_, scene, initial, motions, grips, recorder))
        captured["in_run"] = seconds
        return stats

    runner.sweep = keep
    try:
        total, report = cpu(lambda: dry_run(app, "nextage-sim", BackendOptions(app.robot)))
    finally:
        runner.sweep = original
    if report.findings:
        raise SystemExit(f"{path}: the dry run found problems: {report.findings[0]}")
    times: dict[str, list[float]] = {"old": [], "new": []}
    stats: dict[str, Any] = {}
    found: dict[str, list[str]] = {}
    for _ in range(repeat):
        for name, step in (("old", SAMPLED_STEP), ("new", None)):
            scene = scene_of(app)
            recorder = Findings(captured["spans"])
            seconds, stats[name] = cpu(lambda: sweep(app, scene, captured["initial"], captured["motions"], captured["grips"], recorder, step))
            times[name].append(seconds)
            found[name] = recorder.found
    motions = stats["new"].motions
    old, new = med(times["old"]), med(times["new"])
    return {
        "motions": motions,
        "configurations_old": stats["old"].samples,
        "configurations_new": stats["new"].samples,
        "ms_per_motion_old": round(1000 * old / motions, 3),
        "ms_per_motion_new": round(1000 * new / motions, 3),
        "ratio_old_vs_new": round(old / new, 1),
        "dry_run_cpu_s": round(total, 2),
        "sweep_share_of_dry_run": round(captured["in_run"] / total, 3),
        "dry_run_ms_per_motion": round(1000 * total / motions, 1),
        "same_findings": found["old"] == found["new"],
    }


def per_tick(guard: Any, now: float, q: Any, moving: Any, work: Any, job: Any, motion: Any, t: float) -> None:
    """The simulator's former check: every pair measured at every control period."""
    hits = [c for c in guard.scene.contacts(q, work) if c.collision]
    if hits:
        worst = min(hits, key=lambda c: c.distance)
        raise BridgeError(FaultKind.COLLISION, f"{', '.join(sorted(job.groups))}: {describe(job.primitive)} at t = {t:.3f} s: {worst.describe(guard.scene.margin)}")


def simulator_runs(runs: int) -> dict[str, Any]:
    """The demonstrator run at --speed max --no-check, per-tick checks against the guard, alternating."""
    new_check = checks.check_collisions
    spent = [0.0]
    calls = [0]

    def timed(check: Callable[..., None]) -> Callable[..., None]:
        def wrapper(*args: Any) -> None:
            start = time.process_time()
            try:
                check(*args)
            finally:
                spent[0] += time.process_time() - start
                calls[0] += 1
        return wrapper

    rows: dict[str, list[tuple[float, float, int]]] = {"old": [], "new": []}
    try:
        for _ in range(runs):
            for name, check in (("old", per_tick), ("new", new_check)):
                checks.check_collisions = timed(check)
                spent[0], calls[0] = 0.0, 0
                with tempfile.TemporaryDirectory() as folder:
                    args = ["run", str(RIVET), "--speed", "max", "--no-check", "--trajectory-db", str(Path(folder) / "t.sqlite")]
                    seconds, code = cpu(lambda: cli(args, io.StringIO(), io.StringIO()))
                if code != 0:
                    raise SystemExit(f"the demonstrator's run failed (exit {code}) with the {name} check")
                rows[name].append((seconds, spent[0], calls[0]))
    finally:
        checks.check_collisions = new_check
    out: dict[str, Any] = {}
    for name, values in rows.items():
        out[f"run_cpu_s_{name}"] = round(med(v[0] for v in values), 2)
        out[f"check_cpu_s_{name}"] = round(med(v[1] for v in values), 3)
        out[f"check_share_{name}"] = round(med(v[1] / v[0] for v in values), 3)
        out[f"ticks_{name}"] = values[-1][2]
    out["check_ratio_old_vs_new"] = round(out["check_cpu_s_old"] / out["check_cpu_s_new"], 1)
    out["run_ratio_old_vs_new"] = round(out["run_cpu_s_old"] / out["run_cpu_s_new"], 2)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--repeat", type=int, default=3, help="sweeps of each kind per size (median)")
    parser.add_argument("--runs", type=int, default=3, help="simulator runs of each kind (median; 0: skip)")
    args = parser.parse_args()
    parse = baseline()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for copies in args.copies:
            rows.append({"copies": copies, **dry_run_sweeps(grown(copies, Path(folder)), args.repeat)})
    print(f"baseline: lxml parse of the demonstrator {parse * 1e6:.0f} us CPU")
    print(f"{'copies':>6} {'motions':>8} {'configs old':>11} {'new':>6} {'ms/motion old':>13} {'new':>7} {'old/new':>7} {'new/parse':>9} {'sweep share':>11} {'dry run ms/motion':>17} {'same':>5}")
    for r in rows:
        print(f"{r['copies']:>6} {r['motions']:>8} {r['configurations_old']:>11} {r['configurations_new']:>6} {r['ms_per_motion_old']:>13} "
              f"{r['ms_per_motion_new']:>7} {r['ratio_old_vs_new']:>6}x {r['ms_per_motion_new'] / 1000 / parse:>8.1f}x {r['sweep_share_of_dry_run']:>11.1%} "
              f"{r['dry_run_ms_per_motion']:>17} {str(r['same_findings']):>5}")
    sim = simulator_runs(args.runs) if args.runs > 0 else {}
    if sim:
        print("simulator, run --speed max --no-check of the demonstrator (old: every tick; new: once per motion):")
        print(f"  run CPU      old {sim['run_cpu_s_old']} s   new {sim['run_cpu_s_new']} s   old/new {sim['run_ratio_old_vs_new']}x")
        print(f"  checks CPU   old {sim['check_cpu_s_old']} s ({sim['check_share_old']:.0%} of the run)   new {sim['check_cpu_s_new']} s "
              f"({sim['check_share_new']:.1%})   old/new {sim['check_ratio_old_vs_new']}x   ({sim['ticks_new']} ticks)")
    print(json.dumps({"bench": "collision_sweep", "repeat": args.repeat, "runs": args.runs, "lxml_parse_us": round(parse * 1e6, 1), "rows": rows, "simulator": sim}))


if __name__ == "__main__":
    main()
