"""A V+ server that refuses a client says why, and the client's error carries those words.

The simulator (like an AdeptServer with every slot taken) accepts the connection, writes one
line -- ``refused: N clients already connected; ...`` -- and closes it.  Whenever that line
arrives -- before the client has sent anything, while its first message waits for an ack, or
before ``connect`` has even returned -- the error the caller sees quotes it: it is the server
speaking, not a malformed ack and not a bare "not connected".
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from typing import Any

import pytest

from node_transport.clock import Clock
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import ConnectError, VPlusClient, VPlusError
from robot_bridges.vplus.simulator import VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
REFUSAL = "the server said: refused: 1 clients already connected; idle ones are closed after 60 s"


def test_a_refusal_arriving_while_the_first_message_waits_for_its_ack_is_reported_as_said(run_sim: Run) -> None:
    """A server that reads the client's first message, then refuses: the refusal overtakes the ack."""

    async def main(clock: Clock) -> str:
        async def refuse(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            await reader.readline()
            writer.write(b"refused: 1 clients already connected; idle ones are closed after 60 s\r\n")
            await writer.drain()
            writer.close()

        server = await asyncio.start_server(refuse, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        client = VPlusClient("127.0.0.1", port, clock, timeout=5.0, retries=0)
        try:
            await client.connect()
            with pytest.raises(VPlusError) as caught:
                await client.execute(codec.BREAK)
            return str(caught.value)
        finally:
            await client.close()
            server.close()

    message = run_sim(main)
    assert REFUSAL in message and "malformed ack" not in message


def test_the_simulator_with_every_slot_taken_says_so_whenever_its_refusal_arrives(run_sim: Run) -> None:
    async def main(clock: Clock) -> str:
        async with VPlusSimulator(clock, max_clients=1) as sim:
            _, holder = await asyncio.open_connection("127.0.0.1", sim.port)
            await clock.sleep(0.01)
            client = VPlusClient("127.0.0.1", sim.port, clock, timeout=5.0, retries=0)
            try:
                await client.connect()
                with pytest.raises(VPlusError) as caught:
                    await client.execute(codec.BREAK)
                return str(caught.value)
            except ConnectError as error:  # the refusal came before connect returned: said there
                return str(error)
            finally:
                await client.close()
                holder.close()

    message = run_sim(main)
    assert REFUSAL in message and "malformed ack" not in message


def test_a_line_that_is_no_ack_of_a_message_sent_does_not_fail_the_waiting_call(run_sim: Run) -> None:
    """A garbled ack names a message sent (its id): a protocol fault.  Anything else is the server
    talking; the call waits on for its own ack."""

    async def main(clock: Clock) -> tuple[str, str]:
        async with VPlusSimulator(clock) as sim:
            client = VPlusClient("127.0.0.1", sim.port, clock, timeout=5.0)
            await client.connect()
            try:
                call = asyncio.ensure_future(client.execute(codec.ENABLE_AIR))
                await asyncio.sleep(0)
                client._on_line(b"notice: operator at the pendant")  # as if the server had said it mid-call
                (ack,) = await call
                return ack.status, client.server_said
            finally:
                await client.close()

    status, said = run_sim(main)
    assert status == "done" and said == "notice: operator at the pendant"
