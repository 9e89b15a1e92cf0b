"""The RSI external system: the loop that answers every ``<Rob>`` packet within the cycle.

ITRA's RSI-Manager Thread (seed 003): one UDP socket serves every robot, each known by the
address its packets come from -- its IP and one port, configured or pinned by its first valid
packet (:mod:`.peer`); each packet is timestamped, parsed, answered at once with its IPOC echoed,
and only then published to the application.  Between the parse and the reply the
loop does the one thing that cannot wait: it reads the latest command, steps the robot's online
trajectory generator (or the next point of a streamed tool path) and writes the correction.

Built never to miss a deadline:

* driven by packet arrival -- the robot's clock -- never by sleeping; the receive wait is bounded
  (``poll``) only so the loop can notice silence and its control pipe;
* commands and feedback go through seqlocked shared records (:mod:`.slots`): setters never wait
  for the loop and the loop never waits for them (a record caught mid-write is read next cycle);
* the reply is one formatting of a precompiled byte template; the receive buffer is reused;
* work that may stall -- files, events to the application, garbage collection -- comes after the
  reply or on other threads; in its own process (:mod:`.runner`) the loop freezes and disables the
  garbage collector and shortens the interpreter's switch interval, so the feedback writer cannot
  hold the GIL across a cycle.

What happens for one robot is :mod:`.channel`'s (the conversation) and :mod:`.motion`'s (the set
point, planned from what the external system commanded, never from what the controller reports).
The loop owns the socket: it sorts datagrams by robot as it reads them (one from anyone else --
another address, or another port of a robot's IP -- is counted by its sender and dropped unread,
so a flood costs a lookup per datagram and at most :data:`MAX_BATCH` are read before the kept
packets are answered), takes a packet only if its IPOC can follow the last one, answers only the
newest packet of each robot, counts and reports what it refuses -- by reason, so that a peer whose
every packet is refused ends the wait for it with what was wrong, not with "no packet" -- watches
for silence, and ends with a summary naming every sender that was not a robot.
"""
from __future__ import annotations

import gc
import os
import socket
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from robot_bridges.kuka_rsi.channel import Channel
from robot_bridges.kuka_rsi.codec import MAX_PACKET_BYTES, PacketError
from robot_bridges.kuka_rsi.feedback import FeedbackLogger
from robot_bridges.kuka_rsi.link import RobotLink
from robot_bridges.kuka_rsi.peer import resolve_ipv4
from robot_bridges.kuka_rsi.pipe import FramedPipe, PipeClosed
from robot_bridges.kuka_rsi.slots import RobotSlots
from robot_bridges.kuka_rsi.streaming import ToolPath

__all__ = ["Channel", "LoopSettings", "LoopStats", "RobotLink", "RsiLoop"]


@dataclass(frozen=True)
class LoopSettings:
    host: str = "127.0.0.1"
    port: int = 49152
    poll: float = 0.02  # s: longest receive wait before the loop looks at the time and its pipe
    silence_timeout: float = 0.1  # s without packets after the first: the robot is lost
    connect_timeout: float = 10.0  # s to the first valid packet of each robot
    heartbeat_cycles: int = 25
    max_packet: int = MAX_PACKET_BYTES
    gc_control: bool = False  # freeze + disable the collector (only where the loop owns the process)
    gc_every: int = 2500  # cycles between young-generation collections in the slack after a reply
    switch_interval: float | None = None  # s; set sys.setswitchinterval (process mode)
    realtime_priority: int | None = None  # try SCHED_FIFO at this priority (needs CAP_SYS_NICE)
    record_busy: bool = False  # keep every receive-to-send time (benchmarks)


#: Datagrams read per wake at most before the ones kept are answered (a flood must not hold a reply back).
MAX_BATCH = 256
#: Senders remembered by address in the counts (the rest are counted, not named).
MAX_NAMED = 100


@dataclass
class LoopStats:
    packets: int = 0
    foreign: int = 0  # datagrams from addresses that are no configured robot's
    rejected: int = 0
    oversized: int = 0
    stale: int = 0  # packets skipped because a newer one from the same robot was already waiting
    foreign_from: dict[str, int] = field(default_factory=dict)  # datagrams from unknown addresses, by address
    spoofed: int = 0  # datagrams from a robot's IP but not its port: another sender on the controller's host
    spoofed_from: dict[str, int] = field(default_factory=dict)  # by sender address
    max_busy_ns: int = 0  # longest receive-to-send time
    busy_ns: list[int] = field(default_factory=list)  # every receive-to-send time, when recording


class RsiLoop:
    """The loop over one socket for every robot; runs on a thread or as a process's main."""

    def __init__(
        self,
        links: Sequence[RobotLink],
        settings: LoopSettings,
        slots: Sequence[RobotSlots],
        pipe: FramedPipe,
        now_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        """``now_ns`` is the timestamp source (ITRA's performance counter), injected so tests
        can drive it; the default is the system-wide monotonic clock, the same in every
        process, so the application can compare its own timestamps with the loop's."""
        if len(slots) != len(links):
            raise ValueError("one set of shared records per robot")
        self.links = tuple(links)
        self.settings = settings
        self.pipe = pipe
        self.now_ns = now_ns
        self.logger = FeedbackLogger(len(links))
        self.channels = [
            Channel(i, link, slots[i], self._emit, self.logger, settings.heartbeat_cycles) for i, link in enumerate(links)
        ]
        hosts = [resolve_ipv4(link.host, f"the address of robot {link.name}") for link in links]  # once, here
        self._by_host_port = {(h, l.port): c for h, l, c in zip(hosts, links, self.channels) if l.port is not None}
        self._by_host = {h: c for h, l, c in zip(hosts, links, self.channels) if l.port is None}
        self._robot_hosts: dict[str, Channel] = {}
        for h, c in zip(hosts, self.channels):
            self._robot_hosts.setdefault(h, c)
        self.stats = LoopStats()
        self._shutdown = False
        self._warned: dict[str, int] = {}

    def _emit(self, message: tuple[object, ...]) -> None:
        try:
            self.pipe.send(message)
        except PipeClosed:
            self._shutdown = True  # the application is gone

    def _warn(self, key: str, text: str) -> None:
        """Report the first occurrence of a kind of bad datagram, then every 1000th."""
        n = self._warned.get(key, 0) + 1
        self._warned[key] = n
        if n == 1 or n % 1000 == 0:
            self._emit(("warn", -1, f"{text} ({n} so far)"))

    # ------------------------------------------------------------------------------ run
    def run(self) -> None:
        """Bind, serve until told to stop; every failure is reported through the pipe."""
        sock = None
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind((self.settings.host, self.settings.port))
            host, port = sock.getsockname()[:2]
            self._emit(("ready", host, port, self._tune()))
            self._serve(sock)
        except OSError as error:
            where = f"{self.settings.host}:{self.settings.port}"
            self._emit(("fault", -1, "connection", f"RSI socket {where}: {error.strerror or error}"))
        except Exception as error:  # noqa: BLE001 - a defect must reach the application, not vanish
            self._emit(("fault", -1, "internal", f"RSI loop crashed: {type(error).__name__}: {error}\n{traceback.format_exc()}"))
        finally:
            if sock is not None:
                sock.close()
            self.logger.close()
            self._emit(("summary", self.summary(), self.suspicious()))
            self._emit(("stopped",))
            try:
                self.pipe.flush()
            except PipeClosed:
                pass

    def _tune(self) -> str:
        """Apply the process-wide settings; say what took effect."""
        notes = []
        s = self.settings
        if s.switch_interval is not None:
            sys.setswitchinterval(s.switch_interval)
            notes.append(f"switch interval {s.switch_interval * 1e6:.0f} us")
        if s.gc_control:
            gc.collect()
            gc.freeze()
            gc.disable()
            notes.append("gc frozen and disabled")
        if s.realtime_priority is not None:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(s.realtime_priority))
                # The saving thread shares the GIL: preempted by ordinary work while holding it,
                # it would hold the loop back too (priority inversion).  Just below the loop, it cannot be.
                writer = max(1, s.realtime_priority - 1)
                os.sched_setscheduler(self.logger.native_id, os.SCHED_FIFO, os.sched_param(writer))
                notes.append(f"SCHED_FIFO {s.realtime_priority} (saving thread {writer})")
            except (PermissionError, OSError) as error:
                notes.append(f"no real-time priority ({error.strerror or error})")
        return ", ".join(notes) or "defaults"

    def _serve(self, sock: socket.socket) -> None:
        s = self.settings
        sock.settimeout(s.poll)
        # The same socket without Python's timeout emulation, to take what is already waiting.
        drain = socket.socket(fileno=os.dup(sock.fileno()))
        drain.setblocking(False)
        buf = bytearray(s.max_packet + 1)
        view = memoryview(buf)
        started = self.now_ns()
        gc_every = s.gc_every if s.gc_control else 0
        try:
            while not self._shutdown:
                try:
                    n, addr = sock.recvfrom_into(buf)
                except TimeoutError:
                    self._idle(started)
                    continue
                except ConnectionRefusedError:
                    continue  # ICMP for an earlier reply: that robot is gone; silence will tell
                # Sorted as they are read: a datagram from no robot's address and port is counted
                # and dropped unread, so a flood costs a dictionary lookup per datagram, not a parse.
                batch: list[tuple[bytes, tuple[str, int], Channel]] = []
                channel = self._admit(addr)
                if channel is not None:
                    batch.append((bytes(view[:n]), addr, channel))
                for _ in range(MAX_BATCH - 1):
                    try:
                        n, addr = drain.recvfrom_into(buf)
                    except (BlockingIOError, ConnectionRefusedError):
                        break
                    channel = self._admit(addr)
                    if channel is not None:
                        batch.append((bytes(view[:n]), addr, channel))
                if not batch:
                    self._service(started)
                    continue
                t = self.now_ns()
                for channel, ipoc, source in self._decoded(batch):
                    self._answer(sock, channel, ipoc, source, t)
                self._service(started)
                if gc_every and self.stats.packets % gc_every < len(batch):
                    gc.collect(0)  # in the slack after a reply, never before one
        finally:
            drain.close()

    def _admit(self, addr: tuple[str, int]) -> Channel | None:
        """The robot a datagram from ``addr`` may come from; None (counted, reported) for anyone else.

        From a robot's IP but not its port -- configured, or pinned by its first valid packet -- is
        another sender on the controller's host: never the robot, never answered, never blamed on it.
        """
        ip, port = addr[0], addr[1]
        channel = self._by_host_port.get((ip, port)) or self._by_host.get(ip)
        if channel is not None and channel.gate.admits(port):
            return channel
        owner = channel or self._robot_hosts.get(ip)
        if owner is None:
            stats = self.stats
            stats.foreign += 1
            source = f"{ip}:{port}"
            if len(stats.foreign_from) < MAX_NAMED or source in stats.foreign_from:
                stats.foreign_from[source] = stats.foreign_from.get(source, 0) + 1
            self._warn("foreign", f"ignored a datagram from {source}, which is not a configured robot")
            return None
        self._spoofed(owner, f"{ip}:{port}")
        return None

    def _spoofed(self, owner: Channel, source: str) -> None:
        stats = self.stats
        stats.spoofed += 1
        owner.spoofed += 1
        if len(stats.spoofed_from) < MAX_NAMED or source in stats.spoofed_from:
            stats.spoofed_from[source] = stats.spoofed_from.get(source, 0) + 1
        link, gate = owner.link, owner.gate
        self._warn(
            f"spoofed {owner.index}",
            f"ignored a datagram from {source}: the address of robot {link.name}, but not its port "
            f"{gate.port} ({gate.where()}); another sender on the controller's host is not the controller",
        )

    def _packets(self, batch: list[tuple[bytes, tuple[str, int]]]) -> list[tuple[Channel, int, tuple[str, int]]]:
        """The packets of a batch of datagrams (as read, in order), decoded, and of each robot only the newest."""
        admitted = []
        for data, addr in batch:
            channel = self._admit(addr)
            if channel is not None:
                admitted.append((data, addr, channel))
        return self._decoded(admitted)

    def _decoded(self, batch: list[tuple[bytes, tuple[str, int], Channel]]) -> list[tuple[Channel, int, tuple[str, int]]]:
        """Decode the admitted datagrams in order; of each robot keep only the newest packet.

        More than one packet from a robot means the loop was held up and the robot has moved on:
        the older packet is late already, and answering it would step the generator for a cycle
        the robot has counted late -- a jump in the set point when the newest reply lands.
        Oversized and malformed datagrams, and packets whose IPOC cannot follow the last one
        (:class:`~.peer.PeerGate`), are counted and reported and change nothing.
        """
        s, stats = self.settings, self.stats
        packets: list[tuple[Channel, int, tuple[str, int]]] = []
        for data, addr, channel in batch:
            source = f"{addr[0]}:{addr[1]}"
            if not channel.gate.admits(addr[1]):  # the batch's first valid packet pinned another port
                self._spoofed(channel, source)
                continue
            if len(data) > s.max_packet:
                stats.oversized += 1
                channel.refuse("size", f"a datagram of {len(data)} bytes, over the {s.max_packet}-byte limit", source)
                self._warn("oversized", f"rejected a datagram over {s.max_packet} bytes from {source} (robot {channel.link.name}'s address)")
                continue
            try:
                ipoc = channel.rob.decode_into(data, channel.spare)  # rx stays as it was until the packet is taken
            except PacketError as error:
                self._reject(channel, error.reason, str(error), source)
                continue
            problem = channel.take(ipoc, addr[1])
            if problem is not None:
                self._reject(channel, "ipoc", problem, source)
                continue
            if channel.pinned_now:
                self._emit(("peer", channel.index, source, channel.gate.where()))
            packets.append((channel, ipoc, addr))
        if len(packets) > 1:
            newest = {id(channel): i for i, (channel, _, _) in enumerate(packets)}
            kept = [p for i, p in enumerate(packets) if newest[id(p[0])] == i]
            stats.stale += len(packets) - len(kept)
            return kept
        return packets

    def _reject(self, channel: Channel, reason: str, message: str, source: str) -> None:
        self.stats.rejected += 1
        channel.refuse(reason, message, source)
        self._warn(f"bad {channel.index} {reason}", f"rejected a packet from {source} (robot {channel.link.name}'s address), {reason}: {message}")

    def _answer(self, sock: socket.socket, channel: Channel, ipoc: int, addr: tuple[str, int], t: int) -> None:
        stats = self.stats
        try:
            reply = channel.respond(ipoc, t)
        except Exception as error:  # noqa: BLE001 - keep answering, report the defect
            channel.broken = True
            self._emit(("fault", channel.index, "internal", f"{type(error).__name__}: {error}\n{traceback.format_exc()}"))
            reply = channel.sen.encode(channel.tx, ipoc)
        if reply is not None:
            sock.sendto(reply, addr)
            busy = self.now_ns() - t
            if busy > stats.max_busy_ns:
                stats.max_busy_ns = busy
            if self.settings.record_busy:
                stats.busy_ns.append(busy)
        stats.packets += 1
        channel.after_reply(t)

    def _service(self, started: int) -> None:
        """Between packets: control messages, silence watch, the saving thread's complaints."""
        errors = self.logger.errors
        while errors:
            self._emit(("warn", -1, errors.popleft()))
        try:
            for message in self.pipe.receive():
                self._control(message)
            self.pipe.flush()
        except PipeClosed:
            self._shutdown = True
        now = self.now_ns()
        s = self.settings
        for channel in self.channels:
            if channel.connected:
                if not channel.lost and now - channel.last_ns > s.silence_timeout * 1e9:
                    silent = (now - channel.last_ns) / 1e6
                    self._emit(("fault", channel.index, "timeout", f"no packet from {channel.link.name} for {silent:.0f} ms after IPOC {channel.ipoc} (delay count {channel.delay})"))
                    channel.mark_lost(f"no RSI packet for {silent:.0f} ms")  # then the running command ends
            elif not channel.lost and now - started > s.connect_timeout * 1e9:
                channel.lost = True
                self._emit(("fault", channel.index, "timeout", self._no_packet(channel)))

    def summary(self) -> str:
        """The run of the loop in one line: each robot's packets, and every other sender by its address."""
        st = self.stats
        parts = []
        for c in self.channels:
            where = f"{c.link.host}:{c.gate.port}" if c.gate.port is not None else f"{c.link.host}, never heard from"
            text = f"{c.link.name} ({where}): {c.cycles:,} packets answered, the controller counted {c.delay:,} late"
            if c.catch_ups:
                text += f", {c.catch_ups:,} showed cycles it held"
            if c.refused:
                text += f", {sum(c.refused.values()):,} refused ({', '.join(f'{n:,} x {r}' for r, n in sorted(c.refused.items()))})"
            parts.append(text)
        if st.stale:
            parts.append(f"{st.stale:,} skipped for a newer packet")
        if st.spoofed:
            parts.append(f"ignored {st.spoofed:,} datagrams from a controller's address but another port, not the controller: {_named(st.spoofed_from, st.spoofed)}")
        if st.foreign:
            parts.append(f"ignored {st.foreign:,} datagrams from other addresses: {_named(st.foreign_from, st.foreign)}")
        return "RSI loop: " + "; ".join(parts)

    def suspicious(self) -> bool:
        """Whether anything but the robots spoke, or a robot's datagrams were refused."""
        return bool(self.stats.spoofed or self.stats.foreign or self.stats.rejected)

    def _no_packet(self, channel: Channel) -> str:
        """Why no valid packet came: refused ones (how many, from where, why), strangers, or nothing."""
        link = channel.link
        text = f"no valid packet from {link.name} ({link.host}{'' if link.port is None else f':{link.port}'}) within {self.settings.connect_timeout:g} s"
        if channel.refused:
            return f"{text}: {channel.refusals()}"
        if channel.spoofed:
            return (
                f"{text}: nothing arrived from its port {channel.gate.port} ({channel.gate.where()}); "
                f"{channel.spoofed} datagrams came from its address but other ports ({_named(self.stats.spoofed_from, self.stats.spoofed)})"
            )
        strangers = self.stats.foreign_from
        if strangers:
            listed = ", ".join(f"{n} from {source}" for source, n in list(strangers.items())[:3])
            return f"{text}: nothing arrived from it; datagrams came from addresses that are not the configured robot ({listed})"
        return f"{text}: nothing arrived"

    def _idle(self, started: int) -> None:
        self._service(started)
        self.logger.flush()

    def _control(self, message: tuple[object, ...]) -> None:
        kind = message[0]
        if kind == "shutdown":
            self._shutdown = True
        elif kind == "stage":
            _, robot, key, space, raw, rows, source, lines = message
            points = np.frombuffer(raw, dtype=np.float64).reshape(int(rows), 6).copy()  # type: ignore[arg-type, call-overload]
            self.channels[int(robot)].staged = {int(key): ToolPath(space, points, str(source), tuple(lines))}  # type: ignore[arg-type, call-overload]
        elif kind == "feedback":
            _, robot, path = message
            self.logger.set_output(int(robot), None if path is None else str(path))  # type: ignore[call-overload]
            self._emit(("feedback", robot, path))
        elif kind == "wake":
            _, robot, cycle = message
            self.channels[int(robot)].wake_at(int(cycle))  # type: ignore[call-overload]
        elif kind == "output":
            _, robot, key, value = message
            self.channels[int(robot)].set_output(str(key), value)  # type: ignore[call-overload]
        elif kind == "withhold":
            _, robot, count = message
            self.channels[int(robot)].withhold = int(count)  # type: ignore[call-overload]
        elif kind == "stats":
            st = self.stats
            self._emit((
                "stats", st.packets, st.foreign, st.rejected, st.oversized, st.max_busy_ns, list(st.busy_ns), [c.withheld for c in self.channels],
                list(self.logger.written), st.stale, [dict(c.refused) for c in self.channels], [dict(c.motion.clamps) for c in self.channels],
                st.spoofed, dict(st.spoofed_from), dict(st.foreign_from),
            ))
        else:
            self._emit(("warn", -1, f"unknown control message {kind!r}"))


def _named(counts: dict[str, int], total: int, shown: int = 3) -> str:
    """The senders with the most datagrams, by address, and how many the rest sent."""
    top = sorted(counts.items(), key=lambda kv: -kv[1])[:shown]
    text = ", ".join(f"{n:,} from {source}" for source, n in top)
    rest = total - sum(n for _, n in top)
    return f"{text} and {rest:,} from others" if rest > 0 else text
