"""An asyncio client for AdeptServer: what pyadept's ``RobotClient`` should have been.

pyadept sends messages and waits until every id has come back; it has no timeout, so a message
the server silently drops (an unknown skill, a failed motion: AdeptServer never replies with an
error) hangs it forever, and a lost connection leaves it guessing.  This client keeps pyadept's
two calls and their meaning --

* :meth:`VPlusClient.execute`: commands one after the other; each command's messages are
  written, then their acks awaited, before the next command is written (``cmdexec``);
* :meth:`VPlusClient.execute_joined`: every message of every command in one write, then all
  acks awaited (``cmdexec_joined``) --

and adds what a controller integration needs: bounded connection retries with backoff; acks
matched by id by one reader task; a timeout per command; and, on any failure, an error that says
exactly what happened to each message (:class:`Exchange`): acked, *unknown* (written but not
acked -- the robot may or may not have run it), or never written.  After a failure the client
never re-sends anything on its own: re-sending a motion blindly could move the robot twice.
Reconnect with :meth:`VPlusClient.connect` and decide.

Every wait goes through the injectable clock, so the client runs under simulated time too.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from execution_engine.clock import Clock
from robot_bridges.vplus.codec import (
    MAX_LINE,
    Ack,
    Command,
    DecodeError,
    FrameError,
    LineSplitter,
    Message,
    decode_ack,
    encode_messages,
    new_id,
)

log = logging.getLogger(__name__)

CommandLike = Command | Sequence[Command]
_READ_SIZE = 65536
_EXPIRED_IDS = 4096  # ids given up on (timeout, cancel) whose late acks are expected and tolerated


# ------------------------------------------------------------------------------ reports
@dataclass(frozen=True)
class Exchange:
    """What became of the messages of one call when it failed."""

    acked: tuple[tuple[Message, Ack], ...] = ()
    unknown: tuple[Message, ...] = ()  # written, not acked: the controller may or may not have run them
    unsent: tuple[Message, ...] = ()  # never written: certainly not run

    def __str__(self) -> str:
        def names(msgs: Sequence[Message]) -> str:
            return ", ".join(str(m) for m in msgs) or "none"

        return (
            f"acked: {names([m for m, _ in self.acked])}; unknown (sent, not acked): {names(self.unknown)}; "
            f"not sent: {names(self.unsent)}"
        )


class VPlusError(Exception):
    """A failure talking to one AdeptServer; ``peer`` names it, ``exchange`` says what was done."""

    def __init__(self, reason: str, *, peer: str, exchange: Exchange | None = None) -> None:
        self.reason = reason
        self.peer = peer
        self.exchange = exchange or Exchange()
        text = f"V+ server {peer}: {reason}"
        if exchange is not None:
            text += f" [{exchange}]"
        super().__init__(text)

    def with_exchange(self, exchange: Exchange) -> VPlusError:
        return type(self)(self.reason, peer=self.peer, exchange=exchange)


class ConnectError(VPlusError):
    """Could not connect within the allowed attempts."""


class ConnectionLost(VPlusError):
    """Not connected, or the connection closed or broke while messages were outstanding."""


class CommandTimeout(VPlusError):
    """Acks did not arrive in time.  AdeptServer never acks an unknown skill or a failed motion."""


class ProtocolError(VPlusError):
    """The server sent something we cannot accept: a malformed ack, an unknown id, a bad status."""


# ------------------------------------------------------------------------------- client
class VPlusClient:
    """One TCP connection to an AdeptServer (real or simulated)."""

    def __init__(
        self,
        host: str,
        port: int,
        clock: Clock,
        *,
        timeout: float = 10.0,
        connect_timeout: float = 2.0,
        retries: int = 3,
        backoff: float = 0.2,
        max_backoff: float = 2.0,
        max_line: int = MAX_LINE,
        make_id: Callable[[], str] = new_id,
    ) -> None:
        if not (timeout > 0 and connect_timeout > 0 and backoff >= 0 and max_backoff >= backoff):
            raise ValueError("timeouts must be > 0 and 0 <= backoff <= max_backoff")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.host = host
        self.port = port
        self.clock = clock
        self.timeout = timeout
        self.connect_timeout = connect_timeout
        self.retries = retries
        self.backoff = backoff
        self.max_backoff = max_backoff
        self.max_line = max_line
        self._make_id = make_id
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._read_task: asyncio.Task[None] | None = None
        self._pending: dict[str, asyncio.Future[Ack]] = {}
        self._expired: OrderedDict[str, Message] = OrderedDict()
        self._lock = asyncio.Lock()
        #: Acks that came after their call had given up (timeout, cancellation); newest last.
        self.late_acks: deque[tuple[Message, Ack]] = deque(maxlen=256)
        #: The most recent ack of any kind: where the robot last was.
        self.last_ack: Ack | None = None
        #: Why the connection last went down, for the report.
        self.last_failure: str = ""

    @property
    def peer(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing() and self._read_task is not None and not self._read_task.done()

    # ------------------------------------------------------------------------ connection
    async def connect(self) -> None:
        """Connect, retrying ``retries`` times with exponential backoff; raises :class:`ConnectError`."""
        await self.close()
        errors: list[str] = []
        delay = self.backoff
        for attempt in range(self.retries + 1):
            if attempt:
                await self.clock.sleep(delay)
                delay = min(delay * 2 or self.backoff, self.max_backoff)
            try:
                reader, writer = await self.clock.wait_for(
                    asyncio.open_connection(self.host, self.port, limit=self.max_line * 4), self.connect_timeout
                )
            except asyncio.TimeoutError:
                errors.append(f"attempt {attempt + 1}: no answer within {self.connect_timeout:g} s")
            except OSError as error:
                errors.append(f"attempt {attempt + 1}: {error.strerror or error}")
            else:
                self._reader, self._writer = reader, writer
                self._read_task = asyncio.get_running_loop().create_task(self._read_loop(reader), name=f"vplus reader {self.peer}")
                self.last_failure = ""
                log.info("connected to V+ server %s", self.peer)
                return
        raise ConnectError(f"cannot connect after {len(errors)} attempt(s): " + "; ".join(errors), peer=self.peer)

    async def close(self) -> None:
        """Close the connection (outstanding calls fail with :class:`ConnectionLost`)."""
        writer, task = self._writer, self._read_task
        self._writer = self._reader = None
        self._read_task = None
        if writer is not None:
            writer.close()
            with contextlib.suppress(ConnectionError, OSError):
                await writer.wait_closed()
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        self._fail_pending(ConnectionLost("connection closed by the client", peer=self.peer))

    async def __aenter__(self) -> VPlusClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -------------------------------------------------------------------------- commands
    async def execute(self, *commands: CommandLike, timeout: float | None = None) -> list[Ack]:
        """Run commands one after the other: write a command's messages, await their acks, go on.

        ``timeout`` (default: the client's) bounds the wait for each command's acks.  Returns
        every ack in message order; raises :class:`VPlusError` with an :class:`Exchange`.
        """
        groups = [_group(c) for c in commands]
        async with self._lock:
            plan = [[Message(self._new_id(), c) for c in group] for group in groups]
            done: list[tuple[Message, Ack]] = []
            for i, messages in enumerate(plan):
                later = tuple(m for group in plan[i + 1 :] for m in group)
                done.extend(await self._exchange(messages, timeout, done, later))
            return [ack for _, ack in done]

    async def execute_joined(self, *commands: CommandLike, timeout: float | None = None) -> list[Ack]:
        """Write every message of every command at once, then await all acks (within ``timeout``)."""
        messages = [Message(self._new_id(), c) for group in map(_group, commands) for c in group]
        async with self._lock:
            return [ack for _, ack in await self._exchange(messages, timeout, [], ())]

    async def _exchange(
        self,
        messages: list[Message],
        timeout: float | None,
        before: list[tuple[Message, Ack]],
        later: tuple[Message, ...],
    ) -> list[tuple[Message, Ack]]:
        """Write ``messages`` in one write and await their acks; on failure, report everything."""
        if not messages:
            return []
        timeout = self.timeout if timeout is None else timeout
        if not self.connected or self._writer is None:
            reason = "not connected" + (f" ({self.last_failure})" if self.last_failure else "")
            raise ConnectionLost(reason, peer=self.peer, exchange=Exchange(tuple(before), (), (*messages, *later)))
        loop = asyncio.get_running_loop()
        futures = {m.id: loop.create_future() for m in messages}
        self._pending.update(futures)
        try:
            self._writer.write(encode_messages(messages))
            try:
                await self.clock.wait_for(self._all_acks(futures), timeout)
            except asyncio.TimeoutError:
                missing = [m for m in messages if not futures[m.id].done()]
                raise CommandTimeout(
                    f"no ack within {timeout:g} s for {len(missing)} message(s), first {missing[0]} "
                    "(the server acks neither unknown skills nor failed motions)",
                    peer=self.peer,
                ) from None
            return [(m, futures[m.id].result()) for m in messages]
        except VPlusError as error:
            acked = tuple((m, futures[m.id].result()) for m in messages if _acked(futures[m.id]))
            unknown = tuple(m for m in messages if not _acked(futures[m.id]))
            raise error.with_exchange(Exchange((*before, *acked), unknown, later)) from None
        finally:
            for m in messages:  # whatever is still outstanding: its ack may yet come, tolerate it
                if self._pending.pop(m.id, None) is not None and not _acked(futures[m.id]):
                    self._expire(m)
                future = futures[m.id]
                if not future.done():
                    future.cancel()
                elif not future.cancelled():
                    future.exception()  # retrieved: an error reported through the exchange is not "never retrieved"

    @staticmethod
    async def _all_acks(futures: dict[str, asyncio.Future[Ack]]) -> None:
        for future in futures.values():
            await asyncio.shield(future)

    def _new_id(self) -> str:
        for _ in range(100):
            msg_id = self._make_id()
            if msg_id not in self._pending and msg_id not in self._expired:
                return msg_id
        raise RuntimeError("the id generator keeps repeating ids in use")

    def _expire(self, message: Message) -> None:
        self._expired[message.id] = message
        while len(self._expired) > _EXPIRED_IDS:
            self._expired.popitem(last=False)

    # ----------------------------------------------------------------------------- reading
    async def _read_loop(self, reader: asyncio.StreamReader) -> None:
        """The one reader: split the stream into lines and hand each ack to its waiter."""
        splitter = LineSplitter(self.max_line)
        try:
            while True:
                data = await reader.read(_READ_SIZE)
                if not data:
                    self._link_down("the server closed the connection")
                    return
                try:
                    for line in splitter.feed(data):
                        self._on_line(line)
                except FrameError as error:
                    self._link_down(f"stream out of step: {error}")
                    return
        except asyncio.CancelledError:
            raise
        except (ConnectionError, OSError) as error:
            self._link_down(f"connection broke: {error}")
        except Exception as error:  # noqa: BLE001 - a reader defect must reach the callers, not vanish
            log.exception("V+ client %s: reader failed", self.peer)
            self._link_down(f"client reader failed: {type(error).__name__}: {error}", ProtocolError)

    def _on_line(self, line: bytes) -> None:
        try:
            ack = decode_ack(line)
        except DecodeError as error:
            self._fail_pending(ProtocolError(f"malformed ack: {error}", peer=self.peer))
            return
        future = self._pending.get(ack.id)
        if future is None:
            late = self._expired.pop(ack.id, None)
            if late is not None:
                self.last_ack = ack
                self.late_acks.append((late, ack))
                log.info("V+ server %s: late ack for %s", self.peer, late)
                return
            self._fail_pending(ProtocolError(f"ack for unknown id {ack.id!r}: {line!r}", peer=self.peer))
            return
        self.last_ack = ack
        if ack.status != "done":
            future.set_exception(ProtocolError(f"status {ack.status!r} for {ack.id}: {line!r}", peer=self.peer))
        elif not future.done():
            future.set_result(ack)

    def _link_down(self, reason: str, kind: type[VPlusError] = ConnectionLost) -> None:
        self.last_failure = reason
        log.warning("V+ server %s: %s", self.peer, reason)
        if self._writer is not None:
            self._writer.close()
        self._fail_pending(kind(reason, peer=self.peer))

    def _fail_pending(self, error: VPlusError) -> None:
        for future in self._pending.values():
            if not future.done():
                future.set_exception(error)


def _group(command: CommandLike) -> tuple[Command, ...]:
    if isinstance(command, Command):
        return (command,)
    group = tuple(command)
    if not group or not all(isinstance(c, Command) for c in group):
        raise TypeError(f"expected a Command or a non-empty sequence of Commands, got {command!r}")
    return group


def _acked(future: asyncio.Future[Ack]) -> bool:
    return future.done() and not future.cancelled() and future.exception() is None
