"""The RSI external system: the loop that answers every ``<Rob>`` packet within the cycle.

ITRA's RSI-Manager Thread (seed 003): one UDP socket serves every robot, each known by the
address its packets come from; each packet is timestamped, parsed, answered at once with its
IPOC echoed, and only then published to the application.  Between the parse and the reply the
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
The loop owns the socket: it sorts datagrams by robot, answers only the newest packet of each,
counts and reports what it refuses -- by reason, so that a peer whose every packet is refused ends
the wait for it with what was wrong, not with "no packet" -- and watches for silence.
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


@dataclass
class LoopStats:
    packets: int = 0
    foreign: int = 0
    rejected: int = 0
    oversized: int = 0
    stale: int = 0  # packets skipped because a newer one from the same robot was already waiting
    foreign_from: dict[str, int] = field(default_factory=dict)  # datagrams from unknown addresses, by address
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
        self._by_host_port = {(l.host, l.port): c for l, c in zip(links, self.channels) if l.port is not None}
        self._by_host = {l.host: c for l, c in zip(links, self.channels) if l.port is None}
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
                batch = [(bytes(view[:n]), addr)]
                while True:
                    try:
                        n, addr = drain.recvfrom_into(buf)
                    except (BlockingIOError, ConnectionRefusedError):
                        break
                    batch.append((bytes(view[:n]), addr))
                t = self.now_ns()
                for channel, ipoc, source in self._packets(batch):
                    self._answer(sock, channel, ipoc, source, t)
                self._service(started)
                if gc_every and self.stats.packets % gc_every < len(batch):
                    gc.collect(0)  # in the slack after a reply, never before one
        finally:
            drain.close()

    def _packets(self, batch: list[tuple[bytes, tuple[str, int]]]) -> list[tuple[Channel, int, tuple[str, int]]]:
        """The packets of a batch of datagrams, decoded, and of each robot only the newest.

        More than one packet from a robot means the loop was held up and the robot has moved on:
        the older packet is late already, and answering it would step the generator for a cycle
        the robot has counted late -- a jump in the set point when the newest reply lands.
        Foreign, oversized and malformed datagrams are counted and reported, never answered.
        """
        s, stats = self.settings, self.stats
        packets: list[tuple[Channel, int, tuple[str, int]]] = []
        for data, addr in batch:
            channel = self._by_host_port.get(addr[:2]) or self._by_host.get(addr[0])
            source = f"{addr[0]}:{addr[1]}"
            if channel is None:
                stats.foreign += 1
                if len(stats.foreign_from) < 100 or source in stats.foreign_from:
                    stats.foreign_from[source] = stats.foreign_from.get(source, 0) + 1
                self._warn("foreign", f"ignored a datagram from {source}, which is not a configured robot")
                continue
            if len(data) > s.max_packet:
                stats.oversized += 1
                channel.refuse("size", f"a datagram of {len(data)} bytes, over the {s.max_packet}-byte limit", source)
                self._warn("oversized", f"rejected a datagram over {s.max_packet} bytes from {channel.link.name}")
                continue
            try:
                ipoc = channel.rob.decode_into(data, channel.rx)  # a later packet overwrites an earlier one
            except PacketError as error:
                stats.rejected += 1
                channel.refuse(error.reason, str(error), source)
                self._warn(f"bad {channel.index} {error.reason}", f"rejected a packet from {channel.link.name} ({source}), {error.reason}: {error}")
                continue
            packets.append((channel, ipoc, addr))
        if len(packets) > 1:
            newest = {id(channel): i for i, (channel, _, _) in enumerate(packets)}
            kept = [p for i, p in enumerate(packets) if newest[id(p[0])] == i]
            stats.stale += len(packets) - len(kept)
            return kept
        return packets

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

    def _no_packet(self, channel: Channel) -> str:
        """Why no valid packet came: refused ones (how many, from where, why), strangers, or nothing."""
        link = channel.link
        text = f"no valid packet from {link.name} ({link.host}{'' if link.port is None else f':{link.port}'}) within {self.settings.connect_timeout:g} s"
        if channel.refused:
            return f"{text}: {channel.refusals()}"
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
        elif kind == "withhold":
            _, robot, count = message
            self.channels[int(robot)].withhold = int(count)  # type: ignore[call-overload]
        elif kind == "stats":
            st = self.stats
            self._emit((
                "stats", st.packets, st.foreign, st.rejected, st.oversized, st.max_busy_ns, list(st.busy_ns), [c.withheld for c in self.channels],
                list(self.logger.written), st.stale, [dict(c.refused) for c in self.channels], [dict(c.motion.clamps) for c in self.channels],
            ))
        else:
            self._emit(("warn", -1, f"unknown control message {kind!r}"))
