"""The collision sweep of ``validate --simulate``: time per checked motion, as the application grows.

Usage: python bench/collision_sweep.py [--copies 1 2 4 8 16] [--repeat 3]

The paper's rivet demonstrator with its deburr/pick/insert operations repeated ``copies`` times
(every copy the same four holes: the same motions again, so the work per motion is the same and
only the count grows) is dry-run in this process; the sweep (cell_runner/dry_run/collisions.py)
is timed on its own, beside the rest of the dry run (the baseline: the engine, machines, skills
and simulator that produce the motions).  Per size: motions and configurations checked, sweep
time, time per motion and per configuration, and the sweep's share of the whole dry run.  "Close
to linear" reads as a flat time-per-motion column.  Last line: JSON.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from lxml import etree

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.dry_run import dry_run  # noqa: E402
import cell_runner.dry_run.runner as runner  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"


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


def measure(path: Path, repeat: int) -> dict[str, float]:
    app = load_application(path, full_catalog())
    sweep_times, totals, stats = [], [], None
    original = runner.sweep

    def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
        nonlocal stats
        start = time.perf_counter()
        stats = original(*args, **kwargs)
        sweep_times.append(time.perf_counter() - start)
        return stats

    runner.sweep = timed
    try:
        for _ in range(repeat):
            start = time.perf_counter()
            report = dry_run(app, "nextage-sim", BackendOptions(app.robot))
            totals.append(time.perf_counter() - start)
            if report.findings:
                raise SystemExit(f"{path}: the dry run found problems: {report.findings[0]}")
    finally:
        runner.sweep = original
    assert stats is not None
    sweep = statistics.median(sweep_times)
    total = statistics.median(totals)
    return {
        "motions": stats.motions,
        "configurations": stats.samples,
        "sweep_ms": round(1000 * sweep, 1),
        "us_per_motion": round(1e6 * sweep / stats.motions, 1),
        "us_per_configuration": round(1e6 * sweep / stats.samples, 1),
        "dry_run_without_sweep_ms": round(1000 * (total - sweep), 1),
        "sweep_share": round(sweep / total, 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for copies in args.copies:
            row = {"copies": copies, **measure(grown(copies, Path(folder)), args.repeat)}
            rows.append(row)
    base = rows[0]["us_per_motion"]
    print(f"{'copies':>6} {'motions':>8} {'configs':>8} {'sweep ms':>9} {'us/motion':>10} {'vs first':>8} {'us/config':>10} {'rest of dry run ms':>19} {'sweep share':>11}")
    for row in rows:
        print(
            f"{row['copies']:>6} {row['motions']:>8} {row['configurations']:>8} {row['sweep_ms']:>9} {row['us_per_motion']:>10} "
            f"{row['us_per_motion'] / base:>8.2f} {row['us_per_configuration']:>10} {row['dry_run_without_sweep_ms']:>19} {row['sweep_share']:>11.1%}"
        )
    print(json.dumps({"bench": "collision_sweep", "repeat": args.repeat, "rows": rows}))


if __name__ == "__main__":
    main()
