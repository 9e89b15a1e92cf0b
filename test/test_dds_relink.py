"""An engine links 2,000 primitives to machines in their own processes over DDS, then a second
engine links to the same machines (issue 22 item 4).

The bridge and the three group machines run as processes of their own on the DDS transport, on
loopback, in a domain of this test's own (dds_domain.py); the engines run in this process, one after
the other, as ``bench/dds_primitive_overhead.py`` runs them.  Between the two engines one machine is
stopped (SIGSTOP) until the first engine sees its result publisher lapse, then continued: before
the fix, Cyclone marked that idle writer "not alive" for good (only a write of its own revives it),
and every later reader of this process saw it "matched but not alive", so the second engine's link
failed after its whole timeout -- what busy hosts did by chance, in 5 runs of 5 of the bench.  Every
wait is bounded by a deadline on a condition; the DDS transport runs on the wall clock by design.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from app_builder import make_app
from dds_domain import domain_env, stop_group

from core_functions.robots import NEXTAGE_OPEN
from execution_engine.engine.engine import ExecutionEngine
from cell_runner.libraries import APPLICATION_FUNCTIONS
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.port import poll_until
from node_transport.qos import COMMANDS
from node_transport.typed import MachineResultMsg
from node_transport.wire import sm_topic

ROOT = Path(__file__).resolve().parent.parent
PRIMITIVES = 2_000
BOUND = 30.0  # seconds a link or a state may take on a loaded machine
RUN_BOUND = 120.0  # seconds the 2,000 primitives may take on a loaded machine (about 5 s on a quiet one)
STALLED = "torso_head"  # a group the application leaves idle: its result writer writes only at each operation's end


@pytest.fixture(scope="module")
def cell() -> Iterator[tuple[dict[str, str], dict[str, subprocess.Popen[bytes]]]]:
    """The Nextage simulator's bridge and one machine per group, each a process on the DDS transport."""
    with domain_env() as env:
        full = {**os.environ, **env, "PYTHONPATH": str(ROOT)}
        dds = ("--transport", "dds")
        commands = {"bridge": [sys.executable, "-c", "import sys; from cell_runner.bridge_nodes.nextage_sim import main; sys.exit(main(sys.argv))",
                               *dds, "--ros-args", "-p", "state_period:=1.0"]}
        for group in NEXTAGE_OPEN.group_names:
            commands[group] = [sys.executable, "-c", "import sys; from cell_runner.nodes import group_machine_main; sys.exit(group_machine_main(sys.argv))",
                               *dds, "--ros-args", "-r", f"__node:={group}_machine", "-p", f"group:={group}", "-p", "trajectory_db:=':memory:'"]
        processes = {name: subprocess.Popen(command, env=full, cwd=ROOT, start_new_session=True) for name, command in commands.items()}
        try:
            yield env, processes
        finally:
            for process in processes.values():
                with_signal(process, signal.SIGCONT)
                stop_group(process)


def with_signal(process: subprocess.Popen[bytes], sig: int) -> None:
    if process.poll() is None:
        os.kill(process.pid, sig)


def engine_on(transport: DdsTransport, name: str) -> ExecutionEngine:
    parameters = {"startup_timeout": BOUND, "function_timeout": RUN_BOUND}
    return ExecutionEngine(transport.create_node(name, parameters=parameters), APPLICATION_FUNCTIONS.catalog(None))


def test_a_second_engine_links_after_2000_primitives_and_a_stalled_machine(
    cell: tuple[dict[str, str], dict[str, subprocess.Popen[bytes]]],
) -> None:
    env, processes = cell
    stalled = processes[STALLED]

    async def first(clock: Clock) -> None:
        transport = DdsTransport(clock, ["test"], env=env)
        try:
            engine = engine_on(transport, "execution_engine")
            application = make_app([{"left_arm": ("set_speed", "0.5" if i % 2 else "1.0")} for i in range(PRIMITIVES)])
            report = await clock.wait_for(engine.run(application), RUN_BOUND)
            assert report.ok, report.summary_lines()
            assert report.operations_done == PRIMITIVES
            # what the engine's link counts, on a reader of its own in the same participant
            results = transport.create_node("watcher").create_subscription(MachineResultMsg, sm_topic(STALLED, "result"), lambda _m: None, COMMANDS)
            assert await poll_until(clock, lambda: results.get_publisher_count() == 1, BOUND, 0.02)
            # the machine stops answering anything for longer than its lease: its writers lapse here
            with_signal(stalled, signal.SIGSTOP)
            try:
                assert await poll_until(clock, lambda: results.get_publisher_count() == 0, BOUND, 0.02), \
                    "the stopped machine's result publisher never lapsed"
            finally:
                with_signal(stalled, signal.SIGCONT)
            # it pulses again: live again, without having written a result
            assert await poll_until(clock, lambda: results.get_publisher_count() == 1, BOUND, 0.02), \
                "the continued machine's result publisher did not come back"
        finally:
            await transport.shutdown()

    async def second(clock: Clock) -> None:
        transport = DdsTransport(clock, ["test"], env=env)  # the same process and Cyclone domain as the first
        try:
            engine = engine_on(transport, "second_engine")
            report = await clock.wait_for(engine.run(make_app([{"left_arm": ("set_speed", "0.5")}, {STALLED: ("set_speed", "0.5")}])), BOUND * 2)
            assert report.ok, report.summary_lines()
            assert report.operations_done == 2
        finally:
            await transport.shutdown()

    run_with_clock(first, real_clock())
    assert all(p.poll() is None for p in processes.values()), "a node process ended"
    run_with_clock(second, real_clock())
