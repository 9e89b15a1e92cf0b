"""Cycle time of the rivet demonstrator, lock-step against asynchronous (sync="flags"), side by side.

Usage: python bench/async_cycle.py

Both applications (apps_xml/rivet_installation.xml and apps_xml/rivet_async.xml: the same skills on the same
holes and rivets) are dry-run on the Nextage simulator in this process; on that simulator the prediction is the
time ``run --speed max`` takes, to the millisecond.  Printed per application: predicted cycle, each group's busy
and idle time, the waits for flags and zones, and the asynchronous cycle as a share of the lock-step one.  Last
line: JSON.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.dry_run import dry_run  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
APPS = {"lock-step": ROOT / "apps_xml" / "rivet_installation.xml", "flags": ROOT / "apps_xml" / "rivet_async.xml"}


def main() -> None:
    catalog = full_catalog()
    rows = {}
    for mode, path in APPS.items():
        app = load_application(path, catalog)
        report = dry_run(app, "nextage-sim", BackendOptions(app.robot))
        if not report.ok:
            raise SystemExit(f"{path}: {report.findings[:1]} {report.notes}")
        waits: dict[str, float] = {}
        for wait in report.waits:
            key = f"{wait.group} {wait.kind} {wait.flag}"
            waits[key] = round(waits.get(key, 0.0) + wait.duration, 3)
        rows[mode] = {
            "file": path.name, "cycle_s": round(report.cycle_time, 3),
            "groups": {g: {"busy_s": round(t.busy, 3), "idle_s": round(t.idle, 3)} for g, t in report.groups.items()},
            "waits_s": waits,
        }
        print(f"{mode:<10} {path.name:<26} cycle {report.cycle_time:8.2f} s")
        for group, t in report.groups.items():
            print(f"{'':<10} {group:<12} busy {t.busy:8.2f} s, idle {t.idle:8.2f} s")
        for key, seconds in waits.items():
            print(f"{'':<10} waiting: {key} {seconds:.2f} s")
    ratio = rows["flags"]["cycle_s"] / rows["lock-step"]["cycle_s"]
    print(f"asynchronous / lock-step cycle: {ratio:.3f} ({rows['lock-step']['cycle_s'] - rows['flags']['cycle_s']:.2f} s shorter)")
    print(json.dumps({"bench": "async_cycle", "ratio": round(ratio, 4), "rows": rows}))


if __name__ == "__main__":
    main()
