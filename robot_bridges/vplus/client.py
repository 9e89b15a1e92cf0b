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
import math
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from node_transport.clock import Clock
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
_LISTED = 8  # messages named one by one in an error report
_EXPIRED_IDS = 4096  # ids given up on (timeout, cancel) whose late acks are expected and tolerated
_DEADLINE_SLACK = 1e-6  # s: a timer may fire a hair early (loop clock resolution)


# ------------------------------------------------------------------------------ reports
@dataclass(frozen=True)
class Exchange:
    """What became of the messages of one call when it failed."""

    acked: tuple[tuple[Message, Ack], ...] = ()
    unknown: tuple[Message, ...] = ()  # written, not acked: the controller may or may not have run them
    unsent: tuple[Message, ...] = ()  # never written: certainly not run

    def __str__(self) -> str:
        def names(msgs: Sequence[Message]) -> str:
            if len(msgs) > _LISTED:  # a joined batch can hold thousands: name the ends, count the rest
                return f"{len(msgs)} messages: {msgs[0]} ... {msgs[-1]}"
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
class _Batch:
    """The messages of one write and their acks, resolved when the last ack is in."""

    __slots__ = ("messages", "acks", "future", "timeout", "deadline")

    def __init__(self, messages: list[Message], future: asyncio.Future[None], timeout: float, deadline: float) -> None:
        self.messages = messages
        self.acks: dict[str, Ack] = {}
        self.future = future
        self.timeout = timeout
        self.deadline = deadline  # run time

    def fail(self, error: VPlusError) -> None:
        if not self.future.done():
            self.future.set_exception(error)


class Turn:
    """One call at a time, in the order they came: asyncio.Lock's contract, but entering a free
    turn is a plain call (the lock's three coroutines were a tenth of a round trip's Python).

    ``leave`` hands the turn to the first waiter still waiting; a waiter cancelled after it was
    handed the turn passes it on, so a cancellation never leaves the turn taken."""

    __slots__ = ("busy", "waiters")

    def __init__(self) -> None:
        self.busy = False
        self.waiters: deque[asyncio.Future[None]] = deque()

    def take_now(self) -> bool:
        """Take the turn if it is free and nobody waits; False otherwise (then ``await take()``)."""
        if self.busy or self.waiters:
            return False
        self.busy = True
        return True

    async def take(self) -> None:
        if self.take_now():
            return
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.waiters.append(waiter)
        try:
            await waiter
        except asyncio.CancelledError:
            if waiter.done() and not waiter.cancelled():
                self.leave()  # handed the turn, then cancelled: hand it on
            elif waiter in self.waiters:
                self.waiters.remove(waiter)
            raise

    def leave(self) -> None:
        while self.waiters:
            waiter = self.waiters.popleft()
            if not waiter.done():
                waiter.set_result(None)  # the turn passes on: still busy
                return
        self.busy = False


class ControllerLink(asyncio.Protocol):
    """The connection's protocol: hands each received line to the client as it arrives.

    A protocol, not a StreamReader plus reader task, so an ack reaches its waiter without an
    extra trip round the event loop -- the difference between 1.5x and 3x a raw echo.
    """

    def __init__(self, client: VPlusClient) -> None:
        self.client = client
        self.splitter = LineSplitter(client.max_line)
        self.transport: asyncio.Transport | None = None
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def data_received(self, data: bytes) -> None:
        try:
            for line in self.splitter.feed(data):
                self.client._on_line(line)
        except FrameError as error:
            self.client._link_down(self, f"stream out of step: {error}")
        except Exception as error:  # noqa: BLE001 - a client defect must reach the callers, not vanish
            log.exception("V+ client %s: failed on received data", self.client.peer)
            self.client._link_down(self, f"client failed on received data: {type(error).__name__}: {error}", ProtocolError)

    def eof_received(self) -> bool:
        self.client._link_down(self, "the server closed the connection")
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.client._link_down(self, f"connection broke: {exc}" if exc else "the connection closed")
        if not self.closed.done():
            self.closed.set_result(None)


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
        self._link: ControllerLink | None = None
        self._pending: dict[str, _Batch] = {}
        self._expired: OrderedDict[str, Message] = OrderedDict()
        self._turn = Turn()
        # One watchdog timer for all outstanding batches, re-armed only when a deadline comes
        # earlier than the one it waits for: a timer per command would cost more than the rest
        # of a round trip.
        self._waiting: set[_Batch] = set()
        self._watchdog: asyncio.TimerHandle | None = None
        self._watchdog_at = math.inf
        #: Acks that came after their call had given up (timeout, cancellation); newest last.
        self.late_acks: deque[tuple[Message, Ack]] = deque(maxlen=256)
        #: The most recent ack of any kind: where the robot last was.
        self.last_ack: Ack | None = None
        #: Why the connection last went down, for the report.
        self.last_failure: str = ""
        #: A line the server sent unasked on the current connection (a refusal, an idle close).
        self.server_said: str = ""

    @property
    def peer(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        link = self._link
        return link is not None and link.transport is not None and not link.transport.is_closing()

    # ------------------------------------------------------------------------ connection
    async def connect(self) -> None:
        """Connect, retrying ``retries`` times with exponential backoff; raises :class:`ConnectError`."""
        await self.close()
        loop = asyncio.get_running_loop()
        errors: list[str] = []
        delay = self.backoff
        for attempt in range(self.retries + 1):
            if attempt:
                await self.clock.sleep(delay)
                delay = min(delay * 2 or self.backoff, self.max_backoff)
            self.server_said = ""  # a refusal arrives before create_connection returns: keep it
            try:
                _, link = await self.clock.wait_for(
                    loop.create_connection(lambda: ControllerLink(self), self.host, self.port), self.connect_timeout
                )
            except asyncio.TimeoutError:
                errors.append(f"attempt {attempt + 1}: no answer within {self.connect_timeout:g} s")
            except OSError as error:
                errors.append(f"attempt {attempt + 1}: {error.strerror or error}")
            else:
                if link.transport is None or link.transport.is_closing() or link.closed.done():
                    # accepted and closed at once (every client slot taken): what the server said is the reason
                    said = f"; the server said: {self.server_said}" if self.server_said else ""
                    errors.append(f"attempt {attempt + 1}: the server closed the connection at once{said}")
                    continue
                self._link = link
                self.last_failure = ""
                log.info("connected to V+ server %s", self.peer)
                return
        raise ConnectError(f"cannot connect after {len(errors)} attempt(s): " + "; ".join(errors), peer=self.peer)

    async def close(self) -> None:
        """Close the connection (outstanding calls fail with :class:`ConnectionLost`)."""
        link, self._link = self._link, None
        if link is None or link.transport is None:
            return
        link.transport.close()
        with contextlib.suppress(asyncio.TimeoutError):
            await self.clock.wait_for(asyncio.shield(link.closed), 1.0)
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
        turn = self._turn
        if len(commands) == 1 and type(commands[0]) is Command:  # the common case: one message, one ack
            if not turn.take_now():
                await turn.take()
            try:  # _exchange inline (a coroutine less to enter and resume)
                message = Message(self._new_id(), commands[0])
                batch = self._send([message], timeout, [])
                try:
                    await batch.future
                    return [batch.acks[message.id]]
                except VPlusError as error:
                    raise self._failed(batch, error, [], []) from None
                finally:
                    self._settle(batch)
            finally:
                turn.leave()
        groups = [_group(c) for c in commands]
        if not turn.take_now():
            await turn.take()
        try:
            if len(groups) == 1:  # one command of several messages, without the bookkeeping of several commands
                return await self._exchange(self._messages(groups[0]), timeout, [], [])
            done: list[tuple[Message, Ack]] = []
            for i, group in enumerate(groups):
                messages = self._messages(group)
                done.extend(zip(messages, await self._exchange(messages, timeout, done, groups[i + 1 :])))
            return [ack for _, ack in done]
        finally:
            turn.leave()

    async def execute_joined(self, *commands: CommandLike, timeout: float | None = None) -> list[Ack]:
        """Write every message of every command at once, then await all acks (within ``timeout``)."""
        groups = [_group(c) for c in commands]
        turn = self._turn
        if not turn.take_now():
            await turn.take()
        try:
            messages = self._messages(c for group in groups for c in group)
            return await self._exchange(messages, timeout, [], [])
        finally:
            turn.leave()

    async def _exchange(
        self,
        messages: list[Message],
        timeout: float | None,
        before: list[tuple[Message, Ack]],
        later: list[tuple[Command, ...]],
    ) -> list[Ack]:
        """Write ``messages`` in one write and await their acks, in message order; on failure, report everything.

        ``before`` are the acks this call already has, ``later`` the commands it has yet to send:
        both go into the report if this exchange fails.
        """
        if not messages:
            return []
        batch = self._send(messages, timeout, before, later)
        try:
            await batch.future
            acks = batch.acks
            return [acks[m.id] for m in messages]
        except VPlusError as error:
            raise self._failed(batch, error, before, later) from None
        finally:
            self._settle(batch)

    def extend(self, seconds: float) -> None:
        """Give every call waiting for acks ``seconds`` more: the operator's speed override slowed (or holds) the
        motion they wait for (robot_bridges/vplus/monitor.py); a call's error names its whole allowance."""
        for batch in self._waiting:
            batch.deadline += seconds
            batch.timeout += seconds

    def _send(
        self, messages: list[Message], timeout: float | None, before: list[tuple[Message, Ack]], later: list[tuple[Command, ...]] | None = None,
    ) -> _Batch:
        """Register ``messages`` as in flight and write them in one write: their batch to await."""
        timeout = self.timeout if timeout is None else timeout
        link = self._link
        transport = link.transport if link is not None else None
        if transport is None or transport.is_closing():
            reason = "not connected" + (f" ({self.last_failure})" if self.last_failure else "")
            unsent = (*messages, *self._unsent(later or []))
            raise ConnectionLost(reason, peer=self.peer, exchange=Exchange(tuple(before), (), unsent))
        batch = _Batch(messages, asyncio.get_running_loop().create_future(), timeout, self.clock.now() + timeout)
        pending = self._pending
        for m in messages:
            pending[m.id] = batch
        if batch.deadline < self._watchdog_at:
            self._watch(batch)
        else:
            self._waiting.add(batch)  # the watchdog is set for an earlier deadline: it looks at this batch then
        try:
            transport.write(messages[0].encode() if len(messages) == 1 else encode_messages(messages))
        except BaseException:
            self._settle(batch)
            raise
        return batch

    def _failed(self, batch: _Batch, error: VPlusError, before: list[tuple[Message, Ack]], later: list[tuple[Command, ...]]) -> VPlusError:
        """``error`` with the report of what became of every message of the call."""
        messages = batch.messages
        acked = tuple((m, batch.acks[m.id]) for m in messages if m.id in batch.acks)
        unknown = tuple(m for m in messages if m.id not in batch.acks)
        return error.with_exchange(Exchange((*before, *acked), unknown, self._unsent(later)))

    def _settle(self, batch: _Batch) -> None:
        """The batch is no longer awaited: messages still without an ack may have their ack yet; tolerate it then."""
        self._waiting.discard(batch)
        messages = batch.messages
        if not batch.future.done() or len(batch.acks) < len(messages):
            pending = self._pending
            for m in messages:
                if pending.get(m.id) is batch:
                    del pending[m.id]
                    self._expire(m)

    def _unsent(self, later: list[tuple[Command, ...]]) -> tuple[Message, ...]:
        """Messages for commands never written (ids for the report only: nothing was sent)."""
        return tuple(self._messages(c for group in later for c in group))

    def _watch(self, batch: _Batch) -> None:
        self._waiting.add(batch)
        if batch.deadline < self._watchdog_at:
            if self._watchdog is not None:
                self._watchdog.cancel()
            self._watchdog_at = batch.deadline
            self._watchdog = self.clock.call_later(batch.deadline - self.clock.now(), self._on_watchdog)

    def _on_watchdog(self) -> None:
        self._watchdog, self._watchdog_at = None, math.inf
        now = self.clock.now()
        for batch in [b for b in self._waiting if b.deadline <= now + _DEADLINE_SLACK]:
            self._waiting.discard(batch)
            missing = [m for m in batch.messages if m.id not in batch.acks]
            if not missing or batch.future.done():
                continue  # its last ack came in the same loop pass as its deadline: it made it
            batch.fail(
                CommandTimeout(
                    f"no ack within {batch.timeout:g} s for {len(missing)} message(s), first {missing[0]} "
                    "(the server acks neither unknown skills nor failed motions)",
                    peer=self.peer,
                )
            )
        if self._waiting:
            earliest = min(self._waiting, key=lambda b: b.deadline)
            self._watchdog_at = earliest.deadline
            self._watchdog = self.clock.call_later(earliest.deadline - now, self._on_watchdog)

    def _new_id(self, taken: set[str] | None = None) -> str:
        """A fresh id: not in flight, not expired, and not ``taken`` by another message of the same batch."""
        for _ in range(100):
            msg_id = self._make_id()
            if msg_id not in self._pending and msg_id not in self._expired and (taken is None or msg_id not in taken):
                if taken is not None:
                    taken.add(msg_id)
                return msg_id
        raise RuntimeError("the id generator keeps repeating ids in use")

    def _messages(self, commands: Iterable[Command]) -> list[Message]:
        """One message per command, with ids unique within the batch too (32-bit random ids collide in large batches)."""
        taken: set[str] = set()
        return [Message(self._new_id(taken), c) for c in commands]

    def _expire(self, message: Message) -> None:
        self._expired[message.id] = message
        while len(self._expired) > _EXPIRED_IDS:
            self._expired.popitem(last=False)

    # ----------------------------------------------------------------------------- reading
    def _on_line(self, line: bytes) -> None:
        try:
            ack = decode_ack(line)
        except DecodeError as error:
            if not self._pending or not self._answers_a_message(line):
                # not an ack of anything asked: the server speaks, e.g. to refuse us or to close an idle
                # link; it closes the connection next, and the loss is reported with these words
                self.server_said = line.decode("utf-8", "replace")[:200]
                log.warning("V+ server %s says: %s", self.peer, self.server_said)
                return
            self._fail_pending(ProtocolError(f"malformed ack: {error}", peer=self.peer))
            return
        batch = self._pending.pop(ack.id, None)
        if batch is None:
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
            batch.fail(ProtocolError(f"status {ack.status!r} for {ack.id}: {line!r}", peer=self.peer))
            return
        batch.acks[ack.id] = ack
        if len(batch.acks) == len(batch.messages) and not batch.future.done():
            batch.future.set_result(None)

    def _answers_a_message(self, line: bytes) -> bool:
        """Whether ``line`` (not a well-formed ack) starts with the id of a message sent: a garbled ack."""
        head = line.split(b":", 1)[0].decode("ascii", "replace").strip()
        return head in self._pending or head in self._expired

    def _link_down(self, link: ControllerLink, reason: str, kind: type[VPlusError] = ConnectionLost) -> None:
        if link is not self._link:
            return  # an old connection finishing its close
        if self.server_said:
            reason = f"{reason}; the server said: {self.server_said}"
        if not self.last_failure:
            self.last_failure = reason
            log.warning("V+ server %s: %s", self.peer, reason)
        if link.transport is not None:
            link.transport.close()
        self._fail_pending(kind(reason, peer=self.peer))

    def _fail_pending(self, error: VPlusError) -> None:
        for batch in set(self._pending.values()):
            batch.fail(error)


def _group(command: CommandLike) -> tuple[Command, ...]:
    if isinstance(command, Command):
        return (command,)
    group = tuple(command)
    if not group or not all(isinstance(c, Command) for c in group):
        raise TypeError(f"expected a Command or a non-empty sequence of Commands, got {command!r}")
    return group
