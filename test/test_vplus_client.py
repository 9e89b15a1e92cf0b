"""The client's handling of whatever bytes a server sends, without a network: random, truncated, misordered."""
from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable, Coroutine
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from node_transport.clock import Clock, real_clock, run_with_clock, simulated_clock
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import (
    CommandTimeout,
    ConnectionLost,
    ControllerLink,
    Exchange,
    ProtocolError,
    Turn,
    VPlusClient,
)
from robot_bridges.vplus.codec import Message, set_speed

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]


class FakeTransport(asyncio.Transport):
    """Records writes; closing it tells the protocol, as a socket transport would."""

    def __init__(self, link: ControllerLink) -> None:
        super().__init__()
        self.link = link
        self.written: list[bytes] = []
        self.closing = False

    def write(self, data: bytes) -> None:  # type: ignore[override]
        self.written.append(bytes(data))

    def is_closing(self) -> bool:
        return self.closing

    def close(self) -> None:
        if not self.closing:
            self.closing = True
            asyncio.get_running_loop().call_soon(self.link.connection_lost, None)


def attach(client: VPlusClient) -> tuple[ControllerLink, FakeTransport]:
    link = ControllerLink(client)
    transport = FakeTransport(link)
    link.connection_made(transport)
    client._link = link
    return link, transport


async def started(clock: Clock, command: codec.Command, timeout: float = 10.0) -> tuple[VPlusClient, ControllerLink, FakeTransport, asyncio.Future[list[codec.Ack]]]:
    """A client on a fake link with one ``execute`` under way (its message written)."""
    client = VPlusClient("sim", 1, clock, timeout=timeout)
    link, transport = attach(client)
    call = asyncio.ensure_future(client.execute(command))
    await clock.sleep(0)
    return client, link, transport, call


def ids(transport: FakeTransport) -> list[str]:
    return [line.split(b":")[0].decode() for chunk in transport.written for line in chunk.split(b"\r\n") if line]


def ack_for(msg_id: str) -> bytes:
    return codec.Ack(msg_id, 1.0, 1.5, (480, 0, 710, 0, 180, 0)).encode()


def test_acks_out_of_order_and_cut_anywhere_complete_a_joined_call(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        client = VPlusClient("sim", 1, clock)
        link, transport = attach(client)
        call = asyncio.ensure_future(client.execute_joined(codec.set_speed(10), *codec.move_tool_z(1.0)))
        await clock.sleep(0)
        sent = ids(transport)
        stream = ack_for(sent[2]) + ack_for(sent[0]) + ack_for(sent[1])
        for i in range(len(stream)):
            link.data_received(stream[i : i + 1])
        acks = await call
        assert [a.id for a in acks] == sent  # returned in message order, whatever the arrival order

    run_sim(main)


junk = st.binary(max_size=120)


@settings(max_examples=150)
@given(st.lists(junk, max_size=6))
def test_random_bytes_from_the_server_end_a_call_with_a_client_error_never_a_crash(chunks: list[bytes]) -> None:
    async def main(clock: Clock) -> None:
        client, link, transport, call = await started(clock, codec.ENABLE_AIR, 1.0)
        for chunk in chunks:
            link.data_received(chunk)  # must not raise, whatever arrives
        try:
            await call
        except (ProtocolError, ConnectionLost, CommandTimeout) as error:
            assert "V+ server sim:1" in str(error)
        else:
            pytest.fail("random bytes cannot hold an ack for an id they never saw")

    run_with_clock(main, simulated_clock())


@given(st.integers(min_value=1, max_value=60))
def test_a_truncated_ack_followed_by_close_is_a_lost_connection(cut: int) -> None:
    async def main(clock: Clock) -> None:
        client, link, transport, call = await started(clock, codec.ENABLE_AIR, 5.0)
        link.data_received(ack_for(ids(transport)[0])[:cut])
        link.eof_received()
        with pytest.raises(ConnectionLost) as caught:
            await call
        assert [m.command for m in caught.value.exchange.unknown] == [codec.ENABLE_AIR]

    run_with_clock(main, simulated_clock())


def test_an_endless_line_from_the_server_drops_the_link(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        client, link, transport, call = await started(clock, codec.ENABLE_AIR)
        link.data_received(b"9" * 400)
        with pytest.raises(ConnectionLost, match="stream out of step"):
            await call
        assert not client.connected

    run_sim(main)


def test_a_status_other_than_done_is_a_protocol_error(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        client, link, transport, call = await started(clock, codec.ENABLE_AIR)
        msg_id = ids(transport)[0]
        link.data_received(f"{msg_id}:failed:1.000,1.000:0.000,0.000,0.000,0.000,0.000,0.000\r\n".encode())
        with pytest.raises(ProtocolError, match="status 'failed'"):
            await call

    run_sim(main)


def test_cancelling_a_call_keeps_its_late_acks_harmless(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        client, link, transport, call = await started(clock, codec.ENABLE_AIR)
        call.cancel()
        with pytest.raises(asyncio.CancelledError):
            await call
        first = ids(transport)[0]
        second = asyncio.ensure_future(client.execute(codec.DISABLE_AIR))
        await clock.sleep(0)
        link.data_received(ack_for(first) + ack_for(ids(transport)[1]))
        (ack,) = await second
        assert ack.id == ids(transport)[1] and [m.id for m, _ in client.late_acks] == [first]

    run_sim(main)


def test_bad_arguments_are_refused(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        with pytest.raises(ValueError):
            VPlusClient("sim", 1, clock, timeout=0)
        with pytest.raises(ValueError):
            VPlusClient("sim", 1, clock, retries=-1)
        client = VPlusClient("sim", 1, clock)
        attach(client)
        with pytest.raises(TypeError, match="expected a Command"):
            await client.execute(["break"])  # type: ignore[list-item]
        assert await client.execute() == []

    run_sim(main)



def test_ids_are_unique_within_a_joined_batch_even_when_the_generator_repeats() -> None:
    """32-bit random ids collide in large joined batches (birthday bound); the client must not send one id twice."""
    repeating = itertools.cycle(["0000000a", "0000000a", "0000000b", "0000000a", "0000000c"])
    client = VPlusClient("127.0.0.1", 1234, real_clock(), make_id=lambda: next(repeating))
    messages = client._messages([set_speed(10), set_speed(20), set_speed(30)])
    assert [m.id for m in messages] == ["0000000a", "0000000b", "0000000c"]


def test_a_failure_report_of_a_huge_batch_stays_short() -> None:
    messages = tuple(Message(f"{i:08x}", set_speed(50)) for i in range(5000))
    text = str(Exchange(unknown=messages))
    assert "5000 messages: 00000000:set_speed:50 ... 00001387:set_speed:50" in text and len(text) < 300


def test_an_ack_in_the_same_loop_pass_as_its_deadline_completes_the_call(run_sim: Run) -> None:
    """The ack and the watchdog due together: the call succeeds, nothing is raised onto the loop,
    and the watchdog still watches the calls behind it."""

    async def main(clock: Clock) -> list[dict[str, Any]]:
        raised: list[dict[str, Any]] = []
        asyncio.get_running_loop().set_exception_handler(lambda loop, context: raised.append(context))
        client, link, transport, call = await started(clock, codec.ENABLE_AIR, timeout=2.0)
        await clock.sleep(0.5)
        behind = asyncio.ensure_future(client.execute(codec.DISABLE_AIR))  # due at 2.5 s, never acked
        await clock.sleep(0)
        msg_id = ids(transport)[0]
        clock.call_later(1.5 - 1e-10, link.data_received, ack_for(msg_id))  # lands in the watchdog's pass
        (ack,) = await call
        assert ack.id == msg_id
        with pytest.raises(CommandTimeout, match="no ack within 2 s"):
            await clock.wait_for(behind, 10.0)
        return raised

    assert run_sim(main) == []


def test_calls_take_turns_in_order_and_a_cancelled_waiter_never_keeps_the_turn() -> None:
    """The client's turn (one call at a time, in arrival order) as asyncio.Lock promised it:
    waiters go in order; one cancelled while waiting, or just after being handed the turn, passes
    it on; the turn is free once everybody has left."""
    async def scenario() -> list[str]:
        turn = Turn()
        order: list[str] = []
        assert turn.take_now() and not turn.take_now()

        async def call(name: str) -> None:
            await turn.take()
            order.append(name)
            await asyncio.sleep(0)
            turn.leave()

        waiting = asyncio.create_task(call("cancelled while waiting"))
        handed = asyncio.create_task(call("handed the turn, then cancelled"))
        second, third = asyncio.create_task(call("second")), asyncio.create_task(call("third"))
        await asyncio.sleep(0)
        waiting.cancel()
        await asyncio.sleep(0)
        turn.leave()  # hands the turn to the first still waiting...
        handed.cancel()  # ...which is cancelled before it runs
        results = await asyncio.gather(waiting, handed, second, third, return_exceptions=True)
        assert [type(r) for r in results] == [asyncio.CancelledError, asyncio.CancelledError, type(None), type(None)]
        assert not turn.busy and not turn.waiters and turn.take_now()
        return order

    assert asyncio.run(scenario()) == ["second", "third"]
