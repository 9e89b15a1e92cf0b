"""Every node process aggregates its console's warnings as the command line does: one line per kind and second, with a count.

``launch`` starts one process per node and prints their lines as they come; a bridge flooding a
warning there printed it line by line, whatever the command line's own console did.  Now the node
main (``run_node``, shared by the engine, the machines and every bridge) prints its own log through
the same aggregation over DDS, and under rclpy aggregates before it hands a record to rcutils.
"""
from __future__ import annotations

import io
import logging
import re
import sys
from typing import Any

import pytest
import ros_fake_logging
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from cell_runner.launcher import NodeSpec, launch
from cell_runner.ros_main import ExitCode, Outcome, run_node
from node_transport.clock import Clock, real_clock, run_with_clock
import node_transport.console_log as console_log
from node_transport.port import Node
from node_transport.wall_clock import ManualWallClock

#: A node process over DDS whose body floods one warning (the count in it changing) for FLOOD wall
#: seconds, then says how many it logged and in how long, and ends (the launch ends with it).
FLOODER = """
import logging, sys, time
from cell_runner.ros_main import run_node

async def body(node, outcome):
    log = logging.getLogger("robot_bridges.kuka_rsi.backend")
    start = time.monotonic()
    count = 0
    while time.monotonic() - start < float(sys.argv[1]):
        log.warning("kuka_rsi 127.0.0.1:49152: the controller counts %d late replies (IPOC %d)", count + 1, 3741924000 + 4 * count)
        count += 1
    print(f"flooded {count} in {time.monotonic() - start:.3f} s", flush=True)

sys.exit(run_node("kuka_rsi_bridge", body, [sys.argv[0], *sys.argv[2:]]))
"""
FLOOD = 2.5  # wall seconds of flood: two windows' counted lines at least
COUNTED = re.compile(r"\(x(\d+) in the last ([\d.e-]+) s\)$")


def test_a_node_flooding_a_warning_under_launch_prints_one_line_per_second_with_a_count(dds_env: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> None:
    for name, value in dds_env.items():  # the node process inherits the launch's environment
        monkeypatch.setenv(name, value)
    out = io.StringIO()
    spec = NodeSpec("execution_engine", (sys.executable, "-c", FLOODER, str(FLOOD), "--transport", "dds"))  # ends the launch when it ends

    async def main(clock: Clock) -> int:
        return await launch(clock, [spec], out, grace=0.5, stop_timeout=10.0)

    code = run_with_clock(main, real_clock())
    text = out.getvalue()
    assert code == 0, text
    done = re.search(r"^\[execution_engine\] flooded (\d+) in ([\d.]+) s$", text, re.MULTILINE)
    assert done, text
    logged, seconds = int(done.group(1)), float(done.group(2))
    lines = [line for line in text.splitlines() if "late replies" in line]
    assert logged > 100 * len(lines), (logged, lines)  # the flood was real: far more warnings than lines
    assert lines[0] == "[execution_engine] [WARNING] [robot_bridges.kuka_rsi.backend]: kuka_rsi 127.0.0.1:49152: the controller counts 1 late replies (IPOC 3741924000)"
    counted = [COUNTED.search(line) for line in lines[1:]]
    assert counted and all(counted), lines
    assert 1 + sum(int(m.group(1)) for m in counted if m) == logged  # every warning accounted for, none printed twice
    assert all(float(m.group(2)) <= console_log.WINDOW for m in counted if m)
    assert len(lines) <= 2 + int(seconds / console_log.WINDOW)  # the first at once, then one a second, the rest at the end
    assert lines[-1].startswith(f"[execution_engine] [WARNING] [robot_bridges.kuka_rsi.backend]: kuka_rsi 127.0.0.1:49152: the controller counts {logged} late replies")


def test_under_rclpy_a_flood_reaches_rcutils_and_rosout_as_one_counted_line_per_second(fake_rclpy: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    wall = ManualWallClock()
    monkeypatch.setattr(console_log, "RealWallClock", lambda: wall)  # the aggregation's wall clock, moved by hand
    log = logging.getLogger("robot_bridges.kuka_rsi.backend")

    async def body(node: Node, outcome: Outcome) -> None:
        for second in range(3):
            for i in range(300):
                log.warning("the controller counts %d late replies", 300 * second + i + 1)
            wall.advance(1.0)  # a window ends: the held ones go as one line
        for i in range(50):
            log.warning("the controller counts %d late replies", 901 + i)
        wall.advance(0.25)
        node.logger.info("%s: stopping", node.name)

    assert run_node("kuka_rsi_bridge", body, ["kuka_rsi_bridge"]) == ExitCode.OK
    late = [(severity, text) for name, severity, text in ros_fake_logging.ROSOUT if "late replies" in text]
    assert late == [
        (30, "[robot_bridges.kuka_rsi.backend] the controller counts 1 late replies"),
        (30, "[robot_bridges.kuka_rsi.backend] the controller counts 300 late replies (x299 in the last 1 s)"),
        (30, "[robot_bridges.kuka_rsi.backend] the controller counts 600 late replies (x300 in the last 1 s)"),
        (30, "[robot_bridges.kuka_rsi.backend] the controller counts 900 late replies (x300 in the last 1 s)"),
        (30, "[robot_bridges.kuka_rsi.backend] the controller counts 950 late replies (x50 in the last 0.25 s)"),  # held when the node went
    ]
    assert ("kuka_rsi_bridge", 20, "kuka_rsi_bridge: stopping") in ros_fake_logging.ROSOUT  # another kind: at once
    assert not [h for h in logging.getLogger().handlers if isinstance(h, console_log.AggregatingHandler)]  # gone with the node
