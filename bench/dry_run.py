"""``validate --simulate`` against plain ``validate``: the rivet demonstrator and generated applications of growing size.

Usage: python bench/dry_run.py [--operations 250 500 1000] [--repeat 5] [--repeat-large 1]

Both commands run in this process through the CLI's ``main`` (the catalog is built by each call,
as on the command line), side by side on the same files.  The large application is the one
``bench/load_validate.py`` generates, with its cell moved within reach of the Nextage's arms, tool
pointing down (load_validate's cell only has to be valid: its frames lie beyond the arms, and a
dry run of it would measure nothing but failing inverse kinematics).  The dry run still finds the
problems the generator writes, such as replays of trajectory names never recorded.  For each
file: wall and CPU time of both commands, the dry run's predicted robot time, how many times
faster than the robot the dry run is, and the dry run's CPU time per operation and per motion it
checked for collisions (the sizes side by side show whether the cost grows linearly).  The dry run
is also run with the former collision sweep (fixed samples every 20 ms of motion,
``cell_runner/dry_run/collisions.py`` ``sweep(step=0.02)``), alternating with the current one
(conservative advancement): CPU per motion both ways and their ratio.  Each ``validate --simulate``
gets a fresh, empty verdict cache (``XDG_CACHE_HOME``), so every one is a real dry run.  Last line: JSON.
"""
from __future__ import annotations

import argparse
import functools
import io
import json
import os
import re
import statistics
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from lxml import etree

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from load_validate import catalog, generate, measure  # noqa: E402

import cell_runner.dry_run.runner as runner  # noqa: E402
from cell_runner.cli import main as cli  # noqa: E402
from cell_runner.dry_run.collisions import SAMPLED_STEP  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RIVET = ROOT / "apps_xml" / "rivet_installation.xml"
DOWN = "3.14159265 0 1.57079633"  # tool pointing down, as the rivet cell's holes and slots


def within_reach(cell: Path) -> None:
    """Move the generated cell's fixtures in front of the robot (x 0.30-0.40 m, |y| <= 0.08 m, z 0.02 m)."""
    tree = etree.parse(str(cell))
    fixtures = tree.getroot().findall("frame")
    for k, fixture in enumerate(fixtures):
        fixture.set("xyz", f"0.30 {-0.08 + 0.16 * k / max(1, len(fixtures) - 1):.3f} 0.02")
        for i, frame in enumerate(fixture.findall("frame")):
            frame.set("xyz", f"{0.005 * i:.3f} 0 0")
            frame.set("rpy", DOWN)
    tree.write(str(cell), xml_declaration=True, encoding="UTF-8")


def command(args: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with tempfile.TemporaryDirectory() as cache:  # no verdict kept from an earlier run: a real dry run each time
        before = os.environ.get("XDG_CACHE_HOME")
        os.environ["XDG_CACHE_HOME"] = cache
        try:
            return cli(args, out, err), out.getvalue(), err.getvalue()
        finally:
            if before is None:
                os.environ.pop("XDG_CACHE_HOME", None)
            else:
                os.environ["XDG_CACHE_HOME"] = before


@contextmanager
def former_sweep() -> Iterator[None]:
    """The dry run with the former collision sweep: fixed samples every 20 ms of motion."""
    current = runner.sweep
    runner.sweep = functools.partial(current, step=SAMPLED_STEP)
    try:
        yield
    finally:
        runner.sweep = current


def compare(path: Path, repeat: int, db: str) -> dict[str, object]:
    """Time both commands on ``path``; the dry run's prediction and findings from its last output."""
    plain_code, _, plain_err = command(["validate", str(path)])
    if plain_code != 0:
        raise SystemExit(f"{path} does not validate:\n{plain_err}")
    last: list[tuple[int, str, str]] = []
    plain, plain_cpu = measure(lambda: command(["validate", str(path)]), repeat)
    dry, dry_cpu, old_cpu = [], [], []
    for _ in range(repeat):  # alternating: the current sweep, then the former
        wall, cpu = measure(lambda: last.append(command(["validate", "--simulate", str(path), "--trajectory-db", db])), 1)
        dry += wall
        dry_cpu += cpu
        with former_sweep():
            old_cpu += measure(lambda: command(["validate", "--simulate", str(path), "--trajectory-db", db]), 1)[1]
    code, out, err = last[-1]
    predicted = re.search(r"predicted cycle time +([\d.]+) s", out)
    if predicted is None:
        raise SystemExit(f"the dry run of {path} printed no prediction (exit {code}):\n{err[-2000:]}")
    findings = len([line for line in err.splitlines() if re.match(r".+:\d+:\d+: operation ", line)])
    robot = float(predicted.group(1))
    swept = re.search(r"collisions checked: (\d+) motions, (\d+) configurations", out)
    motions = int(swept.group(1)) if swept else 0
    operations = len(etree.parse(str(path)).getroot().findall("operation"))
    med = statistics.median
    return {
        "file": path.name,
        "validate_ms": round(med(plain) * 1000, 1),
        "validate_cpu_ms": round(med(plain_cpu) * 1000, 1),
        "simulate_ms": round(med(dry) * 1000, 1),
        "simulate_cpu_ms": round(med(dry_cpu) * 1000, 1),
        "ratio_simulate_vs_validate": round(med(dry) / med(plain), 1),
        "predicted_robot_s": robot,
        "faster_than_robot": round(robot / med(dry), 1),
        "findings": findings,
        "exit": code,
        "operations": operations,
        "motions": motions,
        "configurations": int(swept.group(2)) if swept else 0,
        "cpu_ms_per_operation": round(med(dry_cpu) * 1000 / operations, 2),
        "cpu_ms_per_motion": round(med(dry_cpu) * 1000 / motions, 2) if motions else None,
        "former_sweep_cpu_ms": round(med(old_cpu) * 1000, 1),
        "former_sweep_cpu_ms_per_motion": round(med(old_cpu) * 1000 / motions, 2) if motions else None,
        "ratio_former_vs_now": round(med(old_cpu) / med(dry_cpu), 2),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operations", type=int, nargs="+", default=[250, 500, 1000], help="sizes of the generated applications")
    parser.add_argument("--repeat", type=int, default=5, help="runs of each command on the rivet demonstrator (median)")
    parser.add_argument("--repeat-large", type=int, default=1, help="runs of each command on the large application")
    args = parser.parse_args()
    functions, source = catalog()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        db = str(folder / "none.sqlite")  # no trajectories recorded before: what this run records is thrown away
        rows = [compare(RIVET, args.repeat, db)]
        for size in args.operations:
            sub = folder / str(size)
            sub.mkdir()
            large = generate(functions, size, sub)
            within_reach(sub / "cells" / "bench_cell.xml")
            rows.append(compare(large, args.repeat_large, db))
    print(f"catalog: {source}; generated applications: {', '.join(map(str, args.operations))} operations")
    print(f"{'file':<26} {'ops':>6} {'validate':>10} {'--simulate':>12} {'ratio':>7} {'robot time':>12} {'x robot':>8} {'findings':>9} {'motions':>8} {'cpu/op':>9} {'cpu/motion':>11} {'former sweep':>13} {'former/now':>10}")
    for r in rows:
        print(f"{r['file']:<26} {r['operations']:>6} {r['validate_ms']:>8} ms {r['simulate_ms']:>9} ms {r['ratio_simulate_vs_validate']:>6}x "
              f"{r['predicted_robot_s']:>10} s {r['faster_than_robot']:>7}x {r['findings']:>9} {r['motions']:>8} {r['cpu_ms_per_operation']:>6} ms {r['cpu_ms_per_motion']:>8} ms "
              f"{r['former_sweep_cpu_ms_per_motion']:>10} ms {r['ratio_former_vs_now']:>9}x")
        print(f"{'':<26} cpu {r['validate_cpu_ms']:>7} ms cpu {r['simulate_cpu_ms']:>7} ms (cpu/motion: the whole dry run; former sweep: the same with 20 ms samples)")
    print(json.dumps({"bench": "dry_run", "catalog": source, "operations": args.operations, "repeat": args.repeat,
                      "repeat_large": args.repeat_large, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
