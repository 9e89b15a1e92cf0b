"""Framed messages between the real-time loop and the application, never blocking the loop.

Rare or bulky things (a tool path to stream, "command done", "packets stopped") travel as
length-prefixed pickled tuples over a Unix stream socket pair.  The loop's end is non-blocking
both ways: it reads what has arrived after each reply, and an event it cannot send at once is
counted as dropped rather than waited for -- the application re-reads the shared records anyway.
"""
from __future__ import annotations

import pickle
import socket
import struct
from typing import Any

_LENGTH = struct.Struct("!I")
#: Largest message accepted (a tool path of ~1.4 million points).
MAX_MESSAGE = 64 * 1024 * 1024


class PipeClosed(ConnectionError):
    """The other end has gone."""


class FramedPipe:
    """One end of a message pipe."""

    def __init__(self, sock: socket.socket, *, blocking_send: bool) -> None:
        self.sock = sock
        self.sock.setblocking(False)
        self._blocking_send = blocking_send
        self._inbox = bytearray()
        self._outbox = bytearray()
        self.dropped = 0

    @staticmethod
    def pair() -> tuple[socket.socket, socket.socket]:
        return socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)

    def fileno(self) -> int:
        return self.sock.fileno()

    def send(self, message: tuple[Any, ...]) -> bool:
        """Queue ``message``; the loop's end drops it (and returns False) rather than wait."""
        data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        if len(data) > MAX_MESSAGE:
            raise ValueError(f"message of {len(data)} bytes exceeds {MAX_MESSAGE}")
        frame = _LENGTH.pack(len(data)) + data
        if self._blocking_send:
            self.sock.setblocking(True)
            try:
                self.sock.sendall(frame)
            except OSError as error:
                raise PipeClosed(str(error)) from None
            finally:
                self.sock.setblocking(False)
            return True
        if self._outbox:
            self.flush()
        if self._outbox:
            if len(self._outbox) > 1 << 20:
                self.dropped += 1
                return False
            self._outbox += frame
            return True
        try:
            sent = self.sock.send(frame)
        except BlockingIOError:
            sent = 0
        except OSError as error:
            raise PipeClosed(str(error)) from None
        if sent < len(frame):
            self._outbox += frame[sent:]
        return True

    def flush(self) -> None:
        """Push out what a full socket buffer held back (non-blocking end only)."""
        if not self._outbox:
            return
        try:
            sent = self.sock.send(self._outbox)
        except BlockingIOError:
            return
        except OSError as error:
            raise PipeClosed(str(error)) from None
        del self._outbox[:sent]

    def receive(self) -> list[tuple[Any, ...]]:
        """Every complete message that has arrived (empty if none); PipeClosed when the peer left."""
        while True:
            try:
                chunk = self.sock.recv(1 << 16)
            except BlockingIOError:
                break
            except OSError as error:
                raise PipeClosed(str(error)) from None
            if not chunk:
                if self._inbox:
                    break
                raise PipeClosed("the other end closed the pipe")
            self._inbox += chunk
            if len(chunk) < 1 << 16:
                break
        messages: list[tuple[Any, ...]] = []
        while len(self._inbox) >= _LENGTH.size:
            (size,) = _LENGTH.unpack_from(self._inbox)
            if size > MAX_MESSAGE:
                raise PipeClosed(f"corrupt frame of {size} bytes")
            if len(self._inbox) < _LENGTH.size + size:
                break
            payload = bytes(self._inbox[_LENGTH.size : _LENGTH.size + size])
            del self._inbox[: _LENGTH.size + size]
            messages.append(pickle.loads(payload))
        return messages

    def close(self) -> None:
        self.sock.close()
