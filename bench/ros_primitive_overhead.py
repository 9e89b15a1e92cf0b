"""Overhead per primitive with every node in its own process over rclpy, beside the in-process figure.

Needs a sourced ROS 2 Jazzy (rclpy importable).  One run measures, side by side:

* in-process: engine, three group machines and the Nextage simulator bridge as nodes of one process on
  the local transport (what ``bench/primitive_overhead.py`` measures);
* per-process: the same five nodes as five processes over rclpy (the simulator bridge and three
  ``group_machine`` processes started here, the engine in this process), on a ROS domain of their own;

each for two applications: N operations of one ``set_speed`` (one primitive per function: engine dispatch,
result and Ready check per primitive, the worst case) and one operation whose skill yields N ``set_speed``
primitives (machine <-> bridge per primitive, the engine once).  ``set_speed`` does no motion, so the figures
are pure orchestration and transport overhead.  As the floor of any ROS 2 Python node, the same run times a
raw rclpy echo: a String of a bridge command's size to another process and back, both sides on rclpy's
MultiThreadedExecutor (a primitive within a skill is one such round trip between machine and bridge).
Prints per-primitive times, the ratios per-process / in-process and per-process / raw round trip, and one
JSON line.

Run:  python bench/ros_primitive_overhead.py [N]      (after: source /opt/ros/jazzy/setup.bash)
"""
from __future__ import annotations

import asyncio
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "test"))

from dds_domain import hold_domain  # noqa: E402
from primitive_overhead import BenchFunctions, app  # noqa: E402

from app_functions.registry import LIBRARIES  # noqa: E402
from cell_runner.deployment import deploy_local  # noqa: E402
from cell_runner.libraries import APPLICATION_FUNCTIONS  # noqa: E402
from core_functions.robots import NEXTAGE_OPEN  # noqa: E402
from execution_engine.engine.engine import ExecutionEngine  # noqa: E402
from node_transport.clock import Clock, real_clock, run_with_clock  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402

ENGINE_PARAMETERS = {"startup_timeout": 60.0}


def applications(n: int) -> dict[str, object]:
    return {
        "function": app([{"left_arm": ("set_speed", "0.5")} for _ in range(n)]),
        "skill": app([{"left_arm": ("speed_sweep", str(n))}]),
    }


async def time_runs(engine: ExecutionEngine, n: int) -> dict[str, float]:
    """Seconds per primitive of each application, run one after the other on ``engine``."""
    seconds: dict[str, float] = {}
    for name, application in applications(n).items():
        t0 = time.perf_counter()
        report = await engine.run(application)  # type: ignore[arg-type]
        seconds[name] = (time.perf_counter() - t0) / n
        assert report.ok, report.summary_lines()
    return seconds


async def in_process(clock: Clock, n: int) -> dict[str, float]:
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
    deployment = await deploy_local(
        clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:", "libraries": "all"},
        engine_parameters=ENGINE_PARAMETERS, bridge_parameters={"state_period": 1.0},
    )
    try:
        await time_runs(deployment.engine, max(10, n // 10))  # warm-up: imports, first IK, caches
        return await time_runs(deployment.engine, n)
    finally:
        await deployment.close()


def start_nodes(env: dict[str, str], transport: tuple[str, ...] = ()) -> list[subprocess.Popen[bytes]]:
    """The simulator bridge and one machine per group, each its own process, as a launch file starts them
    (``transport``: e.g. ``("--transport", "dds")``; by default rclpy)."""
    bridge = [sys.executable, "-c", "import sys; from cell_runner.bridge_nodes.nextage_sim import main; sys.exit(main(sys.argv))",
              *transport, "--ros-args", "-p", "state_period:=1.0"]
    processes = [subprocess.Popen(bridge, env=env, cwd=ROOT)]
    for group in NEXTAGE_OPEN.group_names:
        machine = [sys.executable, str(Path(__file__).resolve()), "--machine", *transport, "--ros-args", "-r", f"__node:={group}_machine",
                   "-p", f"group:={group}", "-p", "trajectory_db:=':memory:'"]
        processes.append(subprocess.Popen(machine, env=env, cwd=ROOT))
    return processes


async def per_process(clock: Clock, n: int, transport_class: Any = None) -> dict[str, float]:
    """Seconds per primitive with the engine in this process on ``transport_class`` (default: rclpy)."""
    if transport_class is None:
        from node_transport.ros import RosTransport as transport_class

    transport = transport_class(clock, ["bench"])
    try:
        engine = ExecutionEngine(transport.create_node("execution_engine", parameters=ENGINE_PARAMETERS), APPLICATION_FUNCTIONS.catalog(None))
        await time_runs(engine, max(10, n // 10))
        return await time_runs(engine, n)
    finally:
        await transport.shutdown()


ECHO_TEXT = '{"id":"left_arm-0a1b2c-17","group":"left_arm","op":"execute","primitive":{"kind":"set_speed","fraction":0.5},"v":1}'


def echo_process() -> int:
    """Child mode: a raw rclpy node that sends every String on ``bench_ping`` back on ``bench_pong``."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
    from std_msgs.msg import String

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pong = node.create_publisher(String, "bench_pong", 50)
    node.create_subscription(String, "bench_ping", pong.publish, 50)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return 0


def raw_round_trip(n: int) -> float:
    """Seconds per round trip of a String to the echo process and back, raw rclpy on both sides."""
    import threading

    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from std_msgs.msg import String

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_ping", context=context)
    answered = threading.Event()
    ping = node.create_publisher(String, "bench_ping", 50)
    node.create_subscription(String, "bench_pong", lambda msg: answered.set(), 50)
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 30.0
        while ping.get_subscription_count() == 0 or node.count_publishers("bench_pong") == 0:
            if time.monotonic() > deadline:
                raise RuntimeError("the echo process never matched")
            time.sleep(0.01)
        time.sleep(0.5)  # the echo's own publisher must match us too
        message = String(data=ECHO_TEXT)
        for _ in range(max(10, n // 10)):  # warm-up
            answered.clear()
            ping.publish(message)
            answered.wait(5.0)
        t0 = time.perf_counter()
        for _ in range(n):
            answered.clear()
            ping.publish(message)
            if not answered.wait(5.0):
                raise RuntimeError("the echo process stopped answering")
        return (time.perf_counter() - t0) / n
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def machine_process() -> int:
    """Child mode: a group machine that also knows the bench skill."""
    from cell_runner.nodes import group_machine_main

    LIBRARIES["bench"] = BenchFunctions
    return group_machine_main([sys.argv[0], *sys.argv[2:]])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--machine":
        sys.exit(machine_process())
    if len(sys.argv) > 1 and sys.argv[1] == "--echo":
        sys.exit(echo_process())
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    LIBRARIES["bench"] = BenchFunctions
    os.environ["ROS_DOMAIN_ID"] = str(hold_domain())  # the cell of this bench only: no test or other bench uses it meanwhile (test/dds_domain.py)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    local_runs, ros_runs, echo_runs = [], [], []
    processes = start_nodes(env)
    processes.append(subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--echo"], env=env, cwd=ROOT))
    try:
        for _ in range(3):  # interleaved, so all see the same machine load
            local_runs.append(run_with_clock(lambda c: in_process(c, n), real_clock()))
            ros_runs.append(run_with_clock(lambda c: per_process(c, n), real_clock()))
            echo_runs.append(raw_round_trip(n))
    finally:
        for process in processes:
            process.terminate()
        for process in processes:
            process.wait(timeout=20)
    us = {
        f"{where}_{path}_us": round(statistics.median(r[path] for r in runs) * 1e6, 1)
        for where, runs in (("in_process", local_runs), ("per_process", ros_runs))
        for path in ("function", "skill")
    }
    us["raw_rclpy_round_trip_us"] = round(statistics.median(echo_runs) * 1e6, 1)
    ratios = {f"ratio_{path}": round(us[f"per_process_{path}_us"] / us[f"in_process_{path}_us"], 2) for path in ("function", "skill")}
    ratios["ratio_skill_vs_raw_round_trip"] = round(us["per_process_skill_us"] / us["raw_rclpy_round_trip_us"], 2)
    result = {"primitives": n, "runs": 3, "rmw": os.environ.get("RMW_IMPLEMENTATION", "default"), **us, **ratios}
    for path, label in (("function", "one primitive per function"), ("skill", "within one skill")):
        print(f"{label:28s} in-process {us[f'in_process_{path}_us']:8.1f} us, per-process over rclpy "
              f"{us[f'per_process_{path}_us']:8.1f} us per primitive ({ratios[f'ratio_{path}']}x)")
    print(f"{'raw rclpy echo round trip':28s} {us['raw_rclpy_round_trip_us']:8.1f} us "
          f"(a primitive within a skill: {ratios['ratio_skill_vs_raw_round_trip']}x of it)")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
