"""Overhead per primitive with every node in its own process over Cyclone DDS (no ROS), beside the
in-process figure, and joint-state throughput between two processes.

Needs only ``pip install '.[dds]'``.  One run measures, side by side and interleaved (five rounds by
default; each round every side once, one after the other, and prints its own line; then the medians,
and each ratio as the median of the rounds' own ratios, since the two sides of a round saw the same
load):

* in-process: engine, three group machines and the Nextage simulator bridge as nodes of one process on
  the local transport (``bench/primitive_overhead.py``);
* per-process over DDS: the same five nodes as five processes with ``--transport dds`` (bridge and three
  ``group_machine`` processes started here, the engine in this process), in a domain no test uses meanwhile, on loopback;
* the floor: a raw cyclonedds round trip (a String of a bridge command's size to an echo process and
  back, no project code on either side);

for the same two applications as ``bench/ros_primitive_overhead.py``: N operations of one ``set_speed``
(engine dispatch, result and Ready check per primitive) and one skill yielding N ``set_speed``
primitives (machine <-> bridge per primitive).  Then joint-state throughput: a child process publishes
``sensor_msgs/JointState`` of the Nextage's 15 joints as fast as it can through the DDS transport,
this process receives them through the DDS transport; messages per second delivered to the callback.

Each side waits for what it measures before the clock starts: the raw side until the echo has
answered (both directions matched), the engine by a warm-up run of both applications (its link to the
machines is bounded by ``startup_timeout``); the engine's DDS transport and the raw participant stay
up through every round.

Run:  python bench/dds_primitive_overhead.py [N] [ROUNDS]
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "test"))

from dds_domain import hold_domain  # noqa: E402
from primitive_overhead import BenchFunctions  # noqa: E402
from ros_primitive_overhead import ECHO_TEXT, ENGINE_PARAMETERS, applications, in_process, start_nodes, time_runs  # noqa: E402

from app_functions.registry import LIBRARIES  # noqa: E402
from cell_runner.libraries import APPLICATION_FUNCTIONS  # noqa: E402
from execution_engine.engine.engine import ExecutionEngine  # noqa: E402
from node_transport.clock import Clock, real_clock, run_with_clock  # noqa: E402
from node_transport.dds import DdsTransport  # noqa: E402

LOOPBACK = '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces></General></Domain></CycloneDDS>'
THROUGHPUT_MESSAGES = 20_000


def _raw_participant() -> object:
    """A bare cyclonedds participant in the bench's domain, configured as the transport's are."""
    from cyclonedds.domain import DomainParticipant

    from node_transport.dds import _domain, _import_cyclonedds
    from node_transport.dds_graph import domain_config, domain_id

    _domain(_import_cyclonedds(), domain_id(os.environ), domain_config(os.environ))
    return DomainParticipant(domain_id(os.environ))


def _raw_endpoints(participant: object, read: str, write: str) -> tuple[object, object, object]:
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from node_transport.dds_graph import dds_qos
    from node_transport.idl import InterfaceRegistry
    from node_transport.qos import COMMANDS

    string = InterfaceRegistry().message("std_msgs/msg/String")
    writer = DataWriter(participant, Topic(participant, write, string), qos=dds_qos(COMMANDS))
    return string, writer, (participant, Topic(participant, read, string), dds_qos(COMMANDS), DataReader)


def echo_process() -> int:
    """Child mode: raw cyclonedds, every String on rt/bench_ping written back on rt/bench_pong."""
    from cyclonedds.core import Listener

    participant = _raw_participant()
    _, writer, (p, topic, qos, reader_class) = _raw_endpoints(participant, "rt/bench_ping", "rt/bench_pong")

    readers: list[object] = []

    def echo(_reader: object) -> None:
        for sample in readers[0].take(N=64) if readers else ():  # type: ignore[attr-defined]
            if sample.sample_info.valid_data:  # not the parent's writer going away
                writer.write(sample)  # type: ignore[attr-defined]

    readers.append(reader_class(p, topic, qos=qos, listener=Listener(on_data_available=echo)))
    threading.Event().wait()
    return 0


class RawRoundTrip:
    """A bare cyclonedds participant of this process pinging the echo process: no project code on the
    way.  This side waits in a WaitSet on its own thread (no listener: the engine's DDS transport
    writes from this process at the same time, see node_transport/dds_waiter.py)."""

    def __init__(self) -> None:
        from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState, WaitSet

        self.participant = _raw_participant()
        self.string, self.writer, (p, topic, qos, reader_class) = _raw_endpoints(self.participant, "rt/bench_pong", "rt/bench_ping")
        self.reader = reader_class(p, topic, qos=qos)
        self.waitset = WaitSet(self.participant)
        self.waitset.attach(ReadCondition(self.reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        self.message = self.string(data=ECHO_TEXT)

    def ready(self, timeout: float = 60.0) -> None:
        """Until the echo answers: both directions matched (discovery is per side)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.writer.get_matched_subscriptions():  # type: ignore[attr-defined]
                try:
                    self.once(0.1)
                    return
                except TimeoutError:
                    pass
            else:
                time.sleep(0.01)
        raise RuntimeError(f"the echo process did not answer within {timeout:g} s")

    def once(self, timeout: float = 5.0) -> None:
        from cyclonedds.util import duration

        self.writer.write(self.message)  # type: ignore[attr-defined]
        while not self.reader.take(N=64):  # type: ignore[attr-defined]
            if not self.waitset.wait(duration(seconds=timeout)):
                raise TimeoutError("the echo process stopped answering")

    def seconds_per_round_trip(self, n: int) -> float:
        for _ in range(max(10, n // 10)):
            self.once()
        t0 = time.perf_counter()
        for _ in range(n):
            self.once()
        return (time.perf_counter() - t0) / n

    def close(self) -> None:
        from node_transport.dds_entities import delete

        delete(self.participant)


THROUGHPUT_PUBLISHER = """
import asyncio, sys
from node_transport.clock import real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import Header, JointState
from node_transport.qos import JOINT_STATES
from core_functions.robots import NEXTAGE_OPEN

async def main(clock):
    transport = DdsTransport(clock)
    node = transport.create_node("bench_bridge")
    pub = node.create_publisher(JointState, "joint_states", JOINT_STATES)
    names = tuple(NEXTAGE_OPEN.joint_names)
    while pub.get_subscription_count() == 0:
        await clock.sleep(0.01)
    await clock.sleep(0.5)
    for i in range(int(sys.argv[1])):
        pub.publish(JointState(Header(node.now_stamp(), ""), names, tuple(0.001 * i + k for k in range(len(names))), (), ()))
        if i % 100 == 0:
            await asyncio.sleep(0)
    await clock.sleep(2.0)
    await transport.shutdown()

run_with_clock(main, real_clock())
"""


async def joint_state_throughput(clock: Clock, env: dict[str, str]) -> tuple[float, int, int]:
    """(messages per second delivered, delivered, sent), publisher in a child process."""
    from node_transport.dds import DdsTransport
    from node_transport.msgs import JointState
    from node_transport.qos import JOINT_STATES

    transport = DdsTransport(clock, ["bench"])
    times: list[float] = []
    try:
        transport.create_node("bench_viewer").create_subscription(JointState, "joint_states", lambda _m: times.append(time.perf_counter()), JOINT_STATES)
        child = subprocess.Popen([sys.executable, "-c", THROUGHPUT_PUBLISHER, str(THROUGHPUT_MESSAGES)], env=env, cwd=ROOT)
        while child.poll() is None:
            await clock.sleep(0.05)
    finally:
        await transport.shutdown()
    if len(times) < 2:
        raise RuntimeError("no joint states arrived")
    return (len(times) - 1) / (times[-1] - times[0]), len(times), THROUGHPUT_MESSAGES


ROUNDS = 5


def cpu_seconds(pids: list[int]) -> float:
    """CPU time (user + system) the processes ``pids`` have used so far (Linux /proc)."""
    total = 0
    for pid in pids:
        with open(f"/proc/{pid}/stat") as stream:
            fields = stream.read().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


async def measure(clock: Clock, n: int, rounds: int, nodes: list[int], echo: int) -> list[dict[str, float]]:
    """Seconds per primitive or round trip, ``rounds`` times, each round all sides one after the other;
    beside each wall figure the CPU all the processes of that side used for it (``cpu_*``): on a shared
    host the wall figure follows the load, the CPU figure much less."""
    raw = RawRoundTrip()
    transport = DdsTransport(clock, ["bench"])
    engine_side, raw_side = [os.getpid(), *nodes], [os.getpid(), echo]
    try:
        raw.ready()  # the echo answers
        engine = ExecutionEngine(transport.create_node("execution_engine", parameters=ENGINE_PARAMETERS), APPLICATION_FUNCTIONS.catalog(None))
        await time_runs(engine, max(10, n // 10))  # the engine links to the machines (bounded) and warms up
        rows = []
        for index in range(rounds):
            cpu = cpu_seconds(raw_side)
            row = {"raw": raw.seconds_per_round_trip(n)}
            row["cpu_raw"] = (cpu_seconds(raw_side) - cpu) / (n + max(10, n // 10))
            for path, application in applications(n).items():
                cpu, t0 = cpu_seconds(engine_side), time.perf_counter()
                report = await engine.run(application)  # type: ignore[arg-type]
                row[f"dds_{path}"] = (time.perf_counter() - t0) / n
                row[f"cpu_dds_{path}"] = (cpu_seconds(engine_side) - cpu) / n
                assert report.ok, report.summary_lines()
            row.update({f"local_{path}": seconds for path, seconds in (await in_process(clock, n)).items()})
            rows.append(row)
            print(f"round {index + 1}: raw round trip {row['raw'] * 1e6:7.1f} us (CPU {row['cpu_raw'] * 1e6:5.0f} us) | "
                  f"over DDS, within a skill {row['dds_skill'] * 1e6:7.1f} us = {row['dds_skill'] / row['raw']:4.1f}x raw "
                  f"(CPU {row['cpu_dds_skill'] * 1e6:5.0f} us = {row['cpu_dds_skill'] / row['cpu_raw']:4.1f}x), one per function "
                  f"{row['dds_function'] * 1e6:7.1f} us | in one process {row['local_skill'] * 1e6:6.1f} / "
                  f"{row['local_function'] * 1e6:6.1f} us", flush=True)
        return rows
    finally:
        raw.close()
        await transport.shutdown()


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--echo":
        sys.exit(echo_process())
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else ROUNDS
    LIBRARIES["bench"] = BenchFunctions
    # a domain no test or other bench uses while this runs (test/dds_domain.py)
    os.environ.update(ROS_DOMAIN_ID=str(hold_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", CYCLONEDDS_URI=LOOPBACK)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    processes = start_nodes(env, ("--transport", "dds"))
    processes.append(subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--echo"], env=env, cwd=ROOT))
    try:
        nodes, echo = [p.pid for p in processes[:-1]], processes[-1].pid
        rows = run_with_clock(lambda c: measure(c, n, rounds, nodes, echo), real_clock())
    finally:
        for process in processes:
            process.terminate()
        for process in processes:
            process.wait(timeout=20)
    rate, delivered, sent = run_with_clock(lambda c: joint_state_throughput(c, env), real_clock())

    def median_us(key: str) -> float:
        return round(statistics.median(row[key] for row in rows) * 1e6, 1)

    def median_ratio(top: str, bottom: str) -> float:  # each round's own ratio: the two sides saw the same load
        return round(statistics.median(row[top] / row[bottom] for row in rows), 2)

    us = {f"{where}_{path}_us": median_us(f"{key}_{path}") for where, key in (("in_process", "local"), ("per_process_dds", "dds"))
          for path in ("function", "skill")}
    us["raw_cyclonedds_round_trip_us"] = median_us("raw")
    us["cpu_per_process_dds_skill_us"] = median_us("cpu_dds_skill")
    us["cpu_per_process_dds_function_us"] = median_us("cpu_dds_function")
    us["cpu_raw_cyclonedds_round_trip_us"] = median_us("cpu_raw")
    ratios = {f"ratio_{path}": median_ratio(f"dds_{path}", f"local_{path}") for path in ("function", "skill")}
    ratios["ratio_skill_vs_raw_round_trip"] = median_ratio("dds_skill", "raw")
    ratios["cpu_ratio_skill_vs_raw_round_trip"] = median_ratio("cpu_dds_skill", "cpu_raw")
    result = {
        "primitives": n, "runs": rounds, **us, **ratios,
        "joint_states_per_s": round(rate), "joint_states_delivered": delivered, "joint_states_sent": sent,
    }
    print(f"medians of {rounds} rounds (ratios: each round's own, then the median):")
    for path, label in (("function", "one primitive per function"), ("skill", "within one skill")):
        print(f"{label:28s} in-process {us[f'in_process_{path}_us']:8.1f} us, per-process over DDS "
              f"{us[f'per_process_dds_{path}_us']:8.1f} us per primitive ({ratios[f'ratio_{path}']}x)")
    print(f"{'raw cyclonedds round trip':28s} {us['raw_cyclonedds_round_trip_us']:8.1f} us "
          f"(a primitive within a skill: {ratios['ratio_skill_vs_raw_round_trip']}x of it)")
    print(f"{'CPU, all processes':28s} {us['cpu_per_process_dds_skill_us']:8.1f} us per primitive within a skill, "
          f"{us['cpu_per_process_dds_function_us']:8.1f} us per function, {us['cpu_raw_cyclonedds_round_trip_us']:6.1f} us per raw "
          f"round trip (skill: {ratios['cpu_ratio_skill_vs_raw_round_trip']}x)")
    print(f"{'joint_states (15 joints)':28s} {rate:8.0f} messages/s delivered ({delivered} of {sent}, reliable, depth 10)")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
