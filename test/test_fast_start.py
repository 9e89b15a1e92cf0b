"""The commands that only read start fast: ``validate``, ``functions`` and ``report`` load none of the slow libraries.

An integrator validates an application dozens of times while writing it, and a script calls ``functions --json``
to build an editor's completion: each used to load the whole program (numpy, pinocchio, coal, OpenCV: 494 modules,
1.3 s of CPU, 15 times an lxml parse).  Each command runs here in a fresh interpreter, as a person starts it, and
the libraries it loaded are read from ``sys.modules`` at its end.  ``bench/startup.py`` measures the time.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_report_bounds import status_recording

ROOT = Path(__file__).resolve().parents[1]
#: What only running a robot (back ends, simulators, the dry run), the camera or a transport needs.
HEAVY = ("numpy", "pinocchio", "coal", "cv2", "cyclonedds", "matplotlib", "rclpy", "starlette", "uvicorn")
#: Runs the program's main in this interpreter, then prints the exit code and the heavy libraries loaded.
PROBE = f"""
import json, sys
from operator_station.program import main
code = main(sys.argv[1:])
sys.stdout.flush()
print(json.dumps({{"code": code, "loaded": [name for name in {HEAVY!r} if name in sys.modules]}}), file=sys.stderr)
"""


def started(*argv: str, preload: str = "") -> tuple[int, list[str], str]:
    """Run ``python -m execution_engine ARGV`` in a fresh interpreter: (exit code, heavy libraries loaded, stdout)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this tree, not an installed copy
    done = subprocess.run(
        [sys.executable, "-c", preload + PROBE, *argv], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120, check=False,
    )
    verdict = json.loads(done.stderr.strip().splitlines()[-1])
    return verdict["code"], verdict["loaded"], done.stdout


def trace(path: Path) -> Path:
    """A small trace of one group's function with one primitive, as ``run --trace`` writes it."""
    base = {"group": "left_arm", "operation": "1", "function": "wait"}
    records = [
        {"event": "function_start", "t": 0.0, **base},
        {"event": "primitive_start", "t": 0.1, **base, "primitive": "wait 1 s", "index": 0, "state": "Motion"},
        {"event": "primitive_end", "t": 1.1, **base, "outcome": "done"},
        {"event": "function_end", "t": 1.2, **base, "outcome": "succeeded"},
    ]
    path.write_text("".join(json.dumps(r) + "\n" for r in records), encoding="utf-8")
    return path


@pytest.mark.parametrize("argv", [
    ("validate", "apps_xml/rivet_installation.xml", "apps_xml/kuka_rsi_demo.xml", "apps_xml/vplus_pick_inspect.xml", "apps_xml/rivet_async.xml"),
    ("functions",),
    ("functions", "--json"),
    ("--help",),
], ids=["validate", "functions", "functions-json", "help"])
def test_a_command_that_only_reads_loads_no_slow_library(argv: tuple[str, ...]) -> None:
    code, loaded, out = started(*argv)
    assert code == 0
    assert loaded == [], f"{' '.join(argv)} loaded {', '.join(loaded)}"
    assert out  # it did its work: the verdicts, the catalog, the usage


def test_report_of_a_trace_loads_no_slow_library_until_it_draws(tmp_path: Path) -> None:
    """The summary needs none of them; drawing the timeline (the default) needs matplotlib, and only then loads it."""
    code, loaded, out = started("report", str(trace(tmp_path / "run.jsonl")), "--no-timeline")
    assert (code, loaded) == (0, [])
    assert "operations: 1 started, 1 complete" in out
    code, loaded, out = started("report", str(trace(tmp_path / "run.jsonl")))
    assert code == 0 and (tmp_path / "run.timeline.svg").is_file()
    assert set(loaded) == {"matplotlib", "numpy"}


def test_report_of_a_recording_loads_only_its_reader(tmp_path: Path) -> None:
    """A recording needs the MCAP reader (mcap, its ROS 2 decoder), nothing of the robot."""
    recording = tmp_path / "run.mcap"
    recording.write_bytes(status_recording(2))
    code, loaded, out = started("report", str(recording), "--no-timeline")
    assert (code, loaded) == (0, [])
    assert out.startswith(f"recording {recording}: 2 message(s)")


def test_validate_of_a_broken_application_says_so_without_loading_them(tmp_path: Path) -> None:
    broken = tmp_path / "broken.xml"
    broken.write_text('<application name="x" robot="nextage"><operation id="1"><left_arm><function name="no_such"/></left_arm></operation></application>\n')
    code, loaded, _ = started("validate", str(broken))
    assert (code, loaded) == (1, [])


def test_the_probe_sees_a_slow_library_when_one_is_loaded() -> None:
    """The check above can fail: the module ``run`` imports when it runs does load them."""
    _, loaded, _ = started("functions", preload="import cell_runner.run_command\n")
    assert {"numpy", "pinocchio", "coal"} <= set(loaded)
