"""``run --interactive``: at a terminal a key acts when it is pressed, and the terminal is given back.

The console read lines: an operator pressing ``s`` to stop the robot saw nothing happen until
Enter, and the prompt did not say so.  At a terminal (a pseudo-terminal here, as a terminal
emulator or ssh gives one) it is now in cbreak mode while the console reads it and restored as it
was afterwards -- after the run, after an exception, and at exit; anything else is read line by
line, and the prompt says which.  Waits are bounded and wait for the event they need, never for a
time.
"""
from __future__ import annotations

import asyncio
import io
import os
import pty
import subprocess
import sys
import termios
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cell_runner.cli import main
from cell_runner.operator_console import MAX_LINE, PROMPT_KEYS, PROMPT_LINES, KeyDecoder, OperatorConsole
from node_transport.clock import real_clock
from node_transport.local import LocalTransport

ROOT = Path(__file__).resolve().parents[1]
BOUND = 10.0  # s: the longest any wait below may take (each ends on the event it waits for)


@pytest.fixture
def terminal() -> Iterator[tuple[int, int]]:
    """A pseudo-terminal: (the keyboard's end, the end the console reads)."""
    keyboard, screen = pty.openpty()
    try:
        yield keyboard, screen
    finally:
        os.close(keyboard)
        os.close(screen)


class Commands:
    """The engine's side: records each command with its source, and wakes whoever waits for one."""

    def __init__(self) -> None:
        self.given: list[tuple[str, str]] = []
        self.arrived = asyncio.Event()

    async def __call__(self, command: str, source: str) -> tuple[bool, str]:
        self.given.append((command, source))
        self.arrived.set()
        return True, command


def console_for(commands: Commands, out: io.StringIO) -> OperatorConsole:
    transport = LocalTransport(real_clock().bind(asyncio.get_running_loop()))
    return OperatorConsole(transport.create_node("operator_console"), out, commands)


def test_at_a_terminal_one_key_acts_without_enter_and_the_terminal_is_given_back(terminal: tuple[int, int]) -> None:
    keyboard, screen = terminal
    before = termios.tcgetattr(screen)

    async def main() -> tuple[list[tuple[str, str]], str, list[Any]]:
        commands, out = Commands(), io.StringIO()
        console = console_for(commands, out)
        loop = asyncio.get_running_loop()
        with os.fdopen(os.dup(screen), "rb", buffering=0) as stream:
            assert console.attach_stdin(loop, stream)
            during = termios.tcgetattr(screen)
            os.write(keyboard, b"p")  # no Enter
            await asyncio.wait_for(commands.arrived.wait(), BOUND)
            console.detach_stdin(loop)
        return commands.given, out.getvalue(), during

    given, printed, during = asyncio.run(main())
    assert given == [("pause", "terminal console (key 'p')")]
    assert printed.splitlines()[0] == PROMPT_KEYS and "no Enter needed" in PROMPT_KEYS
    assert "pause: ok" in printed
    assert not during[3] & termios.ICANON and not during[3] & termios.ECHO and during[3] & termios.ISIG  # Ctrl-C still interrupts
    assert termios.tcgetattr(screen) == before


def test_keys_act_one_by_one_and_arrow_keys_are_not_commands(terminal: tuple[int, int]) -> None:
    keyboard, screen = terminal

    async def main() -> list[tuple[str, str]]:
        commands, out = Commands(), io.StringIO()
        console = console_for(commands, out)
        loop = asyncio.get_running_loop()
        with os.fdopen(os.dup(screen), "rb", buffering=0) as stream:
            console.attach_stdin(loop, stream)
            os.write(keyboard, b"\x1b[A\x1bOBr\r")  # up, down (both forms), r, Enter
            while len(commands.given) < 1:
                commands.arrived.clear()
                await asyncio.wait_for(commands.arrived.wait(), BOUND)
            os.write(keyboard, b"s")
            commands.arrived.clear()
            await asyncio.wait_for(commands.arrived.wait(), BOUND)
            console.detach_stdin(loop)
        return commands.given

    assert [c for c, _ in asyncio.run(main())] == ["resume", "stop"]


def test_the_terminal_is_given_back_when_the_run_ends_in_an_exception(terminal: tuple[int, int]) -> None:
    """The CLI detaches in a ``finally``; whatever escapes that too, the settings come back at exit."""
    keyboard, screen = terminal
    before = termios.tcgetattr(screen)
    child = (
        "import asyncio, sys\n"
        "from cell_runner.operator_console import OperatorConsole\n"
        "from node_transport.local import LocalTransport\n"
        "from node_transport.clock import real_clock\n"
        "async def main():\n"
        "    node = LocalTransport(real_clock().bind(asyncio.get_running_loop())).create_node('c')\n"
        "    console = OperatorConsole(node, sys.stdout, None)\n"
        "    assert console.attach_stdin(asyncio.get_running_loop())\n"
        "    print('attached', flush=True)\n"
        "    raise RuntimeError('a defect')\n"
        "asyncio.run(main())\n"
    )
    done = subprocess.run([sys.executable, "-c", child], stdin=screen, capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert "attached" in done.stdout and "RuntimeError: a defect" in done.stderr
    assert termios.tcgetattr(screen) == before


def test_not_at_a_terminal_the_console_reads_lines_and_says_so() -> None:
    read_end, write_end = os.pipe()

    async def main() -> tuple[list[tuple[str, str]], str]:
        commands, out = Commands(), io.StringIO()
        console = console_for(commands, out)
        loop = asyncio.get_running_loop()
        with os.fdopen(read_end, "rb", buffering=0) as stream:
            assert console.attach_stdin(loop, stream)
            os.write(write_end, b"p")  # a key without Enter is not a line yet
            os.write(write_end, b"\n" + b"x" * (MAX_LINE + 5) + b"\nstop\n")
            await asyncio.wait_for(commands.arrived.wait(), BOUND)
            while len(commands.given) < 2:
                commands.arrived.clear()
                await asyncio.wait_for(commands.arrived.wait(), BOUND)
            console.detach_stdin(loop)
        return commands.given, out.getvalue()

    try:
        given, printed = asyncio.run(main())
    finally:
        os.close(write_end)
    assert printed.splitlines()[0] == PROMPT_LINES and "and Enter" in PROMPT_LINES
    assert [c for c, _ in given] == ["pause", "stop"]  # the overlong line was dropped, not taken as 'x' (reset)


@given(st.binary(max_size=600), st.booleans())
def test_anything_typed_becomes_keys_or_bounded_lines(data: bytes, keys: bool) -> None:
    decoder = KeyDecoder(keys)
    words = [w for i in range(0, len(data), 7) for w in decoder.feed(data[i:i + 7])]  # arriving in pieces
    if keys:
        assert all(len(w) == 1 and w.isprintable() and not w.isspace() for w in words)
    else:
        assert all(0 < len(w) <= MAX_LINE and w.isprintable() for w in words)


def test_run_quiet_and_interactive_prints_the_alarm_question_and_one_key_answers_it(terminal: tuple[int, int], tmp_path: Path,
                                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """``run -q --interactive`` at a terminal: the alarm that waits for the operator is printed with its
    answers (quiet hides progress, never a question), and ``s`` -- no Enter -- answers it."""
    keyboard, screen = terminal
    before = termios.tcgetattr(screen)
    rivet = (ROOT / "apps_xml" / "rivet_installation.xml").read_text(encoding="utf-8")
    app = tmp_path / "alarm.xml"
    app.write_text(rivet.replace('cell="cells/rivet_cell.xml"', f'cell="{ROOT / "apps_xml" / "cells" / "rivet_cell.xml"}"')
                   .replace('<error_policy retries="1" action="safe_pose" safe_pose="initial"/>', '<error_policy action="alarm"/>'), encoding="utf-8")
    asked = threading.Event()

    class Screen(io.StringIO):
        def write(self, text: str) -> int:
            if "ALARM" in text:
                asked.set()
            return super().write(text)

    out, err = Screen(), io.StringIO()
    stdin = os.fdopen(os.dup(screen), "r")
    monkeypatch.setattr(sys, "stdin", stdin)
    result: list[int] = []
    worker = threading.Thread(target=lambda: result.append(main(
        ["run", str(app), "--speed", "max", "-q", "--interactive", "--no-check", "--fault", "right_arm:joint_limit@0.5",
         "--trajectory-db", str(tmp_path / "t.sqlite")], out, err)), daemon=True)
    try:
        worker.start()
        assert asked.wait(60.0), out.getvalue() + err.getvalue()
        os.write(keyboard, b"s")  # stop, without Enter
        worker.join(60.0)
        assert not worker.is_alive()
    finally:
        stdin.close()
    printed = out.getvalue()
    question = next(line for line in printed.splitlines() if "ALARM" in line)
    assert "engine  ALARM operation" in question and "to retry: key 'x'" in question and "to abort: key 's'" in question
    assert printed.splitlines()[0] == PROMPT_KEYS
    assert "-> Motion" not in printed  # still quiet: no progress lines
    assert result == [3], err.getvalue()  # stopped by the operator
    assert termios.tcgetattr(screen) == before
