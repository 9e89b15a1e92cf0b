"""The operator's keyboard during ``run``: pause, resume, stop, step, reset through the engine's services.

Commands go through the same ``/execution_engine/*`` services a ROS 2 operator panel would
call, so the console exercises the real control path.  Ctrl-C asks the engine to stop
(Table 2's stop: every moving group halts, then ErrorHandling, then Finish); a second Ctrl-C
abandons the run.
"""
from __future__ import annotations

import asyncio
import sys
from typing import IO

from execution_engine.transport.msgs import Trigger
from execution_engine.transport.port import Node, TransportError
from execution_engine.transport.wire import ENGINE_SERVICES, engine_service

HELP = "operator commands: p(ause) r(esume) s(top) t (step) x (reset alarm) h(elp)"
_KEYS = {"p": "pause", "pause": "pause", "r": "resume", "resume": "resume", "s": "stop", "stop": "stop",
         "t": "step", "step": "step", "x": "reset", "reset": "reset", "start": "start"}


class OperatorConsole:
    def __init__(self, node: Node, out: IO[str] = sys.stdout) -> None:
        self.node = node
        self.out = out
        self._clients = {c: node.create_client(Trigger, engine_service(c)) for c in ENGINE_SERVICES}

    async def command(self, name: str) -> str:
        """Call one engine service; the answer (or why it failed) for the console."""
        try:
            response = await self._clients[name].call(Trigger.Request(), timeout=10.0)
        except (TransportError, asyncio.TimeoutError) as error:
            return f"{name}: {error}"
        return f"{name}: {'ok' if response.success else 'refused'} - {response.message}"

    async def handle_line(self, line: str) -> None:
        word = line.strip().lower()
        if not word:
            return
        if word in ("h", "help", "?"):
            self.out.write(HELP + "\n")
            return
        name = _KEYS.get(word)
        if name is None:
            self.out.write(f"unknown command {word!r}; {HELP}\n")
            return
        self.out.write(await self.command(name) + "\n")
        self.out.flush()

    def attach_stdin(self, loop: asyncio.AbstractEventLoop) -> bool:
        """Read commands from stdin when it is a terminal; False when it is not."""
        if not sys.stdin.isatty():
            return False

        def readable() -> None:
            line = sys.stdin.readline()
            if line:
                loop.create_task(self.handle_line(line))

        loop.add_reader(sys.stdin.fileno(), readable)
        self.out.write(HELP + "\n")
        return True

    @staticmethod
    def detach_stdin(loop: asyncio.AbstractEventLoop) -> None:
        try:
            loop.remove_reader(sys.stdin.fileno())
        except (ValueError, OSError):
            pass
