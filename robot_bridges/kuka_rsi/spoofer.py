"""A second sender on the controller's host: the spoofer and flooder the external system must ignore.

RSI matches nothing but what the external system checks, so the simulator can play the attack an
external system meets on a shared network: datagrams to the external system from the controller's
own IP but another port, at many times the cycle rate -- copies of the controller's packet with a
``Delay`` jumped ahead (one such packet once made the loop play fifty held cycles into its set
point), garbage, or both.  The flood starts once the external system has answered the
controller (it has locked on to it), keeps its own socket, and counts what it sent and every
reply that reached it (replies meant for the robot, if the external system were fooled).
"""
from __future__ import annotations

import random
import socket
from dataclasses import dataclass
from typing import Literal, Protocol

Content = Literal["packet", "garbage", "mixed"]
#: Datagrams one burst may send at most, however late the sender is (no catch-up storms).
MAX_BURST = 1000


@dataclass(frozen=True)
class Flood:
    """What the second sender sends: ``rate`` datagrams per RSI cycle from ``port`` of the controller's IP."""

    rate: float = 0.0  # datagrams per cycle (10: ten times the controller's own rate); 0: no flood
    content: Content = "packet"  # packet: the controller's packet, Delay + delay_jump; garbage; mixed: both by turns
    delay_jump: int = 50
    port: int = 0  # 0: any free port

    def __post_init__(self) -> None:
        if not (0.0 <= self.rate <= MAX_BURST) or self.content not in ("packet", "garbage", "mixed") or self.delay_jump < 0:
            raise ValueError(f"a flood is 0..{MAX_BURST} datagrams per cycle of packet, garbage or mixed, with a Delay jump >= 0: {self}")

    @staticmethod
    def parse(text: str) -> Flood:
        """``RATE`` or ``RATE:CONTENT`` (``10:packet``, ``10:garbage``, ``10:mixed``)."""
        rate, _, content = text.partition(":")
        try:
            value = float(rate)
        except ValueError:
            raise ValueError(f"a flood is RATE[:packet|garbage|mixed] (datagrams per cycle), got {text!r}") from None
        return Flood(value, content or "packet")  # type: ignore[arg-type]


def garbage_datagram(rng: random.Random) -> bytes:
    """A datagram no controller sends: truncated, random bytes, a DTD with an entity, a NaN IPOC."""
    choices = (
        b"<Rob Type=\"KUKA\"><RIst X=\"1\"",
        bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 64))),
        b"<?xml version=\"1.0\"?><!DOCTYPE x [<!ENTITY a \"b\">]><Rob/>",
        b"<Rob Type=\"KUKA\"><IPOC>nan</IPOC></Rob>",
    )
    return rng.choice(choices)


class FloodCounts(Protocol):
    """The simulated controller's counts the flood reads and adds to (simulator.py's SimStats)."""

    accepted: int  # replies of the external system the controller took: none yet, no flood
    flood_sent: int
    flood_replies: int


class ForgingController(Protocol):
    """The simulated controller seen from the flood: its counts and its packet to forge (simulator.py's KrcModel)."""

    @property
    def stats(self) -> FloodCounts: ...

    def forged_packet(self, delay_jump: int, cycles_ahead: int) -> bytes: ...


class Flooder:
    """The flood's socket on the controller's host, and what it sent and got back."""

    def __init__(self, flood: Flood, host: str, peer: tuple[str, int], model: ForgingController, seed: int) -> None:
        self.flood = flood
        self.peer = peer
        self.model = model
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, flood.port))
        self.sock.setblocking(False)
        self.address: tuple[str, int] = self.sock.getsockname()
        self.rng = random.Random(seed ^ 0x5F00F)
        self._credit = 0.0
        self._count = 0
        self.next_at = float("inf")  # run time of the next datagram when paced on a clock
        self._interval = float("inf")

    def pace(self, now: float, cycle: float) -> None:
        """Spread the flood evenly in run time from ``now`` on: ``rate`` datagrams every ``cycle`` s."""
        if self.flood.rate > 0:
            self._interval = cycle / self.flood.rate
            self.next_at = now + self._interval

    def fire(self, now: float) -> None:
        """Send the datagrams due by run time ``now`` (a sender woken late sends at most a burst, then goes on from now)."""
        count = 0
        while self.next_at <= now and count < MAX_BURST:
            count += 1
            self.next_at += self._interval
        if self.next_at <= now:
            self.next_at = now + self._interval
        if count:
            self.send(count)

    def due(self, cycles: float = 1.0) -> int:
        """How many datagrams ``cycles`` cycles of flooding come to (fractions carried over)."""
        self._credit = min(float(MAX_BURST), self._credit + self.flood.rate * cycles)
        n = int(self._credit)
        self._credit -= n
        return n

    def send(self, count: int) -> None:
        """Send ``count`` datagrams made from the controller's current packet; read any replies.

        Nothing before the external system has answered the controller once: it must have had the
        chance to lock on to the controller's port (a sender there first would be taken for it).
        """
        model, stats = self.model, self.model.stats
        if not stats.accepted:
            return
        for _ in range(min(count, MAX_BURST)):
            self._count += 1
            forged = self.flood.content == "packet" or (self.flood.content == "mixed" and self._count % 2)
            data = model.forged_packet(self.flood.delay_jump, self._count % 2) if forged else garbage_datagram(self.rng)
            try:
                self.sock.sendto(data, self.peer)
                stats.flood_sent += 1
            except (BlockingIOError, ConnectionRefusedError):
                pass  # the sender's own buffer is full, or the peer is gone: a flood drops what it cannot send
        self.read_replies()

    def read_replies(self) -> None:
        while True:
            try:
                self.sock.recv(65536)
            except (BlockingIOError, ConnectionRefusedError):
                return
            self.model.stats.flood_replies += 1

    def close(self) -> None:
        self.sock.close()
