"""Only the controller is the controller: its address, the port it speaks from, an IPOC that steps as RSI's.

A second sender on the controller's host -- another port of the same IP -- is played by the
simulator (:class:`~robot_bridges.kuka_rsi.spoofer.Flood`): forged copies of the controller's packet
with ``Delay`` 50 higher, garbage, at ten times the cycle rate.  The deterministic assertions run
against the accelerated (lockstep) simulator, whose verdict on late replies depends on what the
loop answered, not on how busy the machine is; the real-time run asserts only what a loaded
machine cannot change (the run finishes, nothing reaches the flooder, every datagram is counted).
"""
from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from test_rsi_loop import GRACE, READY, WAIT, Rig

from core_functions.primitives import MoveJoints
from core_functions.robots import KUKA_KR
from node_transport.clock import Clock, real_clock, run_with_clock
from robot_bridges.backend import BackendOptions
from robot_bridges.kuka_rsi.backend import KukaRsiBackend, create
from robot_bridges.kuka_rsi.codec import PacketCodec
from robot_bridges.kuka_rsi.config import default_config
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink, RsiLoop
from robot_bridges.kuka_rsi.interface import RsiInterface
from robot_bridges.kuka_rsi.peer import MAX_GAP, PeerGate
from robot_bridges.kuka_rsi.pipe import FramedPipe
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_controller import SimulatorSpec
from robot_bridges.kuka_rsi.sim_network import SimulatorThread
from robot_bridges.kuka_rsi.slots import layout, robot_block_size
from robot_bridges.kuka_rsi.spoofer import Flood

CONFIG = default_config()
ROB = PacketCodec.rob(CONFIG)
TARGETS = (np.radians([60, -60, 100, 30, 60, 90]), np.radians(READY))


@pytest.fixture
def rig() -> Iterator[Callable[..., Rig]]:
    rigs: list[Rig] = []

    def make(**kwargs: Any) -> Rig:
        r = Rig(**kwargs)
        rigs.append(r)
        return r

    yield make
    for r in rigs:
        r.close()


def _packet(ipoc: int, delay: int = 0) -> bytes:
    values = list(ROB.defaults)
    values[ROB.index["Delay.D"]] = delay
    return ROB.encode(values, ipoc)


# ------------------------------------------------------------------------------ the IPOC gate
def test_an_ipoc_must_follow_the_last_one_as_a_controllers_does() -> None:
    gate = PeerGate(None, None)
    assert gate.check(1000, 0) is None and gate.accept(1000, 0, 5000)  # the first packet pins port 5000
    assert not gate.admits(5001) and gate.admits(5000)
    assert gate.check(1004, 0) is None
    gate.accept(1004, 0, 5000)  # consecutive cycles, nothing late between: the step is 4
    assert gate.step == 4
    refusals = {
        (1000, 0): "older than the last packet's 1004",
        (1004, 0): "a duplicate",
        (1006, 0): "not a whole number of 4-steps",
        (1008, 50): "Delay grew by 50 over 1 cycle",  # the forged packet of the hardening issue
        (1016, 0): "IPOC skipped 2 cycle(s) but Delay counts 0 late",
        (1004 + 4 * (MAX_GAP + 1), MAX_GAP + 1): f"at most {MAX_GAP}",
        (1008, -1): "Delay went back",
    }
    for (ipoc, delay), words in refusals.items():
        problem = gate.check(ipoc, delay)
        assert problem is not None and words in problem, (ipoc, delay, problem)
    assert gate.check(1008, 0) is None and gate.check(1012, 1) is None and gate.check(1012, 2) is None  # a late reply; a lost packet
    assert gate.check(1004, 1) is None  # sent again after a late reply, as ROS-I's simulator does


def test_without_delay_only_order_and_gap_are_checked() -> None:
    gate = PeerGate(7000, None)
    assert not gate.admits(7001)  # a configured port, before any packet
    gate.accept(10, None, 7000)
    gate.accept(12, None, 7000)
    assert gate.step == 2 and gate.check(15, None) is None and gate.check(11, None) is not None


# ------------------------------------------------------------------ the loop's door, unit level
def test_datagrams_from_the_controllers_ip_but_another_port_are_ignored_unread() -> None:
    ours, theirs = FramedPipe.pair()
    loop = RsiLoop([RobotLink("kr0", "127.0.0.1")], LoopSettings(port=0), layout(memoryview(bytearray(robot_block_size())), 1), FramedPipe(theirs, blocking_send=False))
    try:
        robot, other = ("127.0.0.1", 5000), ("127.0.0.1", 5001)
        kept = loop._packets([(_packet(100), robot), (_packet(104, 50), other), (b"<garbage", other), (_packet(104), robot)])
        assert [(c.link.name, ipoc, addr) for c, ipoc, addr in kept] == [("kr0", 104, robot)]
        channel = loop.channels[0]
        assert (loop.stats.spoofed, channel.spoofed, loop.stats.spoofed_from) == (2, 2, {"127.0.0.1:5001": 2})
        assert channel.rejected == 0 and channel.rx[ROB.index["Delay.D"]] == 0  # nothing of the forger's was read
        assert loop._packets([(_packet(100), robot)]) == [] and channel.refused == {"ipoc": 1}  # back in time: refused
        summary = loop.summary()
        assert "kr0 (127.0.0.1:5000)" in summary and "1 refused (1 x ipoc)" in summary
        assert "ignored 2 datagrams from a controller's address but another port, not the controller: 2 from 127.0.0.1:5001" in summary
    finally:
        loop.logger.close()
        ours.close()
        theirs.close()


# --------------------------------------------------------------------- against the simulator
def _moves(r: Rig, count: int) -> None:
    for k in range(count):
        ok, message, _ = r.done(r.iface.set_axial_pos(0, TARGETS[k % 2], 2.0, 10.0))
        assert ok, message


@pytest.mark.parametrize("content", ["packet", "mixed"])
def test_a_flood_from_another_port_of_the_controller_neither_aborts_nor_delays_a_correction(rig: Callable[..., Rig], content: str) -> None:
    """Ten datagrams per cycle from the controller's IP (forged packets with Delay + 50, or those and
    garbage by turns), half just before each packet and half just after it, during two moves."""
    # A reply is late only if the loop took over 5 s of wall time: what it answered decides, not the machine's load.
    r = rig(flood=Flood(10.0, content), reply_grace=5.0).start()  # type: ignore[arg-type]
    r.correcting()
    _moves(r, 2)
    flooder = r.sim.flooder
    assert flooder is not None
    stats, loop = r.sim.model.stats, r.iface.loop
    assert loop is not None
    assert stats.late_since_first_reply == 0 and r.sim.running  # no correction late, RSI never stopped
    assert loop.channels[0].catch_ups == 0 and loop.channels[0].motion.clamped == 0
    assert stats.flood_sent > 10 * 400 and stats.flood_replies == 0  # nothing meant for the robot went to the flooder
    source = f"{flooder.address[0]}:{flooder.address[1]}"
    r.sim.stop()  # the flood with it; then every datagram it sent is in the loop's count
    r.wait(lambda: loop.stats.spoofed == stats.flood_sent, "every flooded datagram counted")
    assert loop.stats.spoofed_from == {source: stats.flood_sent} and loop.stats.rejected == 0  # none blamed on the robot
    assert any(f"ignored a datagram from {source}: the address of robot kr0, but not its port" in w for w in r.iface.events.warnings)
    assert not any("rejected" in w for w in r.iface.events.warnings)
    r.iface.close()
    summary = r.iface.events.summary
    assert summary is not None and f"from a controller's address but another port, not the controller: {stats.flood_sent:,} from {source}" in summary
    assert r.iface.events.suspicious


def test_a_flood_in_real_time_is_counted_and_never_answered(rig: Callable[..., Rig]) -> None:
    """The same at the real 4 ms cycle: on a loaded machine a late packet can happen with or without a
    flood (bench/rsi_flood.py measures them); what must hold is the run, the count and the silence."""
    loop_for_clock = asyncio.new_event_loop()
    try:
        r = rig(flood=Flood(10.0), clock=real_clock().bind(loop_for_clock), settings=LoopSettings(port=0, silence_timeout=1.0)).start()
        r.correcting()
        _moves(r, 2)
        stats, loop = r.sim.model.stats, r.iface.loop
        assert loop is not None and r.sim.running and r.sim.stop_reason is None
        assert stats.flood_sent > 10 * 200 and stats.flood_replies == 0
        assert loop.stats.rejected == 0 and not r.iface.events.faults
        r.sim.stop()
        # A stalled machine may make the kernel drop datagrams from a full buffer: counted are those that came.
        r.wait(lambda: loop.stats.spoofed > stats.flood_sent // 2, "the flood counted")
        assert loop.stats.spoofed <= stats.flood_sent
        r.iface.close()
        assert r.iface.events.summary is not None and f"{loop.stats.spoofed:,} from {r.sim.flooder.address[0]}:" in r.iface.events.summary  # type: ignore[union-attr]
    finally:
        loop_for_clock.close()


def test_the_end_of_run_summary_names_the_flooder_not_the_robot(run_sim: Callable[..., Any], caplog: pytest.LogCaptureFixture) -> None:
    context = RsiContext(start_deg=READY)
    spec = SimulatorSpec(runner="thread", accelerated=True, context=context, flood=Flood(10.0, "garbage"))

    async def main(clock: Clock) -> KukaRsiBackend:
        backend = KukaRsiBackend(listen=("127.0.0.1", 0), simulator=spec, runner="thread", settings=LoopSettings(silence_timeout=1.0))
        await backend.start()
        try:
            await backend.execute("arm", MoveJoints(tuple(TARGETS[0])))
        finally:
            await backend.close()
        return backend

    with caplog.at_level(logging.INFO, logger="robot_bridges.kuka_rsi.backend"):
        backend = run_sim(main)
    assert backend.summary is not None
    assert "kuka (127.0.0.1:" in backend.summary and "refused" not in backend.summary
    assert "from a controller's address but another port, not the controller" in backend.summary
    warned = [rec for rec in caplog.records if rec.levelno == logging.WARNING and backend.summary in rec.getMessage()]
    assert warned, "the summary is a warning when someone else spoke"
    assert any("the controller speaks from 127.0.0.1:" in rec.getMessage() for rec in caplog.records)


# ------------------------------------------------------------------------------ names
def test_a_controller_given_by_name_is_answered_by_its_ip() -> None:
    iface = RsiInterface([RobotLink("kr0", "localhost")], LoopSettings(host="localhost", port=0), mode="thread")
    assert iface.links[0].host == "127.0.0.1" and iface.settings.host == "127.0.0.1"
    iface.start()
    sim = None
    try:
        address = iface.wait_ready(WAIT)
        sim = SimulatorThread(CONFIG, address, context=RsiContext(start_deg=READY), cycles=50, reply_grace=GRACE).start()
        assert sim.join(WAIT) and sim.model.stats.accepted == 50 and sim.model.stats.late == 0
    finally:
        if sim is not None:
            sim.stop()
        iface.close()


@pytest.mark.parametrize(
    ("options", "words"),
    [
        ({"rsi_listen": "controller.invalid:49152", "host": "127.0.0.1"}, "kuka-rsi: rsi_listen (--rsi-listen) 'controller.invalid:49152': the name 'controller.invalid' does not resolve"),
        ({"rsi_listen": "127.0.0.1:49152", "host": "controller.invalid"}, "kuka-rsi: host (--host) 'controller.invalid': the name 'controller.invalid' does not resolve"),
    ],
)
def test_a_name_that_does_not_resolve_is_a_one_line_error_naming_the_option(options: dict[str, str], words: str) -> None:
    async def make(clock: Clock) -> KukaRsiBackend:
        return await create(clock, BackendOptions(KUKA_KR, **options))  # type: ignore[arg-type]

    with pytest.raises(ValueError) as caught:
        run_with_clock(make, real_clock())
    assert words in str(caught.value) and "\n" not in str(caught.value)


def test_names_become_ips_for_a_real_controller() -> None:
    async def make(clock: Clock) -> KukaRsiBackend:
        return await create(clock, BackendOptions(KUKA_KR, rsi_listen="localhost:49152", host="localhost", port=6008))

    backend = run_with_clock(make, real_clock())
    assert (backend.link.host, backend.link.port, backend.settings.host) == ("127.0.0.1", 6008, "127.0.0.1")
    assert math.isfinite(backend.link.tcp_tolerance_mm)
