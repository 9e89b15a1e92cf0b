"""Who speaks for a controller: its address, the port it speaks from, and an IPOC that steps as RSI's does.

RSI itself authenticates nothing, so the external system must not take any datagram from the
controller's IP for the controller: another program on that host (or anything that can put the
host's address on a datagram) could otherwise answer for it -- one forged ``<Rob>`` with
``Delay`` 50 made the loop play fifty held cycles into its set point; the forger got the replies
meant for the robot; a flood of them crowded the real packets out until RSI stopped on its
timeout.  So:

* **addresses** are compared as IPs, each name resolved once at start (:func:`resolve_ipv4`; a
  name that does not resolve is an error naming the option, never a silent mismatch);
* **the port**: a link with a configured port accepts only that one; otherwise the port of the
  first valid packet from the controller's IP is *pinned* and datagrams from any other port of
  that IP are ignored unread (counted and reported as coming from that other sender, never
  blamed on the robot).  A sender already there before the controller's first packet would be
  pinned instead: where that matters, configure the port;
* **the IPOC** must follow the last accepted packet's as a controller's does (:class:`PeerGate`):
  never back, a repeat only as ROS-Industrial's simulator repeats a packet after a timeout (with
  ``Delay`` one higher), forward by whole steps (the step configured, or learned from the first
  two packets without a late cycle between them), at most :data:`MAX_GAP` cycles; and with
  ``Delay`` configured, the count of late cycles never goes back and grows by at least the cycles
  whose packets never came (RSI counts every cycle without a reply) and at most by the cycles
  that passed.  Without ``Delay`` the step is the smallest IPOC difference seen and only order and
  gap are checked.  A packet that breaks this is refused, counted and
  reported; it changes nothing.
"""
from __future__ import annotations

import ipaddress
import socket

#: Cycles an IPOC may jump ahead of the last accepted packet.  RSI stops long before on its
#: Timeout (late packets in a row); the set point model plays at most as many held cycles.
MAX_GAP = 1000


def resolve_ipv4(name: str, option: str) -> str:
    """The IPv4 address ``name`` stands for (itself when it is one; ``""``, as for ``bind``, any
    address); ``ValueError`` naming ``option`` when it stands for none."""
    if not name:
        return "0.0.0.0"
    try:
        return str(ipaddress.IPv4Address(name))
    except ValueError:
        pass
    try:
        found = socket.getaddrinfo(name, None, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as error:
        reason = error.strerror if isinstance(error, socket.gaierror) else str(error)
        raise ValueError(f"{option}: the name {name!r} does not resolve to an IPv4 address ({reason})") from None
    return str(found[0][4][0])


class PeerGate:
    """One controller's gate: the port its packets must come from, and the last IPOC and Delay accepted."""

    def __init__(self, port: int | None, ipoc_step: int | None) -> None:
        self.port = port
        self.configured = port is not None
        self.step = ipoc_step
        self._certain = ipoc_step is not None  # configured, or learned from two packets in consecutive cycles
        self.ipoc: int | None = None
        self.delay: int | None = None

    @property
    def pinned(self) -> bool:
        return self.port is not None

    def admits(self, port: int) -> bool:
        """Whether a datagram from this port (of the controller's IP) may be the controller's."""
        return self.port is None or port == self.port

    def check(self, ipoc: int, delay: int | None) -> str | None:
        """None when a packet with this IPOC and Delay can follow the last accepted one; else why not."""
        if self.ipoc is None:
            return None
        diff = ipoc - self.ipoc
        late = None if delay is None or self.delay is None else delay - self.delay
        if late is not None and late < 0:
            return f"Delay went back from {self.delay} to {delay}"
        if diff < 0:
            return f"IPOC {ipoc} is older than the last packet's {self.ipoc}"
        if diff == 0:
            if late == 1:
                return None  # a packet sent again after a late reply, as ROS-Industrial's simulator does
            return f"IPOC {ipoc} repeats the last packet's without a late cycle between (a duplicate)"
        if self.step is None:
            return None  # not learned yet: the first packets without a late cycle between teach it
        if self._certain and diff % self.step:
            return f"IPOC {ipoc} is {diff} after the last packet's {self.ipoc}, not a whole number of {self.step}-steps"
        cycles = diff // self.step
        if cycles > MAX_GAP:
            return f"IPOC {ipoc} is {cycles} cycles after the last packet's {self.ipoc} (at most {MAX_GAP})"
        if late is None or not self._certain:
            return None
        if late > cycles:
            return f"Delay grew by {late} over {cycles} cycle(s) (from {self.delay} to {delay})"
        if late < cycles - 1:
            return f"IPOC skipped {cycles - 1} cycle(s) but Delay counts {late} late"
        return None

    def accept(self, ipoc: int, delay: int | None, port: int) -> bool:
        """Take the packet as the controller's; True when this pinned the port."""
        if self.ipoc is not None and ipoc > self.ipoc and not self._certain:
            diff = ipoc - self.ipoc
            if delay is not None and delay == self.delay:
                self.step, self._certain = diff, True  # nothing late between: consecutive cycles
            elif delay is None:
                self.step = diff if self.step is None else min(self.step, diff)  # without Delay: the smallest seen
        self.ipoc, self.delay = ipoc, delay
        if self.port is None:
            self.port = port
            return True
        return False

    def where(self) -> str:
        """How the port came to be the controller's, for messages."""
        return "configured" if self.configured else "where its first packet came from"
