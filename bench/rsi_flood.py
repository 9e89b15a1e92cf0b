"""KUKA RSI bridge under a flood from the controller's own host: late corrections, round trips, counts.

    python bench/rsi_flood.py                  # 30 s per run at a real 4 ms cycle
    python bench/rsi_flood.py --seconds 10     # shorter

The hardening issue's attack at ten times the cycle rate: beside the simulated KR C4 (real time,
its own process, ``SCHED_FIFO`` 20) a second sender on the controller's IP but another port sends
2,500 datagrams a second -- forged copies of the controller's packet with ``Delay`` 50 higher
(``packet``), or those and garbage by turns (``mixed``) -- while the RSI loop (its own process, as
in production) keeps a joint move running, a new target every 300 cycles.  A run without the
flood, on the same machine in the same invocation, is the baseline.  Each run reports what the
controller counted (late replies once connected, round trips), what the flooder sent and got
back, and what the loop counted and said in its end-of-run summary.  The last line is the JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from rsi_latency import CYCLE, READY_DEG, free_port, fmt, handshake, summary_of  # noqa: E402

from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink  # noqa: E402
from robot_bridges.kuka_rsi.interface import RsiInterface  # noqa: E402

TARGETS = (np.radians(READY_DEG), np.radians((40.0, -60.0, 70.0, 30.0, 60.0, 45.0)))


def one_run(seconds: float, flood: str) -> dict[str, object]:
    """The loop (own process) against the real-time simulator, with ``flood`` ('' for none)."""
    port = free_port()
    iface = RsiInterface([RobotLink("kr6", "127.0.0.1")], LoopSettings(port=port, silence_timeout=1.0), mode="process")
    iface.start()
    iface.wait_ready()
    args = [sys.executable, "-m", "robot_bridges.kuka_rsi.simulator", "--to", f"127.0.0.1:{port}", "--cycles", str(int(seconds / CYCLE))]
    args += ["--rt-priority", "20"] + (["--flood", flood] if flood else [])
    sim = subprocess.Popen(args, stdout=subprocess.PIPE, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    moves = 0
    try:
        handshake(iface)
        while sim.poll() is None:
            if iface.state(0).cycles >= 300 * (moves + 1):
                iface.set_axial_pos(0, TARGETS[moves % 2], 2.0, 5.0)
                moves += 1
            iface.wait_event(lambda: False, 0.01)
        iface.request_stats()
        iface.wait_event(lambda: iface.events.stats is not None, 10)
        stats = iface.events.stats or ()
    finally:
        summary = summary_of(sim, 30)
        iface.close()
    return {
        "flood": flood or "none",
        "packets": summary.get("packets"),
        "late": summary.get("late_since_first_reply"),
        "late_replies": summary.get("late_replies"),
        "overruns": summary.get("overruns"),
        "round_trip_us": summary.get("round_trip_us"),
        "stopped": summary.get("stopped"),
        "flood_sent": summary.get("flood_sent"),
        "flood_replies": summary.get("flood_replies"),
        "loop_spoofed": stats[11] if len(stats) > 11 else None,
        "loop_rejected": stats[2] if stats else None,
        "moves": moves,
        "loop_summary": iface.events.summary,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="each run at 4 ms (default 30)")
    parser.add_argument("--floods", default=",10:packet,10:mixed", help="comma-separated --flood values ('' = no flood, the baseline)")
    args = parser.parse_args()
    figures: dict[str, object] = {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0], "seconds": args.seconds}
    runs = []
    for flood in args.floods.split(","):
        started = time.monotonic()
        run = one_run(args.seconds, flood)
        runs.append(run)
        print(f"flood {run['flood']:>10}: late {run['late']} of {run['packets']} once connected, {fmt(run['round_trip_us'])}; "  # type: ignore[arg-type]
              f"flood sent {run['flood_sent']}, replies to it {run['flood_replies']}, loop counted {run['loop_spoofed']} ({time.monotonic() - started:.0f} s)")
        print(f"    {run['loop_summary']}")
    figures["runs"] = runs
    figures["load_after"] = os.getloadavg()[0]
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
