"""A scaled run's cycle time against the dry run's prediction, on a quiet and on a loaded computer.

    python bench/paced_clock.py [--speed 10] [--rounds 2] [--burners 2] [--burn-seconds 600] [--iterations 200000]

First what one turn of the event loop costs (``await asyncio.sleep(0)``, which makes every turn
select and run one callback, ``--iterations`` times; CPU time of this process, median of five):
on asyncio's own loop, on a :class:`PacedLoop` not paced (what every real-clock run now uses) and
paced (``--speed 10``), and with a 1 ms timer each turn (``clock.sleep``: a wait a paced loop counts).

Then the rivet demonstrator (``apps_xml/rivet_installation.xml``) on the Nextage simulator, in one
process as ``run`` has it, three ways, alternating, ``--rounds`` times each:

* ``wall-scaled``: wall time times the speed factor (the scaled clock before the paced loop:
  ``Clock(speed)`` on a loop that counts wall time), so every render, detection and every moment
  the computer spent elsewhere passes as robot time;
* ``paced``: ``scaled_clock(speed)``, what ``run --speed 10`` uses now: only the loop's idle waits
  count, each at most to its timer;
* ``max``: simulated time (``--speed max``), for the CPU the run itself needs.

First on the computer as it is, then beside ``--burners`` processes spinning on the CPU (each ends
by itself after ``--burn-seconds``, and is killed when the bench ends).  Each row: the cycle time
(the run report's total), its ratio to the dry run's prediction (the aim: within 1 %), retries and
errors, the wall time and its ratio to the ideal ``cycle / speed``.  The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.deployment import deploy_local  # noqa: E402
from cell_runner.dry_run.runner import dry_run  # noqa: E402
from execution_engine.app_model import Application, load_application  # noqa: E402
from execution_engine.engine.report import RunReport  # noqa: E402
from node_transport.clock import Clock, run_with_clock, scaled_clock, simulated_clock  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402

APP = ROOT / "apps_xml" / "rivet_installation.xml"
AIM = 0.01  # the cycle time within 1 % of the prediction


def loop_turns(kind: str, iterations: int, timer: bool) -> float:
    """CPU seconds per turn of a loop of ``kind`` (asyncio, unpaced, paced), by sleep(0) or a 1 ms clock sleep."""
    clock = Clock(1.0) if kind != "paced" else scaled_clock(10.0)

    async def turns(c: Clock) -> float:
        start = time.process_time()
        for _ in range(iterations):
            if timer:
                await c.sleep(0.001 * c.speed)  # 1 ms of waiting at any speed
            else:
                await asyncio.sleep(0)
        return (time.process_time() - start) / iterations

    if kind == "asyncio":
        loop = asyncio.new_event_loop()
        try:
            clock.bind(loop)
            return loop.run_until_complete(turns(clock))
        finally:
            loop.close()
    return run_with_clock(turns, clock)


def loop_costs(iterations: int) -> dict[str, float]:
    """Median CPU microseconds per turn, for each loop and each way of turning."""
    figures = {}
    for timer in (False, True):
        count = iterations if not timer else max(100, iterations // 100)
        for kind in ("asyncio", "unpaced", "paced"):
            samples = [loop_turns(kind, count, timer) for _ in range(5)]
            figures[f"{kind}_{'timer' if timer else 'turn'}_us"] = round(statistics.median(samples) * 1e6, 2)
    return figures


def run_once(app: Application, clock: Clock, db: str) -> tuple[RunReport, float, float]:
    """One run on ``clock``: its report, wall seconds and CPU seconds of this process."""
    options = BackendOptions(robot=app.robot)

    async def main(c: Clock) -> RunReport:
        backend = await create_backend("nextage-sim", c, options)
        deployment = await deploy_local(c, app.robot, backend, machine_parameters={"trajectory_db": db})
        try:
            return await deployment.engine.run(app)
        finally:
            await deployment.close()

    wall, cpu = time.perf_counter(), time.process_time()
    report = run_with_clock(main, clock)
    return report, time.perf_counter() - wall, time.process_time() - cpu


@contextmanager
def burners(count: int, seconds: float) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``count`` processes spinning on the CPU, each ending by itself after ``seconds``."""
    spin = f"import time\nend = time.monotonic() + {seconds!r}\nwhile time.monotonic() < end: pass\n"
    procs = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(count)]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def measure(app: Application, speed: float, rounds: int, predicted: float, tmp: Path) -> dict[str, dict[str, Any]]:
    sides: dict[str, list[tuple[RunReport, float, float]]] = {"wall-scaled": [], "paced": [], "max": []}
    for index in range(rounds):
        for side in sides:
            clock = Clock(speed) if side == "wall-scaled" else scaled_clock(speed) if side == "paced" else simulated_clock()
            sides[side].append(run_once(app, clock, str(tmp / f"{side}-{index}.sqlite")))
    figures = {}
    for side, runs in sides.items():
        cycles = [r.total for r, _, _ in runs]
        walls = [w for _, w, _ in runs]
        ideal = statistics.median(cycles) / speed if side != "max" else None
        figures[side] = {
            "cycle_s": [round(c, 3) for c in cycles],
            "cycle_ratio": [round(c / predicted, 4) for c in cycles],
            "within_aim": all(abs(c / predicted - 1.0) <= AIM for c in cycles),
            "retries": [r.retries for r, _, _ in runs],
            "errors": [len(r.errors) for r, _, _ in runs],
            "finished": [r.ok for r, _, _ in runs],
            "wall_s": [round(w, 2) for w in walls],
            "wall_ratio_to_ideal": None if ideal is None else round(statistics.median(walls) / ideal, 3),
            "cpu_s": [round(c, 2) for _, _, c in runs],
        }
    return figures


def show(title: str, figures: dict[str, dict[str, Any]], predicted: float) -> None:
    print(f"\n{title}: prediction {predicted:.2f} s")
    print(f"  {'clock':<12} {'cycle (s)':<22} {'/ prediction':<22} {'retries':<9} {'wall (s)':<18} {'wall / ideal':<12} cpu (s)")
    for side, f in figures.items():
        ideal = "-" if f["wall_ratio_to_ideal"] is None else f"{f['wall_ratio_to_ideal']:.2f}"
        print(
            f"  {side:<12} {', '.join(f'{c:.2f}' for c in f['cycle_s']):<22} {', '.join(f'{r:.4f}' for r in f['cycle_ratio']):<22} "
            f"{','.join(map(str, f['retries'])):<9} {', '.join(f'{w:.1f}' for w in f['wall_s']):<18} {ideal:<12} {', '.join(f'{c:.1f}' for c in f['cpu_s'])}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--burners", type=int, default=2, help="CPU-spinning processes beside the loaded runs (0: quiet runs only)")
    parser.add_argument("--burn-seconds", type=float, default=600.0, help="each burner ends by itself after this long")
    parser.add_argument("--iterations", type=int, default=200_000, help="loop turns per sample of the loop's own cost (0: skip it)")
    args = parser.parse_args()
    app = load_application(APP, full_catalog())
    result: dict[str, Any] = {"bench": "paced_clock", "speed": args.speed, "rounds": args.rounds}
    if args.iterations:
        costs = result["loop_us"] = loop_costs(args.iterations)
        print("one turn of the loop, CPU us (median of 5)   asyncio   PacedLoop unpaced   paced   ratio unpaced/asyncio   paced/asyncio")
        for way, label in (("turn", "sleep(0): select + one callback"), ("timer", "clock.sleep(1 ms): a timer waited for")):
            a, u, p = (costs[f"{k}_{way}_us"] for k in ("asyncio", "unpaced", "paced"))
            print(f"  {label:<42} {a:7.2f}   {u:17.2f}   {p:5.2f}   {u / a:21.3f}   {p / a:13.3f}")
    with tempfile.TemporaryDirectory() as tmp:
        predicted = dry_run(app, "nextage-sim", BackendOptions(robot=app.robot), str(Path(tmp) / "dry.sqlite")).cycle_time
        result["predicted_s"] = round(predicted, 3)
        result["as_is"] = measure(app, args.speed, args.rounds, predicted, Path(tmp))
        show(f"x{args.speed:g}, the computer as it is", result["as_is"], predicted)
        if args.burners:
            with burners(args.burners, args.burn_seconds):
                result["loaded"] = measure(app, args.speed, args.rounds, predicted, Path(tmp))
            result["burners"] = args.burners
            show(f"x{args.speed:g}, beside {args.burners} CPU burners", result["loaded"], predicted)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
