"""The injectable clock: simulated time jumps idle waits, scaled time runs faster, all run time starts at 0."""
from __future__ import annotations

import asyncio
import math
import time
from typing import Any

import pytest

from node_transport.clock import Clock, VirtualTimeLoop, run_with_clock, scaled_clock, simulated_clock


def test_simulated_clock_jumps_over_waits_and_orders_timers(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[str, float]], float]:
        order: list[tuple[str, float]] = []

        async def sleeper(name: str, seconds: float) -> None:
            await clock.sleep(seconds)
            order.append((name, clock.now()))

        await asyncio.gather(sleeper("late", 3600.0), sleeper("early", 0.25), sleeper("middle", 60.0))
        return order, clock.now()

    wall = time.perf_counter()
    order, now = run_sim(main)
    assert order == [("early", 0.25), ("middle", 60.0), ("late", 3600.0)]
    assert now == 3600.0
    assert time.perf_counter() - wall < 5.0  # an hour of run time, no hour of waiting


def test_wait_for_times_out_in_run_seconds(run_sim: Any) -> None:
    async def main(clock: Clock) -> float:
        with pytest.raises(asyncio.TimeoutError):
            await clock.wait_for(asyncio.Event().wait(), 42.0)
        return clock.now()

    assert run_sim(main) == pytest.approx(42.0)


def test_call_later_and_sleep_until(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[float]:
        fired: list[float] = []
        clock.call_later(5.0, lambda: fired.append(clock.now()))
        await clock.sleep_until(7.5)
        await clock.sleep_until(1.0)  # in the past: returns at once
        fired.append(clock.now())
        return fired

    assert run_sim(main) == [pytest.approx(5.0), pytest.approx(7.5)]


def test_scaled_clock_runs_run_time_faster_than_wall_time() -> None:
    async def main(clock: Clock) -> tuple[float, float]:
        start = time.perf_counter()
        await clock.sleep(2.0)  # 2 run seconds at x100 = 20 ms of wall time
        return clock.now(), time.perf_counter() - start

    now, wall = run_with_clock(main, scaled_clock(100.0))
    assert now == pytest.approx(2.0, abs=0.5)
    assert wall < 1.0
    assert scaled_clock(100.0).to_wall(2.0) == pytest.approx(0.02)


@pytest.mark.parametrize("speed", [0.0, -1.0, math.inf, math.nan])
def test_bad_speed_factors_are_refused(speed: float) -> None:
    with pytest.raises(ValueError, match="positive finite"):
        Clock(speed)


def test_a_simulated_clock_refuses_a_real_loop() -> None:
    async def main() -> None:
        simulated_clock().bind()

    with pytest.raises(RuntimeError, match="needs a VirtualTimeLoop"):
        asyncio.run(main())


def test_a_clock_serves_one_loop_only() -> None:
    clock = simulated_clock()
    loop_a, loop_b = VirtualTimeLoop(), VirtualTimeLoop()
    try:
        clock.bind(loop_a)
        with pytest.raises(RuntimeError, match="serves one event loop"):
            clock.bind(loop_b)
    finally:
        loop_a.close()
        loop_b.close()


def test_loopback_sockets_work_under_virtual_time(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[bytes, float]:
        async def echo(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            data = await reader.readline()
            await clock.sleep(3.0)  # the peer takes 3 run seconds to answer
            writer.write(data.upper())
            await writer.drain()
            writer.close()

        server = await asyncio.start_server(echo, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"ping\n")
        answer = await clock.wait_for(reader.readline(), 10.0)
        writer.close()
        server.close()
        await server.wait_closed()
        return answer, clock.now()

    answer, now = run_sim(main)
    assert answer == b"PING\n"
    assert now == pytest.approx(3.0, abs=0.01)
