"""The operator's keyboard during ``run``: start, pause, resume, step, stop, reset; breakpoints and run to here.

Run in the engine's own process (``run --interactive``), the console hands each command to
:meth:`ExecutionEngine.operator_command` naming itself as the source -- "terminal console (key
'p')" -- so the trace and the run report tell a key pressed at this terminal from a call of the
``/execution_engine/*`` services by another tool, which the engine records under the service's
name.  (A Trigger request carries no caller, so the services cannot tell callers apart.)
Without an engine at hand the console calls those same services.  Ctrl-C asks the engine to
stop (Table 2's stop: every moving group halts, then ErrorHandling, then Finish); a second
Ctrl-C abandons the run.

At a terminal a key acts the moment it is pressed: an operator who presses ``s`` to stop a robot
must not also have to find Enter.  The terminal is put in cbreak mode (keys one by one, not
echoed; Ctrl-C still interrupts) for as long as the console reads it, and put back as it was when
the console lets go -- at the end of the run, on Ctrl-C, on an exception, and at exit.  Anything
else (a pipe, a file) is read line by line.  The prompt says which of the two it is.

Breakpoints (engine/breakpoints.py): ``b`` toggles one on the next operation to start, ``g`` asks
which operation to run to (its number as the status counts them, or its id, then Enter: the one
question the console asks, read as a line even at a terminal) and ``c`` clears them all; in line
mode ``b 5`` and ``g 7`` name the operation at once.  Continue is ``r``, step ``t``.

The speed override (engine/speed.py): ``+`` and ``-`` raise and lower it by :data:`SPEED_STEP` percent (never
above 100 %: the application's own speed), ``%`` asks for a value (then Enter; ``% 50`` in line mode); ``-`` down
to 0 % holds every motion on its path, ``+`` goes on from there.  The engine records each with the key as source.
"""
from __future__ import annotations

import asyncio
import atexit
import codecs
import contextlib
import os
import sys
from collections.abc import Awaitable, Callable, Coroutine
from typing import IO, Any, Protocol

from execution_engine.engine.breakpoints import BREAKPOINT_SERVICE, RUN_TO_SERVICE, BreakpointService, RunToService
from execution_engine.engine.operator import CONSOLE_KEYS, console_source
from node_transport.msgs import Trigger
from node_transport.port import Node, TransportError
from node_transport.wire import ENGINE_SERVICES, engine_service

try:  # POSIX terminals; elsewhere the console reads lines
    import termios
    import tty
except ImportError:  # pragma: no cover - not on the platforms this runs on
    termios = None  # type: ignore[assignment]
    tty = None  # type: ignore[assignment]

#: ``(command, source) -> (accepted, answer)``: the engine's own entry for operator commands.
Commander = Callable[[str, str], Awaitable[tuple[bool, str]]]
#: ``(action, operation, source) -> (accepted, answer)``: the engine's entry for breakpoints (engine/breakpoints.py).
BreakCommander = Callable[[str, str, str], Awaitable[tuple[bool, str]]]
#: Breakpoint keys: b toggles a breakpoint on the next operation (``b N`` on operation N), g asks for an
#: operation and runs to it (``g N`` at once), c clears every breakpoint; continue and step are r and t.
BREAK_KEYS = {"b": "toggle", "g": "run_to", "c": "clear_all"}
#: Speed override keys: + and - change it by SPEED_STEP percent, % asks for a value.
SPEED_KEYS = ("+", "-", "%")
#: The key that edits the paused run: it asks for the edited application's file (``e FILE`` in line mode).
EDIT_KEY = "e"
#: ``(file, source) -> lines``: run's edit of the paused run from a file (cell_runner/console_edit.py).
Editor = Callable[[str, str], Awaitable[list[str]]]
SPEED_STEP = 10.0


class SpeedControl(Protocol):
    """The engine's speed override (execution_engine/engine/speed.py)."""

    percent: float

    def set(self, percent: object, source: str) -> tuple[bool, str]: ...


KEY_LIST = (" ".join(f"{key} ({command})" for command, key in CONSOLE_KEYS.items())
            + " b (breakpoint on the next operation) g (run to an operation) c (clear breakpoints)"
            + f" +/- (speed override {SPEED_STEP:g} % up/down) % (speed override: type it) e (edit the paused run: its file) h (help)")
HELP = "operator commands: " + KEY_LIST
PROMPT_KEYS = f"operator keys, no Enter needed: {KEY_LIST}"
PROMPT_LINES = f"operator commands, type a key (or the command's name) and Enter: {KEY_LIST}"
_KEYS = {**{key: command for command, key in CONSOLE_KEYS.items()}, **{c: c for c in ENGINE_SERVICES}}

READ_BYTES = 256  # read at most this much per wake of the loop
MAX_LINE = 256  # characters of a typed line; a longer one is dropped whole
MAX_PENDING = 8  # commands in flight at once; keys beyond that are ignored (a held-down key)


class KeyDecoder:
    """Bytes from the keyboard to operator words: one per key (a terminal in cbreak mode) or per line.

    Escape sequences (arrow and function keys) and control characters are dropped, a line longer
    than :data:`MAX_LINE` is dropped whole, and bytes that are not UTF-8 become U+FFFD (an
    unknown command), so nothing typed can grow memory or be taken for another key.
    """

    def __init__(self, keys: bool, line_after: frozenset[str] = frozenset()) -> None:
        """``line_after``: keys after which one line is read (up to Enter) before keys again: an answer to a question."""
        self.keys = keys
        self.line_after = line_after
        self._in_line = False
        self._decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        self._line: list[str] = []
        self._overlong = False
        self._escape = ""  # "" | "esc" (after ESC) | "csi" (after ESC [ or ESC O)

    def feed(self, data: bytes) -> list[str]:
        words: list[str] = []
        for char in self._decoder.decode(data):
            if self._skip_escape(char):
                continue
            if self.keys and not self._in_line:
                if char.isprintable() and not char.isspace():
                    words.append(char)
                    self._in_line = char in self.line_after
                continue
            if self._in_line and char in "\r\n":
                self._in_line = False
            self._take_line_char(char, words)
        return words

    def _skip_escape(self, char: str) -> bool:
        if char == "\x1b":
            self._escape = "esc"
            return True
        if self._escape == "esc":
            self._escape = "csi" if char in "[O" else ""
            return True
        if self._escape == "csi":
            if "\x40" <= char <= "\x7e":
                self._escape = ""
            return True
        return False

    def _take_line_char(self, char: str, words: list[str]) -> None:
        if char in "\r\n":
            if self._line and not self._overlong:
                words.append("".join(self._line))
            self._line, self._overlong = [], False
        elif self._overlong or not char.isprintable():
            return
        elif len(self._line) >= MAX_LINE:
            self._line, self._overlong = [], True
        else:
            self._line.append(char)


class OperatorConsole:
    def __init__(
        self, node: Node, out: IO[str] = sys.stdout, commander: Commander | None = None, breaks: BreakCommander | None = None,
        speed: SpeedControl | None = None,
    ) -> None:
        self.node = node
        self.speed = speed
        self.out = out
        self.commander = commander
        self.breaks = breaks
        self._clients = {c: node.create_client(Trigger, engine_service(c)) for c in ENGINE_SERVICES}
        self._break_clients = (node.create_client(BreakpointService, BREAKPOINT_SERVICE), node.create_client(RunToService, RUN_TO_SERVICE))
        self._asking: str | None = None  # after g: the next word names the operation to run to
        self.editor: Editor | None = None  # the edit of the paused run, when the engine is in this process (set by run)
        self._tasks: set[asyncio.Task[Any]] = set()
        self._fd: int | None = None
        self._saved: tuple[int, list[Any]] | None = None  # the terminal's settings to put back

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

    async def breakpoint(self, action: str, operation: str, key: str) -> str:
        """A breakpoint command (:data:`BREAK_KEYS`); the answer for the console."""
        if self.breaks is not None:
            ok, message = await self.breaks(action, operation, console_source(key))
        else:
            breaks, run_to = self._break_clients
            try:
                if action == "run_to":
                    response = await run_to.call(RunToService.Request(operation=operation), timeout=10.0)
                else:
                    response = await breaks.call(BreakpointService.Request(operation=operation, action=action), timeout=10.0)
            except (TransportError, asyncio.TimeoutError) as error:
                return f"{action}: {error}"
            ok, message = response.success, response.message
        return f"{action}: {'ok' if ok else 'refused'} - {message}"

    async def handle_line(self, line: str) -> None:
        typed = line.strip()
        word = typed.lower()
        if not word:
            return
        asking, self._asking = self._asking, None
        if asking == "speed":  # the answer to "speed override?"
            self._say(self.change_speed("%", typed))
            return
        head, _, argument = typed.partition(" ")
        if asking == "edit" or head.lower() == EDIT_KEY:  # the answer to "which file?", or e FILE
            file = typed if asking == "edit" else argument.strip()
            if asking != "edit" and not file:
                self._asking = "edit"
                self._say("edit the paused run: the edited application's file, then Enter")
                return
            self._say("\n".join(await self.edit(file)))
            return
        if asking is not None:  # the answer to "run to which operation?" (a lone key other than a digit: not an answer)
            if len(word) > 1 or word.isdigit():
                self.out.write(await self.breakpoint("run_to", typed, "g") + "\n")
                self.out.flush()
                return
        head, _, argument = typed.partition(" ")
        if head in SPEED_KEYS:
            if head == "%" and not argument.strip():
                self._asking = "speed"
                self._say("speed override in percent of the application's speed (0-100; 0 holds on the path), then Enter")
            else:
                self._say(self.change_speed(head, argument.strip()))
            return
        if head.lower() in BREAK_KEYS:
            action = BREAK_KEYS[head.lower()]
            if action == "run_to" and not argument.strip():
                self._asking = "run_to"
                self.out.write("run to which operation? its number (or id), then Enter\n")
                self.out.flush()
                return
            self.out.write(await self.breakpoint(action, argument.strip(), head.lower()) + "\n")
            self.out.flush()
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

    async def edit(self, file: str) -> list[str]:
        """Edit the paused run from ``file`` (cell_runner/console_edit.py): the lines to show."""
        if self.editor is None:
            return ["edit: the engine runs in another process: edit the paused run where it was started (run --interactive, or the studio)"]
        return await self.editor(file, console_source(EDIT_KEY))

    def change_speed(self, key: str, typed: str = "") -> str:
        """``+``/``-``: the override a step up or down; ``%``: the value typed.  The engine's answer for the console."""
        if self.speed is None:
            return "speed: no engine in this process; set its parameter: ros2 param set /execution_engine speed_override P"
        now = self.speed.percent
        if key == "%":
            try:
                value: object = float(typed.removesuffix("%").strip())
            except ValueError:
                return f"speed: refused - {typed!r} is no percentage; type 0 to 100, then Enter"
        else:
            value = min(100.0, now + SPEED_STEP) if key == "+" else max(0.0, now - SPEED_STEP)
        ok, answer = self.speed.set(value, console_source(key))
        return f"speed: {'ok' if ok else 'refused'} - {answer}"

    def _say(self, text: str) -> None:
        self.out.write(text + "\n")
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

    def attach_stdin(self, loop: asyncio.AbstractEventLoop, stream: IO[Any] | None = None) -> bool:
        """Read commands from ``stream`` (stdin): key by key at a terminal, line by line otherwise.

        Prints the prompt, which says which.  False when there is nothing to read from.
        """
        stream = sys.stdin if stream is None else stream
        try:
            fd = stream.fileno()
        except (AttributeError, ValueError, OSError):
            return False
        keys = self._cbreak(fd)
        decoder = KeyDecoder(keys, frozenset({"g", "%", EDIT_KEY}))  # g asks for an operation, % for a speed, e for a file: typed with Enter

        def readable() -> None:
            try:
                data = os.read(fd, READ_BYTES)
            except BlockingIOError:
                return
            except OSError as error:
                data = b""
                self.out.write(f"console: cannot read the terminal ({error.strerror or error}); operator keys are off\n")
            if not data:  # end of input: nobody types here any more
                self.detach_stdin(loop)
                return
            for word in decoder.feed(data):
                if len(self._tasks) >= MAX_PENDING:
                    self.out.write(f"console: {len(self._tasks)} commands still being carried out; {word!r} ignored\n")
                    continue
                self.spawn(self.handle_line(word), loop)

        loop.add_reader(fd, readable)
        self._fd = fd
        self.out.write((PROMPT_KEYS if keys else PROMPT_LINES) + "\n")
        self.out.flush()
        return True

    def detach_stdin(self, loop: asyncio.AbstractEventLoop) -> None:
        """Stop reading, and give the terminal back as it was."""
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(ValueError, OSError):
                loop.remove_reader(fd)
        self.restore_terminal()

    def restore_terminal(self) -> None:
        """The terminal's settings from before :meth:`attach_stdin` (at once; also run at exit)."""
        saved, self._saved = self._saved, None
        if saved is None:
            return
        atexit.unregister(self.restore_terminal)
        fd, attributes = saved
        with contextlib.suppress(OSError, termios.error if termios is not None else OSError):
            termios.tcsetattr(fd, termios.TCSADRAIN, attributes)

    def _cbreak(self, fd: int) -> bool:
        """Put the terminal ``fd`` in cbreak mode; False (line mode) when it is no terminal or refuses."""
        if termios is None or not os.isatty(fd):
            return False
        try:
            attributes = termios.tcgetattr(fd)
            tty.setcbreak(fd, termios.TCSANOW)
        except (termios.error, OSError):
            return False
        self._saved = (fd, attributes)
        atexit.register(self.restore_terminal)  # a run that dies past every finally still gives the terminal back
        return True
