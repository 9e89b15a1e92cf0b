"""What a ROS 2 client that is neither Python nor rmw (ros2-client on RustDDS) relies on, byte by byte.

ros2-client's ``ServiceMapping::Cyclone`` writes a request as rmw_cyclonedds_cpp does: the 8 low
bytes of its request writer's GUID and the sequence number (as the RTPS high ``int32`` then low
``uint32``), then the request; it matches a reply by those 16 bytes, so the server must echo them
verbatim.  It puts no ``clientid=`` in its endpoints' user data.  These tests play such a client
with raw CDR on plain Cyclone endpoints: loopback, a domain of its own (dds_domain.py), every wait bounded.
"""
from __future__ import annotations

import os
import struct
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from dds_domain import domain_env

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport import dds_graph
from node_transport.dds import DdsTransport
from node_transport.msgs import Trigger, TriggerResponse
from node_transport.port import poll_until

BOUND = 10.0  # seconds any one condition may take on a loaded machine
XCDR1_LE = b"\x00\x01"  # the encapsulation kind RustDDS and rmw write: plain CDR, little endian


@pytest.fixture(scope="module")
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:  # a domain no other test uses meanwhile (dds_domain.py)
        yield claimed


def take_raw(reader: Any) -> list[bytes]:
    """Serialized samples as they came off the wire (encapsulation header first)."""
    # optional: cyclonedds (pip extra 'dds'); its C layer, to take the raw CDR
    from cyclonedds._clayer import ddspy_take
    from cyclonedds.core import InstanceState, SampleState, ViewState

    taken = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, 16)
    return [bytes(data) for data, info in taken if info.valid_data]


def cdr_string(text: str) -> bytes:
    data = text.encode() + b"\0"
    return struct.pack("<I", len(data)) + data


def test_a_client_without_clientid_gets_its_header_echoed_even_when_its_reply_reader_matches_late(env: dict[str, str]) -> None:
    """The request header comes back byte for byte (a GUID half with its top bit set, a sequence
    number with both RTPS halves non-zero), followed by the Trigger response in plain CDR; and the
    reply reader, created only after the server got the request (as a peer whose discovery is
    slower than its request), still gets the answer: the server waits for a reply reader of the
    caller's participant instead of writing into the void."""
    async def main(clock: Clock) -> tuple[list[bytes], list[str]]:
        # optional: cyclonedds (pip extra 'dds'), a plain DDS peer
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader

        server, peer = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        calls: list[str] = []
        try:
            async def pause(_request: Any) -> TriggerResponse:
                calls.append("pause")
                return TriggerResponse(True, "paused")

            server.create_node("execution_engine").create_service(Trigger, "execution_engine/pause", pause)
            request_type, reply_type = peer.registry.wire_service("std_srvs/srv/Trigger")
            qos = dds_graph.dds_qos(dds_graph.SERVICES)  # no user data, as RustDDS
            writer = DataWriter(peer.participant, peer.topic("rq/execution_engine/pauseRequest", request_type), qos=qos)
            assert await poll_until(clock, lambda: bool(writer.get_matched_subscriptions()), BOUND, 0.01)
            from cyclonedds._clayer import ddspy_write  # optional: cyclonedds (pip extra 'dds'); raw CDR out

            header = bytes([0x01, 0x0F, 0xA2, 0x9C, 0x11, 0x22, 0x80, 0x83]) + struct.pack("<iI", 1, 2)
            assert ddspy_write(writer._ref, XCDR1_LE + b"\x00\x00" + header + b"\x00\x00\x00\x00") >= 0
            assert await poll_until(clock, lambda: calls == ["pause"], BOUND, 0.01)
            reader = DataReader(peer.participant, peer.topic("rr/execution_engine/pauseReply", reply_type), qos=qos)
            replies: list[bytes] = []
            assert await poll_until(clock, lambda: bool(replies.extend(take_raw(reader)) or replies), BOUND, 0.01), "no reply"
            return [r for r in replies], calls
        finally:
            await server.shutdown()
            await peer.shutdown()

    replies, calls = run_with_clock(main, real_clock())
    assert calls == ["pause"]
    assert len(replies) == 1
    reply = replies[0]
    header = bytes([0x01, 0x0F, 0xA2, 0x9C, 0x11, 0x22, 0x80, 0x83]) + struct.pack("<iI", 1, 2)
    assert reply[:2] == XCDR1_LE
    # header echoed; success (bool) then three bytes of padding to the string's 4-byte length
    assert reply[4:].startswith(header + b"\x01\x00\x00\x00" + cdr_string("paused"))


CHURN = """
import asyncio, sys
from node_transport.clock import real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import String
from node_transport.qos import COMMANDS

async def main(clock):
    transport = DdsTransport(clock)
    talker = transport.create_node("talker")
    watcher = talker.create_subscription(String, "chatter", lambda _m: None, COMMANDS)
    chatter = talker.create_publisher(String, "chatter", COMMANDS)  # heard by its own node and the peer's
    print("ready", flush=True)
    for index in range(int(sys.argv[1])):
        node = transport.create_node(f"n{index}")  # each change is a ros_discovery_info update
        node.create_publisher(String, "chatter", COMMANDS)
        for _ in range(20):
            chatter.publish(String(str(index)))
        await asyncio.sleep(0)
        watcher.publisher_nodes()  # and reads the peers' updates
        node.destroy()
        await asyncio.sleep(0)
    await transport.shutdown()
    print("done", flush=True)

run_with_clock(main, real_clock())
"""


def test_processes_updating_the_graph_at_once_never_hang(env: dict[str, str]) -> None:
    """Every process writes ros_discovery_info and reads its peers' updates, and a node hears its
    own topic and its peer's.  cyclonedds writes holding the GIL: had a reader a listener, a local
    write waiting for that listener while a peer's sample holds it (waiting for the GIL) would hang
    the process for good.  And the list of
    matched writers grows while it is read (cyclonedds-python's own getter raised IndexError then).
    Two processes churning their graphs at once both finish."""
    root = Path(__file__).resolve().parent.parent
    children = [
        subprocess.Popen([sys.executable, "-c", CHURN, "150"], cwd=root, env={**os.environ, **env, "PYTHONPATH": str(root)},
                         stdout=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    try:
        outputs = [child.communicate(timeout=60)[0] for child in children]
    finally:
        for child in children:
            child.kill()
            child.wait(timeout=BOUND)
    assert all(out.split() == ["ready", "done"] for out in outputs), outputs
