"""The operator station's page in headless Chromium: the 10,000-operation application, and a ``--speed max`` run.

Usage: python bench/studio_page.py [--operations 10000] [--repeat 3] [--run-operations 400]

1. Time to first paint and to validate in the page, for a 10,000-operation application (the
   rivet demonstrator's debur/pick/insert block repeated: 10,000 operations, 30,000 calls,
   every param a name of the cell model to check) against the 10-operation rivet demonstrator
   (the baseline), each from navigation start: ``shown`` is the frame after the builder's table is
   painted, ``validated`` the moment the page holds the validator's answer for the whole
   application (request, validation, JSON, placing every message).  The same run times
   ``read_application`` of the 10,000-operation file alone, so the last ratio says what the page
   adds on top of the project's validator.  Aim: <= 2 s each.
2. A ``--speed max`` run of the rivet demonstrator's block repeated to 200 operations with the page open: the records the page
   received against the trace file, event for event (no dropped state change), how long the
   page took to catch up after the run ended, and the run's wall time against the same file
   run by ``run --speed max -q`` in a process of its own (the baseline).

Last line: JSON.  Needs Debian's chromium and chromium-driver, and the studio extra.
"""
from __future__ import annotations

import argparse
import copy
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app_functions.registry import full_catalog  # noqa: E402
from execution_engine.app_model import read_application  # noqa: E402
from execution_engine.app_model.document import OperationEntry, read_document, to_xml  # noqa: E402
from operator_station import browser  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import serve, station_args, until as wait  # noqa: E402


def page_times(driver: Any, folder: Path, app: str, repeat: int) -> dict[str, float]:
    """Median shown / validated milliseconds since navigation over ``repeat`` fresh loads."""
    served = serve(build_station(station_args(file=app, no_check=True), full_catalog(), folder))
    shown, validated, operations = [], [], 0
    try:
        for _ in range(repeat):
            driver.get(served.url)
            wait(driver, "Builder.state.shownAt")
            wait(driver, "Builder.state.firstValidatedAt && Builder.state.valid !== null")
            assert driver.execute_script("return Builder.state.valid"), driver.execute_script("return Builder.state.messages.slice(0, 3)")
            shown.append(driver.execute_script("return Builder.state.shownAt"))
            validated.append(driver.execute_script("return Builder.state.firstValidatedAt"))
            operations = driver.execute_script("return Builder.state.doc.operations.length")
    finally:
        served.close()
    return {"operations": operations, "shown_ms": statistics.median(shown), "validated_ms": statistics.median(validated)}


def repeated_rivets(folder: Path, operations: int, name: str = "run") -> Path:
    """The rivet demonstrator with its debur/pick/insert block repeated to about ``operations`` operations."""
    document, _ = read_document(ROOT / "apps_xml" / "rivet_installation.xml")
    assert document is not None
    first, block, last = document.operations[0], document.operations[1:-1], document.operations[-1]
    ops = [first]
    while len(ops) < operations - 1:  # the first and last operations stay; the block fills the rest, cut where it ends
        op = block[(len(ops) - 1) % len(block)]
        ops.append(OperationEntry(str(len(ops) + 1), op.name, copy.deepcopy(op.calls)))
    last.id = str(len(ops) + 1)
    document.operations = [*ops, last]
    path = folder / f"rivets_repeated_{name}.xml"
    path.write_text(to_xml(document), encoding="utf-8")
    return path


def run_max(driver: Any, folder: Path, app: str) -> dict[str, Any]:
    """A --speed max run watched by the page: the page's records against the trace."""
    trace = folder / "max_run.jsonl"
    served = serve(build_station(station_args(file=app, trace=str(trace), no_check=True), full_catalog(), folder))
    try:
        driver.get(served.url)
        wait(driver, "document.body.dataset.ready === 'true' && Builder.state.valid")
        driver.find_element("id", "ctl-start").click()
        started = time.monotonic()
        assert served.station.session is not None
        try:
            wait(driver, "Store.records.length > 0")
        except TimeoutError:
            raise TimeoutError(f"the run did not start: {driver.find_element('id', 'control-answer').text}; {served.station.feed.snapshot.messages}") from None
        served.station.session.join(600.0)
        ended = time.monotonic()
        lines = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines()]
        wait(driver, f"Store.records.length >= {len(lines)}")
        caught_up = time.monotonic()
        page = driver.execute_script("return Store.records")
        transitions = sum(1 for r in lines if r["event"] == "transition")
        return {"records": len(lines), "transitions": transitions, "page_records": len(page), "identical": page == lines,
                "run_s": ended - started, "page_behind_s": caught_up - ended, "outcome": lines[-1].get("outcome")}
    finally:
        served.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operations", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--run-operations", type=int, default=200, help="operations of the --speed max run (the rivet block repeated)")
    args = parser.parse_args()
    if browser.missing():
        print(f"cannot run: {browser.missing()}")
        return 2
    catalog = full_catalog()
    with tempfile.TemporaryDirectory(prefix="studio_bench_") as name:
        folder = Path(name)
        shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells", dirs_exist_ok=True)
        shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", folder / "rivet_installation.xml")
        big = repeated_rivets(folder, args.operations, "large")
        started = time.perf_counter()
        app, _ = read_application(big, catalog)
        bare_ms = (time.perf_counter() - started) * 1000
        assert app is not None
        driver = browser.chromium()
        try:
            small = page_times(driver, folder, "rivet_installation.xml", args.repeat)
            large = page_times(driver, folder, big.name, args.repeat)
            run_app = repeated_rivets(folder, args.run_operations)
            run = run_max(driver, folder, run_app.name)
            started = time.monotonic()
            subprocess.run([sys.executable, "-m", "execution_engine", "run", str(run_app), "--speed", "max", "-q", "--no-check"],
                           cwd=ROOT, check=True, capture_output=True, timeout=1800)
            run["cli_s"] = time.monotonic() - started
        finally:
            driver.quit()
    heading = f"{large['operations']} operations"
    print(f"{'':34}{'rivet (baseline)':>18}{heading:>20}{'ratio':>8}")
    print(f"{'shown (first paint of the table)':34}{small['shown_ms']:>15.0f} ms{large['shown_ms']:>17.0f} ms{large['shown_ms'] / small['shown_ms']:>8.1f}")
    print(f"{'validated in the page':34}{small['validated_ms']:>15.0f} ms{large['validated_ms']:>17.0f} ms{large['validated_ms'] / small['validated_ms']:>8.1f}")
    print(f"{'read_application alone':34}{'':>18}{bare_ms:>17.0f} ms{large['validated_ms'] / bare_ms:>8.1f}  (page / validator)")
    print(f"--speed max run of {args.run_operations} operations: {run['records']} trace records ({run['transitions']} state changes), "
          f"page got {run['page_records']}, identical: {run['identical']}; page caught up {run['page_behind_s']:.2f} s after the end")
    print(f"{'the run, watched by the page':34}{run['run_s']:>15.1f} s   vs `run --speed max -q` {run['cli_s']:.1f} s (ratio {run['run_s'] / run['cli_s']:.2f})")
    print(json.dumps({"baseline": small, "large": large, "read_application_ms": bare_ms, "speed_max_run": run}))
    return 0 if run["identical"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
