"""A V+ AdeptServer simulator: the TCP server a Viper s850 controller runs, over a kinematic arm.

It behaves like AdeptServer's ``serverloop``/``on_recv`` (seed 000, ``adeptserver.V2``): read
whatever bytes arrived, run every complete message in order -- one at a time, for every client,
because the controller runs one server task -- and after each skill write
``<id>:done:<t_recv>,<t_done>:<pose>``.  ``t_recv`` is when the chunk holding the message was
read and ``t_done`` when the skill returned, in controller-clock seconds since the server
started, with millisecond resolution.  Like the real server it sends no error replies: a message
it cannot parse, an unknown skill, or a skill that fails (a location out of reach) gets no ack,
only a line in the log and in :attr:`VPlusSimulator.errors`.  Unlike the real server, which
splits each read on ``\\r\\n`` and so breaks on a message cut across two reads, it reassembles
lines across any segmentation, as the seed says both ends should.

For tests, :class:`Faults` injects what real networks and controllers do: drop the connection
(after a number of messages, or when a given skill starts), delay acks, garble them, write them in
small pieces, or report a pose the arm is not at (a controller that lies).  Everything runs on the
injectable clock.

Client slots are bounded (``max_clients``, AdeptServer's ``/CLIENTS 10``) and so is what a client
may hold one for without working: only a complete message of a skill this server has counts as
work -- an empty line, a few bytes now and then, a malformed line or an unknown skill do not -- so
a client that has sent no such message for ``idle_timeout`` is closed however much it trickles,
one that sends ``max_junk`` bytes without one is closed at once, and when every slot is taken a
new client takes the slot of the client that has worked least recently, if that one has been idle
for ``reclaim_after``.  No set of clients can therefore lock a working client out for longer than
``reclaim_after``.

``python -m robot_bridges.vplus.simulator --port 1234`` runs it standalone until SIGINT/SIGTERM.
"""
from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from core_functions.option_ranges import bounds
from node_transport.clock import Clock, run_with_clock, scaled_clock
from robot_bridges.vplus.codec import (
    MAX_LINE,
    Ack,
    Skill,
    DecodeError,
    FrameError,
    LineSplitter,
    Message,
    UnknownSkill,
    decode_message,
)
from robot_bridges.vplus.kinematics import HOME_DEG, Location
from robot_bridges.vplus.sim_arm import SimulatedArm, SkillError

log = logging.getLogger(__name__)

DEFAULT_PORT = 1234
#: AdeptServer opens its socket with ``/CLIENTS 10``.
MAX_CLIENTS = 10
#: Run seconds a client may go without a complete message before its slot is freed (the back end
#: reconnects at its next primitive); trickled bytes, empty lines and garbage do not reset it.
IDLE_TIMEOUT = 60.0
#: Run seconds without work after which a client's slot goes to a new client when every slot is taken.
RECLAIM_AFTER = 30.0
#: Bytes a client may send without a complete message among them before it is closed: the longest
#: legal message is ~100 bytes, so this is junk, an endless trickle, not a slow command.
MAX_JUNK = 4096
_READ_SIZE = 2048  # AdeptServer's /BUFFER_SIZE
_KEPT = 100_000  # entries of errors / received / acked kept for inspection (the oldest go first)
_T = TypeVar("_T")


@dataclass
class Faults:
    """What to break, for tests.  Fields may be changed while the simulator runs."""

    #: Run this many more messages, then close the connection on the next one (neither run nor acked).
    drop_after: int | None = None
    #: Close the connection when a message with one of these skills starts executing (once per
    #: skill: it is removed when it fires).  The skill still runs to its end -- the arm keeps
    #: moving -- but its ack is never written.
    drop_on: set[str] = field(default_factory=set)
    #: Extra run-time seconds before each ack is written.
    ack_delay: float = 0.0
    #: Garble this many of the next acks (the status field becomes unreadable).
    garble_acks: int = 0
    #: Write each ack in pieces of this many bytes, one write each (0: whole).
    split_acks: int = 0
    #: Skills that run but are never acked, as if the ack were lost.
    mute: set[str] = field(default_factory=set)
    #: Every ack reports this location (mm, deg) instead of where the arm is: a controller that
    #: acknowledges every skill but does not move where it was told (or reports it wrongly).
    report_location: Location | None = None


@dataclass
class _Client:
    peer: str
    writer: asyncio.StreamWriter
    task: asyncio.Task[None]
    last_work: float  # run time its last complete message of a known skill ended (or it connected)
    busy: bool = False  # running (or queued behind another client's) message: not idle
    junk: int = 0  # bytes received since its last complete message

    def idle(self, now: float) -> float:
        return 0.0 if self.busy else now - self.last_work


class VPlusSimulator:
    """The AdeptServer TCP server over a :class:`SimulatedArm`; ``async with`` starts and stops it."""

    def __init__(
        self,
        clock: Clock,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        arm: SimulatedArm | None = None,
        faults: Faults | None = None,
        max_clients: int = MAX_CLIENTS,
        max_line: int = MAX_LINE,
        skills: Iterable[Skill] = tuple(Skill),
        idle_timeout: float = IDLE_TIMEOUT,
        reclaim_after: float = RECLAIM_AFTER,
        max_junk: int = MAX_JUNK,
    ) -> None:
        self.clock = clock
        self.host = host
        self._requested_port = port
        self.arm = arm or SimulatedArm(clock, joints_deg=HOME_DEG)
        self.faults = faults or Faults()
        self.max_clients = max_clients
        self.max_line = max_line
        for name, value in (("idle_timeout", idle_timeout), ("reclaim_after", reclaim_after)):
            bounds(name).check(name, value)  # its range (core_functions.option_ranges): a RangeError, a ValueError
        if max_junk < MAX_LINE:
            raise ValueError(f"max_junk must be >= {MAX_LINE} bytes (one line), got {max_junk}")
        self.idle_timeout = idle_timeout
        self.reclaim_after = reclaim_after
        self.max_junk = max_junk
        #: The skills this server has; AdeptServer variants differ (gripper, movehome on some only).
        self.skills = frozenset(Skill(s) for s in skills)
        self.errors: list[str] = []
        self.received: list[Message] = []
        self.acked: list[str] = []
        self._server: asyncio.Server | None = None
        self._clients: dict[int, _Client] = {}
        self._next_client = 0
        self._robot = asyncio.Lock()  # one server task on the controller: one skill at a time
        self._t0 = 0.0

    # ---------------------------------------------------------------------------- lifecycle
    async def start(self) -> VPlusSimulator:
        self._t0 = self.clock.now()
        self._server = await asyncio.start_server(self._on_connect, self.host, self._requested_port)
        log.info("V+ simulator listening on %s:%d", self.host, self.port)
        return self

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        for client in list(self._clients.values()):
            client.writer.close()
            client.task.cancel()
        await asyncio.gather(*(c.task for c in self._clients.values()), return_exceptions=True)
        self._clients.clear()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> VPlusSimulator:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def port(self) -> int:
        if self._server is None or not self._server.sockets:
            return self._requested_port
        return int(self._server.sockets[0].getsockname()[1])

    @property
    def clients(self) -> int:
        return len(self._clients)

    def controller_time(self) -> float:
        """Seconds since the server started (V+ ``TIMER(-3) - t0``)."""
        return self.clock.now() - self._t0

    async def drop_clients(self) -> None:
        """Close every client connection now (a cable pulled, a controller reboot)."""
        for client in list(self._clients.values()):
            client.writer.close()

    async def send_raw(self, data: bytes) -> None:
        """Write ``data`` to every client as is (to test how a client takes unexpected bytes)."""
        for client in list(self._clients.values()):
            client.writer.write(data)
            with contextlib.suppress(ConnectionError):
                await client.writer.drain()

    # ---------------------------------------------------------------------------- serving
    async def _on_connect(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = _peer(writer)
        if len(self._clients) >= self.max_clients and not self._reclaim(peer):
            # Say why before closing: a client that is simply reset cannot tell a full server from a dead one.
            reason = (
                f"refused: {self.max_clients} clients already connected; idle ones are closed after {self.idle_timeout:g} s, "
                f"and one idle for {self.reclaim_after:g} s gives its slot to a new client"
            )
            self._error(f"{peer}: {reason}")
            writer.write(reason.encode() + b"\r\n")
            with contextlib.suppress(ConnectionError):
                await writer.drain()
            writer.close()
            return
        key = self._next_client
        self._next_client += 1
        task = asyncio.current_task()
        assert task is not None
        client = self._clients[key] = _Client(peer, writer, task, self.clock.now())
        log.info("connection established: %s", peer)
        try:
            await self._serve(client, reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError) as error:
            log.info("%s: connection lost: %s", peer, error)
        except asyncio.CancelledError:  # the server is closing: end quietly (a cancelled connection task
            pass  # makes Python 3.11's start_server callback log a spurious error)
        except Exception as error:  # noqa: BLE001 - a simulator defect must be visible, not silent
            self._error(f"{peer}: simulator fault: {type(error).__name__}: {error}")
            log.exception("%s: simulator fault", peer)
        finally:
            self._clients.pop(key, None)
            writer.close()
            log.info("connection closed: %s", peer)

    def _reclaim(self, newcomer: str) -> bool:
        """Every slot is taken: close the client idle longest, if idle for ``reclaim_after``; whether one was."""
        now = self.clock.now()
        key, idlest = max(self._clients.items(), key=lambda item: item[1].idle(now))
        idle = idlest.idle(now)
        if idle < self.reclaim_after:
            return False
        log.info("%s: idle for %.1f s, its slot goes to %s", idlest.peer, idle, newcomer)
        self._say_and_close(idlest, f"closed: idle for {idle:.1f} s and another client needs the slot")
        del self._clients[key]  # its task ends on its own; the slot is the newcomer's now
        return True

    def _say_and_close(self, client: _Client, text: str) -> None:
        client.writer.write(text.encode() + b"\r\n")
        client.writer.close()

    async def _serve(self, client: _Client, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        splitter = LineSplitter(self.max_line)
        peer = client.peer
        while not writer.is_closing():
            left = client.last_work + self.idle_timeout - self.clock.now()
            try:  # bounded from its last message, not its last byte: trickling does not keep a slot
                data = await self.clock.wait_for(reader.read(_READ_SIZE), max(0.0, left))
            except asyncio.TimeoutError:
                log.info("%s: idle for %g s, closing", peer, self.idle_timeout)
                self._say_and_close(client, f"closed: idle for {self.idle_timeout:g} s")
                return
            if not data:
                return
            t_recv = self.controller_time()
            client.junk += len(data)
            try:
                lines = splitter.feed(data)
            except FrameError as error:
                self._error(f"{peer}: {error}; closing the connection")
                return
            for line in lines:
                if writer.is_closing():
                    return
                client.busy = True
                try:
                    worked = await self._handle(peer, line, t_recv, writer)
                finally:
                    client.busy = False
                if worked:
                    client.last_work, client.junk = self.clock.now(), 0
            if client.junk > self.max_junk:
                self._error(f"{peer}: {client.junk} bytes without a complete message; closing the connection")
                self._say_and_close(client, f"closed: {client.junk} bytes without a message")
                return

    async def _handle(self, peer: str, line: bytes, t_recv: float, writer: asyncio.StreamWriter) -> bool:
        """Run one line; whether it was work (a message of a skill this server has, run or failed)."""
        faults = self.faults
        if faults.drop_after is not None:
            if faults.drop_after <= 0:
                faults.drop_after = None
                writer.close()
                return False
            faults.drop_after -= 1
        try:
            message = decode_message(line)
        except UnknownSkill as error:
            self._error(f"{peer}: unknown skill {error.skill!r} in message {error.msg_id}: not acked")
            return False
        except DecodeError as error:
            self._error(f"{peer}: malformed message: {error}: not acked")
            return False
        if message.command.skill not in self.skills:
            self._error(f"{peer}: unknown skill {message.command.skill.value!r} in message {message.id}: not acked")
            return False
        _keep(self.received, message)
        skill = message.command.skill.value
        if message.command.skill is Skill.MONITOR_SPEED:  # the operator's setting: at once, beside the motion it scales
            await self.arm.run(message.command)
            ack = Ack(message.id, t_recv, self.controller_time(), self.arm.location())
            if not writer.is_closing() and skill not in faults.mute:
                await self._write_ack(ack, writer)
            return True
        async with self._robot:
            if skill in faults.drop_on:
                faults.drop_on.discard(skill)
                writer.close()
            try:
                await self.arm.run(message.command)
            except SkillError as error:
                self._error(f"{peer}: {message}: {error}: not acked")
                return True
            location = self.arm.location() if faults.report_location is None else faults.report_location
            ack = Ack(message.id, t_recv, self.controller_time(), location)
        if writer.is_closing() or skill in faults.mute:
            return True
        await self._write_ack(ack, writer)
        return True

    async def _write_ack(self, ack: Ack, writer: asyncio.StreamWriter) -> None:
        faults = self.faults
        if faults.ack_delay > 0:
            await self.clock.sleep(faults.ack_delay)
        data = ack.encode()
        if faults.garble_acks > 0:
            faults.garble_acks -= 1
            data = data.replace(b":done:", b":d\x7fne:", 1)
        if faults.split_acks > 0:
            for i in range(0, len(data), faults.split_acks):
                writer.write(data[i : i + faults.split_acks])
                await writer.drain()
                await self.clock.sleep(1e-4)  # a separate segment, not coalesced with the next piece
        else:
            writer.write(data)
            await writer.drain()
        _keep(self.acked, ack.id)

    def _error(self, text: str) -> None:
        _keep(self.errors, text)
        log.warning("%s", text)


def _keep(entries: list[_T], entry: _T) -> None:
    """Append, dropping the oldest beyond a bound: a simulator serving for days must not grow for ever."""
    entries.append(entry)
    if len(entries) > _KEPT + _KEPT // 4:
        del entries[: len(entries) - _KEPT]


def _peer(writer: asyncio.StreamWriter) -> str:
    name = writer.get_extra_info("peername")
    return f"{name[0]}:{name[1]}" if isinstance(name, tuple) else str(name)


# ---------------------------------------------------------------------------------- CLI
def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m robot_bridges.vplus.simulator", description=__doc__.split("\n")[0])
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0 picks one)")
    parser.add_argument("--speed", type=float, default=1.0, help="run-time speed factor: 10 simulates 10x faster than real time")
    parser.add_argument("--run-for", type=float, default=None, metavar="SECONDS", help="stop after this much run time")
    parser.add_argument("--max-clients", type=int, default=MAX_CLIENTS, help=f"simultaneous clients (default {MAX_CLIENTS})")
    parser.add_argument(
        "--idle-timeout", type=float, default=IDLE_TIMEOUT,
        help=f"close a client that has sent no complete message this long, run seconds (default {IDLE_TIMEOUT:g}; trickled bytes do not count)",
    )
    parser.add_argument(
        "--reclaim-after", type=float, default=RECLAIM_AFTER,
        help=f"with every slot taken, a new client takes the slot of one idle this long, run seconds (default {RECLAIM_AFTER:g})",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log every connection and error")
    return parser


async def serve(
    clock: Clock,
    host: str,
    port: int,
    *,
    run_for: float | None = None,
    max_clients: int = MAX_CLIENTS,
    idle_timeout: float = IDLE_TIMEOUT,
    reclaim_after: float = RECLAIM_AFTER,
) -> int:
    """Run the simulator until SIGINT/SIGTERM or ``run_for`` seconds of run time; returns an exit code."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with VPlusSimulator(clock, host, port, max_clients=max_clients, idle_timeout=idle_timeout, reclaim_after=reclaim_after) as sim:
            print(f"V+ simulator on {host}:{sim.port} (x{clock.speed:g}); Ctrl-C stops it", flush=True)
            with contextlib.suppress(asyncio.TimeoutError):
                await clock.wait_for(stop.wait(), run_for)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    numbers = {"port": args.port, "speed": args.speed, "max_clients": args.max_clients, "idle_timeout": args.idle_timeout,
               "reclaim_after": args.reclaim_after, "run_for": args.run_for}
    for setting, value in numbers.items():  # each in its range (core_functions.option_ranges): one line, exit 2
        if value is not None and not bounds(setting).contains(value):
            print(f"error: --{setting.replace('_', '-')} must be a {'whole ' if bounds(setting).integer else ''}number in "
                  f"{bounds(setting).describe()}, got {value if isinstance(value, int) else format(value, 'g')}", file=sys.stderr)
            return 2
    try:
        return run_with_clock(
            lambda clock: serve(
                clock, args.host, args.port, run_for=args.run_for, max_clients=args.max_clients,
                idle_timeout=args.idle_timeout, reclaim_after=args.reclaim_after,
            ),
            scaled_clock(args.speed),
        )
    except OSError as error:
        print(f"error: cannot serve on {args.host}:{args.port}: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
