"""Overhead per primitive with every node in its own process over Cyclone DDS (no ROS), beside the
in-process figure, and joint-state throughput between two processes.

Needs only ``pip install '.[dds]'``.  One run measures, side by side and interleaved (three rounds, medians):

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

Run:  python bench/dds_primitive_overhead.py [N]
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
from ros_primitive_overhead import ECHO_TEXT, in_process, per_process, start_nodes  # noqa: E402

from app_functions.registry import LIBRARIES  # noqa: E402
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


def raw_round_trip(n: int) -> float:
    from cyclonedds.core import Listener

    participant = _raw_participant()
    string, writer, (p, topic, qos, reader_class) = _raw_endpoints(participant, "rt/bench_pong", "rt/bench_ping")
    answered = threading.Event()

    readers: list[object] = []

    def pong(_reader: object) -> None:
        if readers and readers[0].take(N=64):  # type: ignore[attr-defined]
            answered.set()

    reader = reader_class(p, topic, qos=qos, listener=Listener(on_data_available=pong))
    readers.append(reader)
    deadline = time.monotonic() + 30.0
    while not (writer.get_matched_subscriptions() and reader.get_matched_publications()):  # type: ignore[attr-defined]
        if time.monotonic() > deadline:
            raise RuntimeError("the echo process never matched")
        time.sleep(0.01)
    message = string(data=ECHO_TEXT)
    for _ in range(300):  # until the echo's writer has matched our reader too (discovery is per side)
        answered.clear()
        writer.write(message)  # type: ignore[attr-defined]
        if answered.wait(0.1):
            break

    def once() -> None:
        answered.clear()
        writer.write(message)  # type: ignore[attr-defined]
        if not answered.wait(5.0):
            raise RuntimeError("the echo process stopped answering")

    try:
        for _ in range(max(10, n // 10)):
            once()
        t0 = time.perf_counter()
        for _ in range(n):
            once()
        return (time.perf_counter() - t0) / n
    finally:  # no listener may fire into a finalizing interpreter
        from node_transport.dds_entities import delete

        delete(participant)


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


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--echo":
        sys.exit(echo_process())
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    LIBRARIES["bench"] = BenchFunctions
    # a domain no test or other bench uses while this runs (test/dds_domain.py)
    os.environ.update(ROS_DOMAIN_ID=str(hold_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", CYCLONEDDS_URI=LOOPBACK)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    local_runs, dds_runs, raw_runs = [], [], []
    processes = start_nodes(env, ("--transport", "dds"))
    processes.append(subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--echo"], env=env, cwd=ROOT))
    try:
        for _ in range(3):  # interleaved, so all see the same machine load
            local_runs.append(run_with_clock(lambda c: in_process(c, n), real_clock()))
            dds_runs.append(run_with_clock(lambda c: per_process(c, n, DdsTransport), real_clock()))
            raw_runs.append(raw_round_trip(n))
    finally:
        for process in processes:
            process.terminate()
        for process in processes:
            process.wait(timeout=20)
    rate, delivered, sent = run_with_clock(lambda c: joint_state_throughput(c, env), real_clock())
    us = {
        f"{where}_{path}_us": round(statistics.median(r[path] for r in runs) * 1e6, 1)
        for where, runs in (("in_process", local_runs), ("per_process_dds", dds_runs))
        for path in ("function", "skill")
    }
    us["raw_cyclonedds_round_trip_us"] = round(statistics.median(raw_runs) * 1e6, 1)
    ratios = {f"ratio_{path}": round(us[f"per_process_dds_{path}_us"] / us[f"in_process_{path}_us"], 2) for path in ("function", "skill")}
    ratios["ratio_skill_vs_raw_round_trip"] = round(us["per_process_dds_skill_us"] / us["raw_cyclonedds_round_trip_us"], 2)
    result = {
        "primitives": n, "runs": 3, **us, **ratios,
        "joint_states_per_s": round(rate), "joint_states_delivered": delivered, "joint_states_sent": sent,
    }
    for path, label in (("function", "one primitive per function"), ("skill", "within one skill")):
        print(f"{label:28s} in-process {us[f'in_process_{path}_us']:8.1f} us, per-process over DDS "
              f"{us[f'per_process_dds_{path}_us']:8.1f} us per primitive ({ratios[f'ratio_{path}']}x)")
    print(f"{'raw cyclonedds round trip':28s} {us['raw_cyclonedds_round_trip_us']:8.1f} us "
          f"(a primitive within a skill: {ratios['ratio_skill_vs_raw_round_trip']}x of it)")
    print(f"{'joint_states (15 joints)':28s} {rate:8.0f} messages/s delivered ({delivered} of {sent}, reliable, depth 10)")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
