"""The simulated KR C4 on the network: its UDP socket, the two drivers that pace it, and the thread that runs one.

RSI's timing is what the bridge must keep up with, so the network side is where it is reproduced: a packet every
cycle on a fixed clock whether or not replies come, a reply on time only if it arrived (by the kernel's receive
stamp) before the next cycle, only datagrams from the external system's address counted, and the injected faults
of :class:`~.sim_faults.Faults` (jitter, lost packets, garbage, replies dropped).  :func:`run_lockstep`
(accelerated: the next packet goes out as soon as the reply is in or known missing; lateness is counted against
the simulated cycle, so 100,000 cycles run in seconds and deterministically) and :func:`run_realtime` (a fixed
clock from the injected :class:`~node_transport.clock.Clock`) drive a :class:`~.krc_model.KrcModel`;
:class:`SimulatorThread` runs one of them for tests and for an in-process bridge.
"""
from __future__ import annotations

import random
import select
import socket
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from node_transport.clock import Clock
from robot_bridges.kuka_rsi.config import RsiConfig, RsiRoles
from robot_bridges.kuka_rsi.krc_model import KrcModel, RsiContext, RsiStopped
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.spoofer import Flood, Flooder, garbage_datagram


@dataclass(frozen=True)
class Endpoint:
    host: str
    port: int

    @staticmethod
    def parse(text: str, default_port: int | None = None) -> Endpoint:
        host, sep, port = text.rpartition(":")
        if not sep:
            if default_port is None:
                raise ValueError(f"expected HOST:PORT, got {text!r}")
            return Endpoint(text, default_port)
        if not port.isdigit() or not 0 <= int(port) < 65536:
            raise ValueError(f"bad port in {text!r}")
        return Endpoint(host or "127.0.0.1", int(port))

    def __str__(self) -> str:
        return f"{self.host}:{self.port}"


def latency_summary(latencies_ns: Sequence[int]) -> dict[str, float]:
    """p50, p99, p99.9 and max of round trips, in microseconds."""
    if not latencies_ns:
        return {}
    values = np.sort(np.asarray(latencies_ns, dtype=np.float64)) / 1000.0
    pick = lambda q: float(values[min(len(values) - 1, int(q * len(values)))])  # noqa: E731
    return {"n": float(len(values)), "p50": pick(0.5), "p99": pick(0.99), "p99.9": pick(0.999), "max": float(values[-1])}


_SO_TIMESTAMPNS = 35  # Linux <asm-generic/socket.h>; not exported by the socket module
_TIMESPEC = struct.Struct("qq")


def _wall_ns() -> int:
    """CLOCK_REALTIME, the clock the kernel stamps received datagrams with (see :class:`_Link`).

    Only the on-time verdict of the real-time driver reads it, to compare with those stamps;
    the schedule itself runs on the injected :class:`Clock`.
    """
    return time.clock_gettime_ns(time.CLOCK_REALTIME)


class _Link:
    """The controller's socket: sends the model's packets (with injected loss and garbage) and
    reads datagrams with their arrival time.

    The arrival time is the kernel's receive stamp when the platform gives one, so a reply that
    came in time is on time even if the simulator itself was scheduled late to read it -- a real
    controller's RSI runs hard real time.  ``now_ns`` stamps sends (and arrivals without kernel
    stamps); round trips of accepted replies go to ``model.stats.latencies_ns``.
    """

    def __init__(self, sock: socket.socket, peer: tuple[str, int], model: KrcModel, faults: Faults, now_ns: Callable[[], int] | None, *, kernel_stamps: bool = False) -> None:
        self.sock, self.peer, self.model, self.faults = sock, peer, model, faults
        self.rng = random.Random(faults.seed)
        self.now_ns = now_ns
        self.sent_ns = 0
        self.kernel_stamps = False
        if kernel_stamps:
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.kernel_stamps = True
            except OSError:
                pass

    def send(self) -> bool:
        """Send this cycle's packet; False when it was 'lost'."""
        packet = self.model.packet()
        if self.faults.garbage and self.rng.random() < self.faults.garbage:
            self.model.stats.garbage_sent += 1
            self.sock.sendto(garbage_datagram(self.rng), self.peer)
        if self.faults.loss and self.rng.random() < self.faults.loss:
            self.model.stats.lost += 1
            return False
        if self.now_ns is not None:
            self.sent_ns = self.now_ns()
        self.sock.sendto(packet, self.peer)
        return True

    def read(self, timeout: float, buf: bytearray) -> tuple[bytes, int] | None:
        """Wait up to ``timeout`` wall seconds for a datagram from the peer: ``(data, arrival_ns)``,
        ``(b"", 0)`` for anything else that arrived, None when nothing did."""
        ready, _, _ = select.select([self.sock], [], [], max(0.0, timeout))
        if not ready:
            return None
        try:
            if self.kernel_stamps:
                n, ancillary, _, addr = self.sock.recvmsg_into([buf], socket.CMSG_SPACE(_TIMESPEC.size))
                arrived = next(
                    (
                        sec * 1_000_000_000 + nsec
                        for level, kind, data in ancillary
                        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size
                        for sec, nsec in [_TIMESPEC.unpack_from(data)]
                    ),
                    0,
                )
            else:
                n, addr = self.sock.recvfrom_into(buf)
                arrived = 0
        except ConnectionRefusedError:
            return (b"", 0)  # ICMP: nobody listens at the external system's address (yet)
        if not arrived and self.now_ns is not None:
            arrived = self.now_ns()
        if addr[0] != self.peer[0] or addr[1] != self.peer[1]:
            self.model.stats.foreign += 1
            return (b"", 0)
        return bytes(buf[:n]), arrived

    def offer(self, data: bytes, arrived: int) -> bool:
        drop = bool(self.faults.drop) and self.rng.random() < self.faults.drop
        accepted = self.model.offer(data, drop)
        if accepted and self.now_ns is not None:
            self.model.stats.latencies_ns.append(arrived - self.sent_ns)
        return accepted


def run_lockstep(
    sock: socket.socket,
    peer: tuple[str, int],
    model: KrcModel,
    *,
    cycles: int | None = None,
    faults: Faults = Faults(),
    reply_grace: float = 0.25,
    stop: threading.Event | None = None,
    now_ns: Callable[[], int] | None = None,
    flooder: Flooder | None = None,
) -> RsiStopped | None:
    """Accelerated mode: each packet goes out as soon as the previous cycle's fate is decided.

    A cycle is on time when its reply arrives before the next packet is sent; a reply that does
    not come within ``reply_grace`` wall seconds is late (a lost packet is late at once).  So the
    outcome depends on what the external system answered, not on how fast the machine is.
    ``now_ns`` (for benchmarks) records each reply's round trip in ``model.stats.latencies_ns``.
    A ``flooder`` sends its cycle's datagrams half just before the packet, half just after it, so
    they compete with the packet and with the reply.  Returns why RSI stopped, or None when
    ``cycles`` ran out or ``stop`` was set.
    """
    link = _Link(sock, peer, model, faults, now_ns)
    buf = bytearray(65536)
    done = 0
    while (cycles is None or done < cycles) and not (stop is not None and stop.is_set()):
        burst = flooder.due() if flooder is not None else 0
        if flooder is not None:
            flooder.send(burst // 2)
        sent = link.send()
        if flooder is not None:
            flooder.send(burst - burst // 2)
        if sent:
            while True:
                got = link.read(reply_grace, buf)
                if got is None or (got[0] and link.offer(*got)):
                    break  # no reply within the grace, or the reply
        try:
            model.advance()
        except RsiStopped as stopped:
            return stopped
        done += 1
    return None


def run_realtime(
    sock: socket.socket,
    peer: tuple[str, int],
    model: KrcModel,
    clock: Clock,
    *,
    cycles: int | None = None,
    faults: Faults = Faults(),
    stop: threading.Event | None = None,
    flooder: Flooder | None = None,
) -> RsiStopped | None:
    """Real-time mode: a packet every cycle of ``clock`` run time, replies or not.

    Packets leave on a fixed grid; a reply is on time if it arrived (by the kernel's receive
    stamp) before the next tick, and the cycle is closed then, just before the next packet is
    computed and sent.  If the simulator itself wakes more than an eighth of a cycle late, it
    counts an overrun and restarts its grid there, so its own hiccups never shorten the
    external system's cycle.  The
    waits are ``select`` timeouts computed from ``clock.now()``: microsecond resolution, where
    asyncio timers round to the millisecond.  A ``flooder`` sends its datagrams evenly spread
    over every cycle from the same thread, between the waits.
    """
    link = _Link(sock, peer, model, faults, _wall_ns, kernel_stamps=True)
    buf = bytearray(65536)
    cycle = model.dt
    tick = clock.now()
    deadline_ns: int | None = None  # for the reply to the packet in flight; None: none can be on time
    in_flight = False
    done = 0
    if flooder is not None:
        flooder.pace(tick, cycle)
    while not (stop is not None and stop.is_set()):
        jitter = link.rng.uniform(0.0, faults.jitter_ms) / 1000.0 if faults.jitter_ms else 0.0
        _collect(link, clock, tick + jitter, buf, deadline_ns, flooder)
        woke = clock.now()
        if woke - tick - jitter > cycle / 8:
            # The simulator itself woke late (a controller never does): start the grid again
            # from here, so the external system still gets a whole cycle for this packet.
            model.stats.overruns += 1
            tick = woke - jitter
        if in_flight:
            try:
                model.advance()
            except RsiStopped as stopped:
                return stopped
            done += 1
            if cycles is not None and done >= cycles:
                return None
        tick += cycle
        now = clock.now()
        sent = link.send()
        # On time means: in by the next tick of the grid, by the kernel's receive stamp.
        deadline_ns = link.sent_ns + int(clock.to_wall(tick - now) * 1e9) if sent else None
        in_flight = True
    return None


def _collect(link: _Link, clock: Clock, until: float, buf: bytearray, deadline_ns: int | None, flooder: Flooder | None = None) -> None:
    """Read datagrams until run time ``until`` (and whatever has arrived by then); offer the ones
    that arrived by ``deadline_ns``, discard the rest as late.  A flooder's datagrams leave at
    their instants in between."""
    while True:
        wake = until
        if flooder is not None:
            flooder.fire(clock.now())
            wake = min(until, flooder.next_at)
        got = link.read(clock.to_wall(wake - clock.now()), buf)
        if got is None:
            if wake < until:
                continue  # woke for the flood, not for the end of the wait
            return
        data, arrived = got
        if not data:
            continue
        if deadline_ns is not None and arrived <= deadline_ns:
            link.offer(data, arrived)
        else:
            link.model.stats.late_replies_discarded += 1
            if deadline_ns is not None:
                link.model.stats.lateness_ns.append(arrived - deadline_ns)


class SimulatorThread:
    """The simulator on its own thread and socket, for tests and for an in-process bridge.

    ``clock=None`` runs in accelerated (lockstep) mode; with a clock it runs in real time.  A
    ``flood`` adds a second sender on the controller's IP (another port): :attr:`flooder`.
    """

    def __init__(
        self,
        config: RsiConfig,
        peer: tuple[str, int],
        *,
        context: RsiContext = RsiContext(),
        roles: RsiRoles = RsiRoles(),
        bind: tuple[str, int] = ("127.0.0.1", 0),
        clock: Clock | None = None,
        faults: Faults = Faults(),
        cycles: int | None = None,
        reply_grace: float = 0.25,
        now_ns: Callable[[], int] | None = None,
        quirks: Quirks = Quirks(),
        flood: Flood = Flood(),
    ) -> None:
        self.model = KrcModel(config, context, roles, quirks=quirks)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(bind)
        self.address: tuple[str, int] = self.sock.getsockname()
        self.peer = peer
        self.flooder = Flooder(flood, self.address[0], peer, self.model, faults.seed) if flood.rate > 0 else None
        self._clock = clock
        self._faults = faults
        self._cycles = cycles
        self._grace = reply_grace
        self._now_ns = now_ns
        self._stop = threading.Event()
        self.result: RsiStopped | None = None
        self.crash: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="rsi-simulator", daemon=True)

    def start(self) -> SimulatorThread:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            if self._clock is None:
                self.result = run_lockstep(
                    self.sock, self.peer, self.model, cycles=self._cycles, faults=self._faults, reply_grace=self._grace,
                    stop=self._stop, now_ns=self._now_ns, flooder=self.flooder,
                )
            else:
                self.result = run_realtime(
                    self.sock, self.peer, self.model, self._clock, cycles=self._cycles, faults=self._faults, stop=self._stop,
                    flooder=self.flooder,
                )
        except BaseException as error:  # noqa: BLE001 - kept for the test or bridge that owns the thread
            self.crash = error
        finally:
            self.sock.close()
            if self.flooder is not None:
                self.flooder.close()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def join(self, timeout: float | None = None) -> bool:
        self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    @property
    def stop_reason(self) -> str | None:
        if self.crash is not None:
            return f"simulator crashed: {type(self.crash).__name__}: {self.crash}"
        return self.result.reason if self.result else None
