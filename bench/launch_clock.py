"""A cell of processes at a scaled speed: the engine's cycle time against the dry run's, quiet and beside CPU burners.

    python bench/launch_clock.py [--speed 10] [--rounds 2] [--burners 2] [--burn-seconds 300]

``python -m execution_engine launch apps_xml/rivet_installation.xml --transport dds --speed F``: the
five nodes, each its own process, on loopback DDS in a domain of its own.  The simulator's bridge is
the cell's clock: the machines and the engine follow its ``/clock``, and it holds robot time while a
group's next step is on its way between processes (robot_bridges/turnaround.py).  ``--rounds``
launches on the computer as it is, then as many beside ``--burners`` processes spinning on the CPU.
Each row: the engine's report total, its ratio to the dry run's prediction (the aim: within 1 %),
whether it finished, retries, and the launch's wall time.  The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.dry_run.runner import dry_run  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402

APP = ROOT / "apps_xml" / "rivet_installation.xml"
AIM = 0.01
LOOPBACK = '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces></General></Domain></CycloneDDS>'


@contextmanager
def burners(count: int, seconds: float) -> Iterator[None]:
    """``count`` processes spinning on the CPU, each ending by itself after ``seconds``."""
    spin = f"import time\nend = time.monotonic() + {seconds!r}\nwhile time.monotonic() < end: pass\n"
    procs = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(count)]
    try:
        yield
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def launch_once(speed: float, home: Path) -> dict[str, Any]:
    env = {**os.environ, "ROS_DOMAIN_ID": str(random.SystemRandom().randint(150, 232)), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "CYCLONEDDS_URI": LOOPBACK, "XDG_DATA_HOME": str(home)}
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "execution_engine", "launch", str(APP), "--transport", "dds", "--speed", repr(speed)],
        cwd=ROOT, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=600, check=False,
    )
    out = done.stdout + done.stderr
    total = re.search(r"\[execution_engine\]\s+total\s+([\d.]+) s", out)
    return {
        "total": float(total.group(1)) if total else None,
        "finished": "rivet_installation: FINISHED" in out,
        "retries": len(re.findall(r"retry|retrying", out, re.IGNORECASE)),
        "exit": done.returncode,
        "wall": round(time.monotonic() - started, 1),
    }


def show(title: str, rows: list[dict[str, Any]], predicted: float) -> None:
    print(f"\n{title}")
    for row in rows:
        ratio = f"{row['total'] / predicted:.4f}" if row["total"] else "-"
        print(f"  total {row['total']!s:>7} s  /prediction {ratio}  finished {row['finished']}  retries {row['retries']}  "
              f"exit {row['exit']}  wall {row['wall']} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--speed", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--burners", type=int, default=2, help="CPU-spinning processes beside the loaded launches (0: quiet launches only)")
    parser.add_argument("--burn-seconds", type=float, default=300.0, help="each burner ends by itself after this long")
    args = parser.parse_args()
    app = load_application(APP, full_catalog())
    predicted = dry_run(app, "nextage-sim", BackendOptions(robot=app.robot)).cycle_time
    print(f"dry run: {predicted:.2f} s; aim within {AIM:.0%}")
    home = Path(os.environ.get("TMPDIR", "/tmp")) / f"launch_clock_{os.getpid()}"
    result: dict[str, Any] = {"predicted": predicted, "speed": args.speed}
    result["quiet"] = [launch_once(args.speed, home) for _ in range(args.rounds)]
    show(f"x{args.speed:g}, the computer as it is", result["quiet"], predicted)
    if args.burners:
        with burners(args.burners, args.burn_seconds):
            result["loaded"] = [launch_once(args.speed, home) for _ in range(args.rounds)]
        result["burners"] = args.burners
        show(f"x{args.speed:g}, beside {args.burners} CPU burners", result["loaded"], predicted)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
