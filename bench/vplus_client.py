"""V+ client benchmark: one command's round trip vs a raw asyncio echo, and joined-ack throughput.

Run: ``python bench/vplus_client.py [--rounds N] [--joined N] [--repeats N]``

* Round trip: our :class:`VPlusClient.execute` of one message against a minimal ack server (it
  answers each line with a canned ack for its id -- as cheap a server as the echo) versus a raw
  asyncio client writing one line to an echo server and awaiting the echoed line.  Both on
  loopback in this process, same loop, in interleaved blocks so both see the same background
  load; the headline compares the best block of each (the least disturbed), the median of the
  per-block ratios is given too, and the same per block in CPU time of this process (both ends
  run here, so a round trip is CPU: the figure that holds when the machine is shared).  The
  ratio is the client's overhead (aim <= 1.3x, issue 22).  The round
  trip against the full simulator (kinematics, pose in every ack) is printed as well.
* Throughput: ``execute_joined`` of many ``set_speed`` messages against the full simulator;
  acked messages per second (aim >= 10,000/s).

Seed anchor (pyadept on a Raspberry Pi, real Viper s850): ~0.2 ms between consecutive sends,
~1 ms robot/vision switching.  The last line printed is one JSON object with every figure.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from node_transport.clock import Clock, real_clock, run_with_clock  # noqa: E402
from robot_bridges.vplus import codec  # noqa: E402
from robot_bridges.vplus.client import VPlusClient  # noqa: E402
from robot_bridges.vplus.simulator import VPlusSimulator  # noqa: E402

LINE = b"0a1b2c3d:set_speed:50\r\n"
CANNED = b":done:0.000,0.000:480.000,0.000,710.000,0.000,180.000,0.000\r\n"


async def _echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while line := await reader.readuntil(b"\r\n"):
            writer.write(line)
    except (asyncio.IncompleteReadError, ConnectionError):
        pass
    finally:
        writer.close()


async def _acker(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while line := await reader.readuntil(b"\r\n"):
            writer.write(line[: line.index(b":")] + CANNED)
    except (asyncio.IncompleteReadError, ConnectionError):
        pass
    finally:
        writer.close()


async def _per_call(rounds: int, call: Callable[[], Awaitable[object]]) -> float:
    """Mean seconds per call over ``rounds`` calls (wall time)."""
    start = time.perf_counter()
    for _ in range(rounds):
        await call()
    return (time.perf_counter() - start) / rounds


async def _per_call_both(rounds: int, call: Callable[[], Awaitable[object]], cpu: list[float]) -> float:
    """Mean wall seconds per call, and the mean CPU seconds of this process per call appended to
    ``cpu`` (both ends run here, so a round trip is CPU: the figure that holds on a shared machine)."""
    start_cpu = time.process_time()
    wall = await _per_call(rounds, call)
    cpu.append((time.process_time() - start_cpu) / rounds)
    return wall


async def _serve(handler: Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]) -> tuple[asyncio.Server, int]:
    server = await asyncio.start_server(handler, "127.0.0.1", 0)
    return server, int(server.sockets[0].getsockname()[1])


async def round_trips(clock: Clock, rounds: int, blocks: int, cpu: dict[str, list[float]]) -> tuple[list[float], list[float], list[float]]:
    """Interleaved blocks of raw echo, client + ack server, client + simulator round trips.

    Interleaving puts the three under the same background load (the order of the first two
    alternating from block to block); each block gives a mean, wall and CPU (into ``cpu``).
    """
    echo_server, echo_port = await _serve(_echo)
    ack_server, ack_port = await _serve(_acker)
    sim = await VPlusSimulator(clock).start()
    reader, writer = await asyncio.open_connection("127.0.0.1", echo_port)
    ours = VPlusClient("127.0.0.1", ack_port, clock)
    on_sim = VPlusClient("127.0.0.1", sim.port, clock)
    await ours.connect()
    await on_sim.connect()
    command = codec.set_speed(50)

    async def raw_call() -> bytes:
        writer.write(LINE)
        return await reader.readuntil(b"\r\n")

    raw: list[float] = []
    client: list[float] = []
    simulated: list[float] = []
    try:
        for call in (raw_call, lambda: ours.execute(command), lambda: on_sim.execute(command)):
            await _per_call(200, call)  # warm-up
        for block in range(blocks):
            if block % 2 == 0:
                raw.append(await _per_call_both(rounds, raw_call, cpu["raw"]))
            client.append(await _per_call_both(rounds, lambda: ours.execute(command), cpu["client"]))
            if block % 2 == 1:
                raw.append(await _per_call_both(rounds, raw_call, cpu["raw"]))
            simulated.append(await _per_call(rounds, lambda: on_sim.execute(command)))
    finally:
        writer.close()
        await ours.close()
        await on_sim.close()
        await sim.close()
        for server in (echo_server, ack_server):
            server.close()
            await server.wait_closed()
    return raw, client, simulated


async def joined_throughput(clock: Clock, messages: int) -> float:
    async with VPlusSimulator(clock) as sim:
        client = VPlusClient("127.0.0.1", sim.port, clock, timeout=60.0)
        await client.connect()
        commands = [codec.set_speed(50)] * messages
        try:
            await client.execute_joined(*commands[: min(500, messages)])  # warm-up
            start = time.perf_counter()
            acks = await client.execute_joined(*commands)
            elapsed = time.perf_counter() - start
        finally:
            await client.close()
        assert len(acks) == messages
        return messages / elapsed


async def bench(clock: Clock, rounds: int, joined: int, repeats: int) -> dict[str, float]:
    cpu: dict[str, list[float]] = {"raw": [], "client": []}
    raw, ours, sim_rt = await round_trips(clock, rounds, repeats, cpu)
    for i, (a, b, c) in enumerate(zip(raw, ours, sim_rt)):
        ca, cb = cpu["raw"][i], cpu["client"][i]
        print(f"block {i + 1}/{repeats}: raw echo {a * 1e6:6.1f} us | client+ack server {b * 1e6:6.1f} us ({b / a:.2f}x) | "
              f"CPU {ca * 1e6:5.1f} vs {cb * 1e6:5.1f} us ({cb / ca:.2f}x) | client+simulator {c * 1e6:6.1f} us")
    rates = []
    for i in range(repeats):
        rates.append(await joined_throughput(clock, joined))
        print(f"joined run {i + 1}/{repeats}: {rates[-1]:8.0f} acked messages/s")
    ratios = [b / a for a, b in zip(raw, ours)]
    cpu_ratios = [b / a for a, b in zip(cpu["raw"], cpu["client"])]
    raw_us, ours_us, sim_us = (min(v) * 1e6 for v in (raw, ours, sim_rt))
    best_ratio, median_ratio = ours_us / raw_us, statistics.median(ratios)
    rate = statistics.median(rates)
    print(f"round trip, best block of {repeats}: raw asyncio echo {raw_us:.1f} us, our client {ours_us:.1f} us -> {best_ratio:.2f}x (aim <= 1.3x)")
    print(f"round trip ratio, median over interleaved blocks: {median_ratio:.2f}x (wall), "
          f"{statistics.median(cpu_ratios):.2f}x CPU [{min(cpu_ratios):.2f}-{max(cpu_ratios):.2f}] (aim <= 1.3x)")
    print(f"round trip through the full simulator (kinematics and pose in every ack): {sim_us:.1f} us")
    print(f"joined commands: {rate:,.0f} acked messages/s, median of {repeats} (aim >= 10,000/s)")
    print("seed anchor: pyadept ~200 us between consecutive sends, ~1 ms switching (Raspberry Pi, real robot)")
    return {
        "raw_echo_rtt_us": round(raw_us, 1),
        "client_rtt_us": round(ours_us, 1),
        "client_vs_echo_ratio": round(best_ratio, 3),
        "client_vs_echo_ratio_median": round(median_ratio, 3),
        "raw_echo_cpu_us": round(statistics.median(cpu["raw"]) * 1e6, 1),
        "client_cpu_us": round(statistics.median(cpu["client"]) * 1e6, 1),
        "client_vs_echo_cpu_ratio_median": round(statistics.median(cpu_ratios), 3),
        "client_vs_echo_cpu_ratio_range": [round(min(cpu_ratios), 3), round(max(cpu_ratios), 3)],
        "client_simulator_rtt_us": round(sim_us, 1),
        "joined_acks_per_s": round(rate),
        "rounds": rounds,
        "joined_messages": joined,
        "repeats": repeats,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=2000, help="round trips per block")
    parser.add_argument("--joined", type=int, default=5000, help="messages in the joined call")
    parser.add_argument("--repeats", type=int, default=9, help="interleaved blocks / joined runs")
    args = parser.parse_args()
    figures = run_with_clock(lambda clock: bench(clock, args.rounds, args.joined, args.repeats), real_clock())
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
