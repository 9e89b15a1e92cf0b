"""The V+ simulator's client slots: what counts as work, and that no set of clients can lock a working one out.

A client holds a slot only by sending complete messages of skills the server has.  Empty lines,
a few bytes now and then, malformed lines and unknown skills are not work: they neither keep a
slot nor stop the idle clock.  Every loop here is bounded in count and in (simulated) time.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from typing import Any

import pytest

from node_transport.clock import Clock
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import VPlusClient, VPlusError
from robot_bridges.vplus.simulator import MAX_CLIENTS, VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]


async def served(clock: Clock, port: int) -> bool:
    """Whether a real client gets a slot and an ack for a ``break`` (one attempt, no retry)."""
    client = VPlusClient("127.0.0.1", port, clock, timeout=2.0, retries=0)
    try:
        await client.connect()
        return (await client.execute(codec.BREAK))[0].status == "done"
    except VPlusError:
        return False
    finally:
        await client.close()


async def trickle(clock: Clock, port: int, data: bytes, every: float, times: int, said: list[bytes]) -> None:
    """A client that sends ``data`` every ``every`` s, ``times`` times at most; what the server said goes to ``said``."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        for _ in range(times):
            if writer.is_closing() or reader.at_eof():
                break
            writer.write(data)
            try:
                await writer.drain()
            except ConnectionError:
                break
            try:  # anything the server says (it talks only to close us)
                line = await clock.wait_for(reader.readline(), every)
            except asyncio.TimeoutError:
                continue
            if line:
                said.append(line)
            break
    finally:
        writer.close()


def test_more_trickling_clients_than_slots_cannot_keep_a_real_client_out(run_sim: Run) -> None:
    """Eleven clients each send an empty line every second: the slots they hold go to a real client
    within ``reclaim_after``, and each trickler is closed ``idle_timeout`` after it connected."""

    async def main(clock: Clock) -> tuple[list[float], list[bytes], int]:
        async with VPlusSimulator(clock) as sim:  # the defaults: idle 60 s, reclaimed after 30 s
            said: list[bytes] = []
            tricklers = [asyncio.ensure_future(trickle(clock, sim.port, b"\r\n", 1.0, 150, said)) for _ in range(MAX_CLIENTS + 1)]
            await clock.sleep(0.5)
            full = sim.clients
            attempts: list[float] = []  # when a real client, trying once a second, was served
            for _ in range(120):
                if await served(clock, sim.port):
                    attempts.append(clock.now())
                    break
                await clock.sleep(1.0)
            await asyncio.wait_for(asyncio.gather(*tricklers), None)
            return attempts, said, full

    attempts, said, full = run_sim(main)
    assert full == MAX_CLIENTS  # the eleventh trickler was refused: every slot was held
    assert attempts and 30.0 <= attempts[0] <= 32.0  # served once a trickler had been idle 30 s, whatever it sent
    assert any(line.startswith(b"closed: idle for 30") and b"another client needs the slot" in line for line in said)
    assert sum(line == b"closed: idle for 60 s\r\n" for line in said) == MAX_CLIENTS - 1  # the rest: 60 s after connecting


def test_a_client_that_works_keeps_its_slot_and_a_newcomer_is_refused_saying_why(run_sim: Run) -> None:
    async def main(clock: Clock) -> tuple[bool, bool, list[str]]:
        async with VPlusSimulator(clock, max_clients=1) as sim:
            worker = VPlusClient("127.0.0.1", sim.port, clock, timeout=2.0, retries=0)
            await worker.connect()
            for _ in range(4):  # a command every 20 s: never idle for 30
                await worker.execute(codec.BREAK)
                await clock.sleep(20.0)
            newcomer = await served(clock, sim.port)  # 20 s after the worker's last command
            still = (await worker.execute(codec.BREAK))[0].status == "done"
            await worker.close()
            return newcomer, still, list(sim.errors)

    newcomer, still, errors = run_sim(main)
    assert not newcomer and still
    assert "refused: 1 clients already connected; idle ones are closed after 60 s, and one idle for 30 s gives its slot to a new client" in errors[-1]


def test_a_client_whose_motion_is_under_way_is_not_idle(run_sim: Run) -> None:
    """A slow motion (its ``break`` awaited for a minute) is work: a newcomer does not take that slot."""

    async def main(clock: Clock) -> tuple[bool, float]:
        async with VPlusSimulator(clock, max_clients=1) as sim:
            worker = VPlusClient("127.0.0.1", sim.port, clock, timeout=120.0, retries=0)
            await worker.connect()
            move = asyncio.ensure_future(worker.execute_joined(codec.set_speed(1), *codec.move_rel_joints((170.0, 0, 0, 0, 0, 0))))
            await clock.sleep(40.0)
            newcomer = await served(clock, sim.port)
            acks = await move
            await worker.close()
            return newcomer, acks[-1].t_done

    newcomer, arrived = run_sim(main)
    assert not newcomer and arrived > 40.0  # the move outlasted reclaim_after (30 s); its client kept the slot


@pytest.mark.parametrize(
    ("data", "said"),
    [
        (b"x" * 200 + b"\r\n", b"closed: 4"),  # malformed lines, fast: closed once 4096 bytes came without a message
        (b"id1:fly_to_moon\r\n", b"closed: 4"),  # an unknown skill is no work either
    ],
)
def test_a_client_sending_bytes_but_no_message_is_closed(run_sim: Run, data: bytes, said: bytes) -> None:
    async def main(clock: Clock) -> list[bytes]:
        async with VPlusSimulator(clock) as sim:
            heard: list[bytes] = []
            await trickle(clock, sim.port, data, 0.01, 1000, heard)
            return heard

    heard = run_sim(main)
    assert len(heard) == 1 and heard[0].startswith(said) and heard[0].endswith(b" bytes without a message\r\n")

