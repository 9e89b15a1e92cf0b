"""The operator's keyboard during ``run``: start, pause, resume, step, stop, reset.

Run in the engine's own process (``run --interactive``), the console hands each command to
:meth:`ExecutionEngine.operator_command` naming itself as the source -- "terminal console (key
'p')" -- so the trace and the run report tell a key pressed at this terminal from a call of the
``/execution_engine/*`` services by another tool, which the engine records under the service's
name.  (A Trigger request carries no caller, so the services cannot tell callers apart.)
Without an engine at hand the console calls those same services.  Ctrl-C asks the engine to
stop (Table 2's stop: every moving group halts, then ErrorHandling, then Finish); a second
Ctrl-C abandons the run.
"""
from __future__ import annotations

import asyncio
import sys
from collections.abc import Awaitable, Callable, Coroutine
from typing import IO, Any

from execution_engine.engine.operator import CONSOLE_KEYS, console_source
from execution_engine.transport.msgs import Trigger
from execution_engine.transport.port import Node, TransportError
from execution_engine.transport.wire import ENGINE_SERVICES, engine_service

#: ``(command, source) -> (accepted, answer)``: the engine's own entry for operator commands.
Commander = Callable[[str, str], Awaitable[tuple[bool, str]]]

HELP = "operator commands: " + " ".join(f"{key} ({command})" for command, key in CONSOLE_KEYS.items()) + " h (help)"
_KEYS = {**{key: command for command, key in CONSOLE_KEYS.items()}, **{c: c for c in ENGINE_SERVICES}}


class OperatorConsole:
    def __init__(self, node: Node, out: IO[str] = sys.stdout, commander: Commander | None = None) -> None:
        self.node = node
        self.out = out
        self.commander = commander
        self._clients = {c: node.create_client(Trigger, engine_service(c)) for c in ENGINE_SERVICES}
        self._tasks: set[asyncio.Task[Any]] = set()

    async def command(self, name: str, key: str | None = None) -> str:
        """Give one command; the answer (or why it failed) for the console.

        ``key`` is what the operator typed (or "Ctrl-C"); it names the source in the trace.
        """
        if self.commander is not None:
            ok, message = await self.commander(name, console_source(key or name))
        else:
            try:
                response = await self._clients[name].call(Trigger.Request(), timeout=10.0)
            except (TransportError, asyncio.TimeoutError) as error:
                return f"{name}: {error}"
            ok, message = response.success, response.message
        return f"{name}: {'ok' if ok else 'refused'} - {message}"

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
        self.out.write(await self.command(name, word) + "\n")
        self.out.flush()

    def spawn(self, work: Coroutine[Any, Any, Any], loop: asyncio.AbstractEventLoop) -> None:
        """Run a command in the background (a typed line, Ctrl-C); a failure is reported, not lost."""
        task = loop.create_task(work)
        self._tasks.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[Any]) -> None:
        self._tasks.discard(task)
        error = None if task.cancelled() else task.exception()
        if error is not None:
            self.node.report_fault("operator console", error)
            self.out.write(f"console: the command failed: {type(error).__name__}: {error}\n")

    def attach_stdin(self, loop: asyncio.AbstractEventLoop) -> bool:
        """Read commands from stdin when it is a terminal; False when it is not."""
        if not sys.stdin.isatty():
            return False

        def readable() -> None:
            line = sys.stdin.readline()
            if line:
                self.spawn(self.handle_line(line), loop)

        loop.add_reader(sys.stdin.fileno(), readable)
        self.out.write(HELP + "\n")
        return True

    @staticmethod
    def detach_stdin(loop: asyncio.AbstractEventLoop) -> None:
        try:
            loop.remove_reader(sys.stdin.fileno())
        except (ValueError, OSError):
            pass
