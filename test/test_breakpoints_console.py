"""Breakpoints from the terminal of ``run --interactive``: b, g (with the operation typed and Enter), c.

The keys reach the engine in its process, recorded with the key as their source; ``g`` is the one
key after which the console reads a line even at a terminal, so a number of several digits can be
typed; anything else stays one key, one command.
"""
from __future__ import annotations

import asyncio
import dataclasses
import io
from typing import Any

from app_builder import Cell, make_app
from hypothesis import given
from hypothesis import strategies as st

from cell_runner.operator_console import KeyDecoder, OperatorConsole
from node_transport.clock import Clock

OPS = [{"left_arm": ("move_to_joint_pose", "initial")} for _ in range(6)]


def test_after_g_a_terminal_reads_one_line_then_keys_again() -> None:
    decoder = KeyDecoder(True, frozenset({"g"}))
    assert decoder.feed(b"pg1") == ["p", "g"]
    assert decoder.feed(b"2\r") == ["12"]
    assert decoder.feed(b"rg\rt") == ["r", "g", "t"]  # an empty answer: nothing, keys again


@given(st.binary(max_size=300))
def test_a_key_decoder_asking_after_g_still_gives_keys_or_one_bounded_line(data: bytes) -> None:
    decoder = KeyDecoder(True, frozenset({"g"}))
    words = [w for i in range(0, len(data), 5) for w in decoder.feed(data[i:i + 5])]
    for before, word in zip([""] + words, words):
        if before == "g":
            assert 0 < len(word) <= 256 and word.isprintable()
        else:
            assert len(word) == 1 and word.isprintable() and not word.isspace()


def test_b_g_and_c_at_the_console_set_run_to_and_clear_recorded_with_their_keys(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, str]:
        cell = await Cell(clock, durations={"move_joints": 2.0}).start()
        engine = cell.deployment.engine
        screen = io.StringIO()
        console = OperatorConsole(cell.deployment.transport.create_node("operator_console"), screen, engine.operator_command, engine.breakpoint_command)
        app = make_app(OPS)
        app = dataclasses.replace(app, operations=tuple(dataclasses.replace(op, breakpoint=op.id == "6") for op in app.operations))
        run = asyncio.ensure_future(cell.run(app))
        await clock.sleep(1.0)  # operation 1 runs: the next is 2
        await console.handle_line("b")
        while engine.state != "paused":
            await clock.sleep(0.1)
        await console.handle_line("g")  # asks; the answer comes as one line
        await console.handle_line("4")
        while engine.state != "paused" or engine._operation is None or engine._operation.id != "4":
            await clock.sleep(0.1)
        await console.handle_line("c")  # the file's breakpoint before 6 goes too
        await console.handle_line("r")
        return await run, screen.getvalue()

    report, screen = run_sim(main)
    assert report.ok and [(h.operation, h.kind) for h in report.breakpoints] == [("2", "break"), ("4", "run_to")]
    assert [(a.command, a.target, a.source) for a in report.operator_actions] == [
        ("break", "2", "terminal console (key 'b')"),
        ("run_to", "4", "terminal console (key 'g')"),
        ("unbreak_all", "", "terminal console (key 'c')"),
        ("resume", "", "terminal console (key 'r')"),
    ]
    assert "toggle: ok - breakpoint set before operation 2 '2' (line 2)" in screen
    assert "run to which operation? its number (or id), then Enter" in screen
    assert "run_to: ok - running to operation 4 '4' (line 4): the run pauses before it" in screen
    assert "clear_all: ok - every breakpoint cleared (2 were set)" in screen
