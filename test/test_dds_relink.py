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

And the other way round: a peer that stops pulsing while Cyclone's threads still renew its leases (its
Python held up by a long call) is not counted lost.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
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
from node_transport.msgs import String
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


QUIET_PUBLISHER = """
import asyncio, sys
from node_transport.clock import real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import String
from node_transport.qos import COMMANDS

async def main(clock):
    transport = DdsTransport(clock)
    transport.create_node("busy").create_publisher(String, "left_arm/sm/result", COMMANDS)
    print("ready", flush=True)
    sys.stdin.readline()
    transport.waiter.every(lambda: 0.2)  # no more pulses, as when its Python is held up: Cyclone's threads go on
    print("quiet", flush=True)
    await asyncio.get_running_loop().create_future()

run_with_clock(main, real_clock())
"""


def test_a_peer_that_stops_pulsing_but_keeps_its_leases_still_counts() -> None:
    """A process whose Python is held up does not pulse, but Cyclone renews its writers' leases: not lost."""
    with domain_env() as env:  # the two processes alone: only the quiet one pulses to the watcher
        quiet_peer(env)


def quiet_peer(env: dict[str, str]) -> None:
    child = subprocess.Popen([sys.executable, "-c", QUIET_PUBLISHER], cwd=ROOT, env={**os.environ, **env, "PYTHONPATH": str(ROOT)},
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdin is not None and child.stdout.readline().strip() == "ready"

        async def main(clock: Clock) -> None:
            transport = DdsTransport(clock, ["test"], env=env)
            try:
                sub = transport.create_node("watcher").create_subscription(String, "left_arm/sm/result", lambda _m: None, COMMANDS)
                assert await poll_until(clock, lambda: sub.get_publisher_count() == 1 and bool(transport.pulse.heard), BOUND, 0.02)
                child.stdin.write("\n")
                child.stdin.flush()
                assert child.stdout.readline().strip() == "quiet"
                lease = transport.lease
                # its last pulse grows older than the lease; all along the publisher counts
                assert not await poll_until(clock, lambda: sub.get_publisher_count() != 1, 2 * lease + 0.5, 0.02)
                newest = max(transport.pulse.heard.values())
                assert time.monotonic() - newest > lease, "the peer kept pulsing: nothing was shown"
            finally:
                await transport.shutdown()

        run_with_clock(main, real_clock())
    finally:
        child.kill()
        child.wait(timeout=BOUND)
