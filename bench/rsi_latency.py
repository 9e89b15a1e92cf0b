"""KUKA RSI bridge: reply latency, late packets, reaction time and setter/getter cost.

    python bench/rsi_latency.py                 # 60 s at a real 4 ms cycle + 100,000 accelerated cycles
    python bench/rsi_latency.py --quick         # a short smoke run of the same

Four measurements, each beside a baseline measured in the same run:

1. accelerated: the simulated KR C4 in lockstep sends 100,000 packets to the RSI loop (its own
   process, a move always running, every packet saved to a file) and to a bare UDP echo server
   (its own process); round trips as the controller sees them;
2. real time: for >= 60 s at 4 ms, the execution engine runs ``apps_xml/kuka_rsi_demo.xml`` again
   and again on the KUKA back end (loop process, saving thread on) while a second simulator
   drives the echo server; round trips and the controller's count of late replies;
3. reaction: ``set_cart_pos`` to the first feedback packet whose actual TCP moved >= 0.01 mm,
   from rest, 2 m/s and 3 m/s^2 (ITRA's measurement; ITRA reports 30 ms at 4 ms);
4. cost of ``set_cart_pos`` and ``get_curr_pos`` per call (ITRA on Linux: 16.3 us and 35.8 us);
5. the runner decision: the loop on a thread of a busy application process (Python bursts holding
   the GIL, garbage collection over a large heap) against the loop in its own process, at 4 ms.

The last line is one JSON object with every figure.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from core_functions.robots import KUKA_KR  # noqa: E402
from robot_bridges.kuka_rsi.backend import KukaRsiBackend  # noqa: E402
from robot_bridges.kuka_rsi.config import default_config  # noqa: E402
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink  # noqa: E402
from robot_bridges.kuka_rsi.interface import RsiInterface  # noqa: E402
from robot_bridges.kuka_rsi.krc_model import KrcModel, RsiContext  # noqa: E402
from robot_bridges.kuka_rsi.sim_network import latency_summary, run_lockstep  # noqa: E402

READY_DEG = (0.0, -80.0, 85.0, 0.0, 35.0, 0.0)
CYCLE = 0.004
READY = "ready"  # what the echo process prints once its socket is bound
STARTUP_TIMEOUT = 60.0  # s: the most a process of this bench may take to be ready (a busy computer included)


# ------------------------------------------------------------------------------- helpers
def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def echo_main(port: int, idle: float) -> None:
    """The baseline: receive, send the same bytes back; nothing else.  Ends after ``idle`` s of silence."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(idle)
    buf = bytearray(65536)
    print(READY, flush=True)
    try:
        while True:
            n, addr = sock.recvfrom_into(buf)
            sock.sendto(buf[:n], addr)
    except TimeoutError:
        pass


def start_echo(idle: float = 5.0) -> tuple[subprocess.Popen[str], int]:
    """The echo process, once it listens: a controller started before it would count its first
    packets late, and after 100 of them in a row (0.4 s: a busy computer starting Python) stop RSI."""
    port = free_port()
    proc = subprocess.Popen([sys.executable, __file__, "--echo", str(port), "--idle", str(idle)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], STARTUP_TIMEOUT)
    line = proc.stdout.readline().strip() if ready else ""
    if line != READY:
        proc.kill()
        proc.wait(10)
        raise RuntimeError(f"the UDP echo process was not ready within {STARTUP_TIMEOUT:g} s ({line or 'no word'}, exit {proc.poll()})")
    return proc, port


def start_simulator(port: int, seconds: float, *, echo: bool = False) -> subprocess.Popen[str]:
    args = [sys.executable, "-m", "robot_bridges.kuka_rsi.simulator", "--to", f"127.0.0.1:{port}", "--cycles", str(int(seconds / CYCLE))]
    args += ["--rt-priority", "20"] + (["--accept-echo"] if echo else [])
    return subprocess.Popen(args, stdout=subprocess.PIPE, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})


def summary_of(proc: subprocess.Popen[str], timeout: float) -> dict[str, object]:
    out, _ = proc.communicate(timeout=timeout)
    lines = [line for line in out.splitlines() if line.startswith("{")]
    return json.loads(lines[-1]) if lines else {}


def percentiles(values_us: list[float]) -> dict[str, float]:
    return latency_summary([int(v * 1000) for v in values_us])


def fmt(stats: dict[str, float] | dict[str, object]) -> str:
    if not stats:
        return "-"
    return f"p50 {stats['p50']:.1f}  p99 {stats['p99']:.1f}  p99.9 {stats['p99.9']:.1f}  max {stats['max']:.1f} us"


def settle(iface: RsiInterface, packets: int = 10) -> None:
    """Wait until the actual TCP has not moved by 1e-7 m for ``packets`` packets: "done" comes when
    it is within tolerance, while the servo still creeps the last fraction of a millimetre."""
    last, still, seen = iface.get_curr_pos(0), 0, 0.0
    while still < packets:
        time.sleep(CYCLE / 2)
        pos = iface.get_curr_pos(0)
        if pos.t_us != seen:
            seen = pos.t_us
            still = still + 1 if math.dist(pos.cartesian[:3], last.cartesian[:3]) < 1e-7 else 0
            last = pos


def handshake(iface: RsiInterface) -> None:
    """Allow start and allow move: after these the robot follows corrections."""
    iface.allow_robot_start(0, 30)
    iface.allow_robot_move(0, 30)


# ------------------------------------------------------------------- 1. accelerated, 100k
def accelerated(cycles: int, feedback: Path | None, switch_interval: float | None = None) -> dict[str, object]:
    config = default_config()
    settings = LoopSettings(port=0, silence_timeout=2.0, record_busy=True, switch_interval=switch_interval)
    iface = RsiInterface([RobotLink("kr6", "127.0.0.1")], settings, mode="process")
    iface.start()
    address = iface.wait_ready()
    if feedback is not None:
        iface.set_feedback_output(0, str(feedback))
        iface.wait_event(lambda: iface.events.feedback[0] is not None, 10)
    model = KrcModel(config, RsiContext(start_deg=READY_DEG))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    result: dict[str, object] = {}

    def simulate() -> None:
        result["stopped"] = run_lockstep(sock, address, model, cycles=cycles, reply_grace=2.0, now_ns=time.perf_counter_ns)

    sim = threading.Thread(target=simulate)
    sim.start()
    handshake(iface)
    targets = [np.radians(READY_DEG), np.radians((40.0, -60.0, 70.0, 30.0, 60.0, 45.0))]
    k = 0
    while sim.is_alive():  # keep the generator busy: a new target every 300 cycles
        state = iface.state(0)
        if state.cycles >= 300 * (k + 1):
            iface.set_axial_pos(0, targets[k % 2], 2.0, 5.0)
            k += 1
        iface.wait_event(lambda: False, 0.01)
    sock.close()
    iface.request_stats()
    iface.wait_event(lambda: iface.events.stats is not None, 10)
    stats = iface.events.stats or ()
    iface.close()
    lines = sum(1 for _ in feedback.open()) - 1 if feedback is not None else 0
    busy = stats[5] if stats else []
    rsi = model.stats
    echo_proc, echo_port = start_echo()
    echo_model = KrcModel(config, RsiContext(start_deg=READY_DEG), accept_echo=True)
    echo_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    echo_sock.bind(("127.0.0.1", 0))
    run_lockstep(echo_sock, ("127.0.0.1", echo_port), echo_model, cycles=cycles, reply_grace=2.0, now_ns=time.perf_counter_ns)
    echo_sock.close()
    echo_proc.terminate()  # our own child, by its handle
    echo_proc.wait(10)
    return {
        "cycles": rsi.packets,
        "answered": rsi.accepted,
        "late": rsi.late,
        "rsi_round_trip_us": latency_summary(rsi.latencies_ns),
        "echo_round_trip_us": latency_summary(echo_model.stats.latencies_ns),
        "over_cycle": int(sum(1 for v in rsi.latencies_ns if v > CYCLE * 1e9)),
        "loop_busy_us": latency_summary(busy),
        "feedback_lines": lines,
        "moves": k,
    }


# ---------------------------------------------------------------- 2. real time with the engine
async def when_bound(backend: KukaRsiBackend, start: Callable[[], None]) -> None:
    """``start`` the controller once the back end's RSI loop has bound its port, as the back end
    itself starts its simulator: a controller sending before then counts every packet late and stops
    RSI after 100 in a row (0.4 s), less than the loop's start takes on a busy computer."""
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while backend.iface is None or backend.iface.events.address is None:
        if time.monotonic() > deadline:
            raise RuntimeError(f"the RSI loop did not bind within {STARTUP_TIMEOUT:g} s")
        await asyncio.sleep(0.01)
    start()


async def engine_phase(port: int, seconds: float, feedback: Path, start_controller: Callable[[], None]) -> dict[str, object]:
    from app_functions.registry import full_catalog
    from execution_engine.app_model import load_application
    from node_transport.clock import real_clock
    from cell_runner.deployment import deploy_local

    app = load_application(str(ROOT / "apps_xml" / "kuka_rsi_demo.xml"), full_catalog())
    backend = KukaRsiBackend(listen=("127.0.0.1", port), simulator=None, runner="process", feedback_file=str(feedback))
    clock = real_clock().bind(asyncio.get_running_loop())
    starter = asyncio.create_task(when_bound(backend, start_controller))
    try:
        deployment = await deploy_local(clock, KUKA_KR, backend)
    finally:
        if not starter.done():
            starter.cancel()
    await starter  # the controller was started (or why not)
    runs, ok = 0, 0
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        report = await deployment.engine.run(app)
        runs += 1
        ok += bool(report.ok)
    try:
        await asyncio.wait_for(deployment.close(), 15)
    except asyncio.TimeoutError:
        print("  (the deployment did not close within 15 s; carrying on)")
    return {"app_runs": runs, "app_runs_ok": ok, "seconds": time.monotonic() - started}


def real_time(seconds: float, feedback: Path, echo: bool = True) -> dict[str, object]:
    """The engine phase against a simulated KR C4; ``echo``: a second simulator drives the bare UDP
    echo baseline at the same time (two more processes on the machine, one of them real time)."""
    port = free_port()
    echo_proc, echo_port = start_echo(idle=seconds + 120) if echo else (None, 0)
    echo_sim = start_simulator(echo_port, seconds + 80.0, echo=True) if echo_proc is not None else None
    started: list[subprocess.Popen[str]] = []
    try:
        # The engine phase may run past ``seconds`` by one application run (~20 s): the simulator outlasts it.
        result = asyncio.run(engine_phase(port, seconds, feedback, lambda: started.append(start_simulator(port, seconds + 40.0))))
    finally:
        for proc in (*started, echo_sim):
            if proc is not None:
                proc.terminate()  # ends the run cleanly (SIGTERM): the summary is still printed
    rsi, echo_summary = summary_of(started[0], 30), summary_of(echo_sim, 30) if echo_sim is not None else {}
    if echo_proc is not None:
        echo_proc.terminate()
        echo_proc.wait(10)
    result.update(
        {
            "packets": rsi.get("packets"),
            "late": rsi.get("late_since_first_reply"),
            "late_ipocs_from_end": [int(i) - int(rsi.get("last_ipoc", 0)) for i in rsi.get("late_ipocs", [])],  # type: ignore[union-attr]
            "late_before_first_reply": int(rsi.get("late", 0)) - int(rsi.get("late_since_first_reply", 0)),  # type: ignore[call-overload]
            "simulator_overruns": rsi.get("overruns"),
            "rsi_round_trip_us": rsi.get("round_trip_us"),
            "echo_packets": echo_summary.get("packets"),
            "echo_late": echo_summary.get("late_since_first_reply"),
            "echo_round_trip_us": echo_summary.get("round_trip_us"),
            "feedback_lines": sum(1 for _ in feedback.open()) - 1 if feedback.exists() else 0,
        }
    )
    return result


# ------------------------------------------------------------- 5. thread or process: the decision
def application_load(stop: threading.Event, burst: float = 0.02, pause: float = 0.1) -> None:
    """What an application process does to a thread beside it: Python bursts holding the GIL and
    allocation churn over a large heap, so the collector's full passes take a while."""
    heap = [{"k": [i, str(i)]} for i in range(150_000)]  # long-lived, tracked objects
    while not stop.is_set():
        end = time.perf_counter() + burst
        garbage = []
        while time.perf_counter() < end:
            node: dict[str, object] = {}
            node["self"] = node  # a cycle: only the collector frees it
            garbage.append(node)
        del garbage
        stop.wait(pause)
    del heap


def runner_comparison(seconds: float) -> dict[str, object]:
    out: dict[str, object] = {}
    for mode in ("thread", "process"):
        port = free_port()
        iface = RsiInterface([RobotLink("kr6", "127.0.0.1")], LoopSettings(port=port, silence_timeout=2.0), mode=mode)  # type: ignore[arg-type]
        iface.start()
        iface.wait_ready()
        sim = start_simulator(port, seconds + 5.0)
        stop = threading.Event()
        load = threading.Thread(target=application_load, args=(stop,))
        try:
            if not iface.wait_event(lambda: iface.events.connected[0], 30):
                raise RuntimeError("no packets from the simulator")
            handshake(iface)
            load.start()
            targets = [np.radians(READY_DEG), np.radians((40.0, -60.0, 70.0, 30.0, 60.0, 45.0))]
            started, k = time.monotonic(), 0
            while time.monotonic() - started < seconds:
                iface.set_axial_pos(0, targets[k % 2], 2.0, 5.0)
                k += 1
                iface.wait_event(lambda: False, 1.0)
        finally:
            stop.set()
            if load.is_alive():
                load.join()
            sim.terminate()
            summary = summary_of(sim, 30)
            iface.close()
        out[mode] = {"late": summary.get("late_since_first_reply"), "packets": summary.get("packets"), "round_trip_us": summary.get("round_trip_us"), "stopped": summary.get("stopped"), "late_replies": summary.get("late_replies"), "lateness_us": summary.get("lateness_us")}
    return out


# ---------------------------------------------------------------- 3 + 4. reaction and cost
def reaction_and_cost(trials: int, calls: int) -> dict[str, object]:
    port = free_port()
    iface = RsiInterface([RobotLink("kr6", "127.0.0.1")], LoopSettings(port=port, silence_timeout=2.0), mode="process")
    iface.start()
    sim: subprocess.Popen[str] | None = None
    try:
        iface.wait_ready(STARTUP_TIMEOUT)  # the loop listens before the controller sends (see when_bound)
        sim = start_simulator(port, 600.0)
        if not iface.wait_event(lambda: iface.events.connected[0], 30):
            raise RuntimeError("no packets from the simulator")
        first_ipoc = iface.state(0).ipoc
        handshake(iface)
        cmd = iface.set_axial_pos(0, np.radians(READY_DEG), 1.0, 3.0)
        iface.wait_event(lambda: cmd in iface.events.done, 30)
        settle(iface)
        reactions: list[float] = []
        rng = np.random.default_rng(1)
        for k in range(trials):
            start = iface.state(0)
            start_pose = start.tcp()
            time.sleep(rng.uniform(0.0, CYCLE))  # any phase of the cycle
            target = start_pose.translated(0.005 if k % 2 == 0 else -0.005, 0.0, 0.0)
            t0 = iface.get_timestamp()
            cmd = iface.set_cart_pos(0, target, 2.0, 3.0)
            while True:
                pos = iface.get_curr_pos(0)
                if math.dist(pos.cartesian[:3], start_pose.position) >= 1e-5:
                    reactions.append((pos.t_us - t0) / 1000.0)
                    break
                time.sleep(0.0002)
            iface.wait_event(lambda: cmd in iface.events.done, 10)
            settle(iface)
        here = iface.state(0).tcp()
        set_ns, get_ns = [], []
        clock = time.perf_counter_ns
        for _ in range(calls):
            a = clock()
            iface.set_cart_pos(0, here, 0.5, 1.0)
            b = clock()
            iface.get_curr_pos(0)
            c = clock()
            set_ns.append(b - a)
            get_ns.append(c - b)
        overhead = min(clock() - clock() for _ in range(1000))
    finally:
        summary: dict[str, object] = {}
        if sim is not None:
            sim.terminate()  # the controller first: a loop closed under it would leave it unanswered
            summary = summary_of(sim, 30)
        iface.close()
    ms = np.array(reactions or [0.0])
    return {
        "reaction_ms": {"p50": float(np.percentile(ms, 50)), "p75": float(np.percentile(ms, 75)), "p99": float(np.percentile(ms, 99)), "max": float(ms.max()), "n": len(ms)},
        "set_cart_pos_us": {"p50": float(np.percentile(set_ns or [0], 50)) / 1000, "p99": float(np.percentile(set_ns or [0], 99)) / 1000},
        "get_curr_pos_us": {"p50": float(np.percentile(get_ns or [0], 50)) / 1000, "p99": float(np.percentile(get_ns or [0], 99)) / 1000},
        "timer_overhead_us": overhead / 1000,
        "late_during_reaction": summary.get("late_since_first_reply"),
        "late_ipocs_during_reaction": summary.get("late_ipocs"),
        "late_replies_during_reaction": summary.get("late_replies"),
        "lateness_during_reaction_us": summary.get("lateness_us"),
        "first_ipoc": first_ipoc,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="real-time phase at 4 ms (default 60)")
    parser.add_argument("--cycles", type=int, default=100_000, help="accelerated cycles (default 100000)")
    parser.add_argument("--trials", type=int, default=100, help="reaction-time trials (default 100)")
    parser.add_argument("--calls", type=int, default=100_000, help="setter/getter calls timed (default 100000)")
    parser.add_argument("--quick", action="store_true", help="10 s, 10,000 cycles, 20 trials, 20,000 calls; 5 s per runner unless --compare-seconds is given")
    parser.add_argument("--skip-engine", action="store_true", help="leave out the real-time phase with the engine")
    parser.add_argument("--compare-seconds", type=float, default=None, help="thread vs process runner under load, each (default 20; 0: skip)")
    parser.add_argument("--echo", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--idle", type=float, default=5.0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo is not None:
        echo_main(args.echo, args.idle)
        return 0
    if args.quick:
        args.seconds, args.cycles, args.trials, args.calls = 10.0, 10_000, 20, 20_000
    if args.compare_seconds is None:
        args.compare_seconds = 5.0 if args.quick else 20.0
    figures: dict[str, object] = {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        print(f"1. accelerated: {args.cycles} cycles (loop process, a move always running, saving every packet)")
        acc = accelerated(args.cycles, Path(tmp) / "accelerated.txt")
        print(f"   RSI loop : {fmt(acc['rsi_round_trip_us'])}  ({acc['over_cycle']} over 4 ms, {acc['late']} late)")  # type: ignore[arg-type]
        print(f"   UDP echo : {fmt(acc['echo_round_trip_us'])}")  # type: ignore[arg-type]
        print(f"   loop busy (receive to send): {fmt(acc['loop_busy_us'])}; feedback file {acc['feedback_lines']} lines")  # type: ignore[arg-type]
        figures["accelerated"] = acc
        if not args.skip_engine:
            print(f"2. real time: {args.seconds:g} s at 4 ms, engine running {ROOT.name}/apps_xml/kuka_rsi_demo.xml in a loop, saving on")
            rt = real_time(args.seconds, Path(tmp) / "realtime.txt")
            print(f"   RSI loop : {fmt(rt['rsi_round_trip_us'])}  late {rt['late']} of {rt['packets']} once connected (simulator overruns {rt['simulator_overruns']})")  # type: ignore[arg-type]
            print(f"   UDP echo : {fmt(rt['echo_round_trip_us'])}  late {rt['echo_late']} of {rt['echo_packets']}")  # type: ignore[arg-type]
            print(f"   engine   : {rt['app_runs_ok']}/{rt['app_runs']} application runs ok in {rt['seconds']:.0f} s; feedback {rt['feedback_lines']} lines")
            figures["real_time"] = rt
        print(f"3+4. reaction ({args.trials} trials, 2 m/s, 3 m/s^2) and cost ({args.calls} calls), real time")
        rc = reaction_and_cost(args.trials, args.calls)
        r = rc["reaction_ms"]
        print(f"   reaction : p50 {r['p50']:.2f}  p75 {r['p75']:.2f}  max {r['max']:.2f} ms   (ITRA, Linux, RSI-based: p50 30.14 ms)")  # type: ignore[index]
        print(f"   set_cart_pos p50 {rc['set_cart_pos_us']['p50']:.2f} us  p99 {rc['set_cart_pos_us']['p99']:.2f} us   (ITRA: 16.3 us)")  # type: ignore[index]
        print(f"   get_curr_pos p50 {rc['get_curr_pos_us']['p50']:.2f} us  p99 {rc['get_curr_pos_us']['p99']:.2f} us   (ITRA: 35.8 us)")  # type: ignore[index]
        figures["reaction_and_cost"] = rc
        if args.compare_seconds > 0:
            print(f"5. thread or process: {args.compare_seconds:g} s each at 4 ms beside an application thread (GIL bursts, GC over a large heap)")
            cmp = runner_comparison(args.compare_seconds)
            for mode in ("thread", "process"):
                m = cmp[mode]
                print(f"   {mode:7s}: {fmt(m['round_trip_us'])}  late {m['late']} of {m['packets']}")  # type: ignore[index]
            figures["runner_comparison"] = cmp
    acc_rsi, acc_echo = acc["rsi_round_trip_us"], acc["echo_round_trip_us"]
    figures["ratios"] = {
        "accelerated_p50_rsi_over_echo": acc_rsi["p50"] / acc_echo["p50"],  # type: ignore[index]
        "accelerated_p99_rsi_over_echo": acc_rsi["p99"] / acc_echo["p99"],  # type: ignore[index]
        "reaction_p50_itra_over_ours": 30.14 / rc["reaction_ms"]["p50"],  # type: ignore[index]
        "set_cart_pos_itra_over_ours": 16.3 / rc["set_cart_pos_us"]["p50"],  # type: ignore[index]
        "get_curr_pos_itra_over_ours": 35.8 / rc["get_curr_pos_us"]["p50"],  # type: ignore[index]
    }
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
