"""The console's log: a warning that repeats is one line per kind and second, with its count.

A KUKA RSI run on a busy computer printed 519 WARNING lines, one per late reply the controller
counted, in a run that finished; the line that explained them was lost among them.  The handler
the CLI installs passes the first of each kind at once and then one counted line a second.  The
wall clock is a :class:`ManualWallClock`: nothing here sleeps.
"""
from __future__ import annotations

import io
import logging
import re

import pytest

from cell_runner import cli
from cell_runner.cli import main
from node_transport.console_log import FORMAT, ONCE, AggregatingHandler, ConsoleLog, kind_of
from node_transport.wall_clock import ManualWallClock

LATE = "%s: the controller counts %d late replies (IPOC %d)"


def console(wall: ManualWallClock) -> tuple[logging.Logger, io.StringIO, AggregatingHandler]:
    stream = io.StringIO()
    target = logging.StreamHandler(stream)
    target.setFormatter(logging.Formatter(FORMAT))
    handler = AggregatingHandler(target, 1.0, wall)
    logger = logging.getLogger("test_console_log.rsi")
    logger.propagate = False
    logger.handlers = [handler]
    logger.setLevel(logging.INFO)
    return logger, stream, handler


def lines(stream: io.StringIO) -> list[str]:
    return stream.getvalue().splitlines()


def test_a_flood_of_one_warning_is_one_line_a_second_with_its_count() -> None:
    wall = ManualWallClock()
    logger, stream, handler = console(wall)
    for late in range(1, 3 * 256 + 1):  # 256 late replies a second for 3 s (1/256 s is exact in binary)
        logger.warning(LATE, "kuka_rsi 127.0.0.1:0", late, 3741924000 + 4 * late)
        wall.advance(1 / 256)
    assert lines(stream) == [
        "WARNING test_console_log.rsi: kuka_rsi 127.0.0.1:0: the controller counts 1 late replies (IPOC 3741924004)",
        "WARNING test_console_log.rsi: kuka_rsi 127.0.0.1:0: the controller counts 256 late replies (IPOC 3741925024) (x255 in the last 1 s)",
        "WARNING test_console_log.rsi: kuka_rsi 127.0.0.1:0: the controller counts 512 late replies (IPOC 3741926048) (x256 in the last 1 s)",
        "WARNING test_console_log.rsi: kuka_rsi 127.0.0.1:0: the controller counts 768 late replies (IPOC 3741927072) (x256 in the last 1 s)",
    ]
    assert handler.held_total == 767
    handler.close()
    assert len(lines(stream)) == 4  # nothing was left to print


def test_what_is_held_when_the_command_ends_is_printed_with_the_time_it_covers() -> None:
    wall = ManualWallClock()
    logger, stream, handler = console(wall)
    for n in range(1, 6):
        logger.warning(LATE, "kuka", n, n)
        wall.advance(0.125)
    handler.close()
    assert lines(stream) == [
        "WARNING test_console_log.rsi: kuka: the controller counts 1 late replies (IPOC 1)",
        "WARNING test_console_log.rsi: kuka: the controller counts 5 late replies (IPOC 5) (x4 in the last 0.625 s)",
    ]


def test_a_held_count_is_printed_when_its_second_ends_even_if_nothing_else_is_logged() -> None:
    wall = ManualWallClock()
    logger, stream, _ = console(wall)
    for n in range(1, 6):
        logger.warning(LATE, "kuka", n, n)
    assert len(lines(stream)) == 1
    wall.advance(0.999)
    assert len(lines(stream)) == 1
    wall.advance(0.001)  # the window's timer fires on the wall clock
    assert lines(stream)[-1] == "WARNING test_console_log.rsi: kuka: the controller counts 5 late replies (IPOC 5) (x4 in the last 1 s)"
    wall.advance(1.0)  # a quiet window: the kind is forgotten, so the next one shows at once
    logger.warning(LATE, "kuka", 6, 6)
    assert lines(stream)[-1] == "WARNING test_console_log.rsi: kuka: the controller counts 6 late replies (IPOC 6)"


def test_different_warnings_are_never_merged_and_a_first_one_is_never_delayed() -> None:
    wall = ManualWallClock()
    logger, stream, _ = console(wall)
    logger.warning(LATE, "kuka", 1, 4)
    logger.warning("%s: could not end the KRL task cleanly: %s", "kuka", "timeout")
    logger.error(LATE, "kuka", 2, 8)  # another level is another kind
    logging.getLogger("test_console_log.other").handlers = []
    logger.info("RSI loop on %s:%d", "127.0.0.1", 49152)
    assert len(lines(stream)) == 4


def test_a_fact_marked_once_is_said_once_in_a_console_and_never_counted() -> None:
    wall = ManualWallClock()
    logger, stream, handler = console(wall)
    for _ in range(3):
        logger.warning("kss.xml sends no ASPos", extra={ONCE: True})
        wall.advance(5.0)
    logger.warning("kss.xml sends no RSol", extra={ONCE: True})
    handler.close()
    assert lines(stream) == ["WARNING test_console_log.rsi: kss.xml sends no ASPos", "WARNING test_console_log.rsi: kss.xml sends no RSol"]
    again, stream2, handler2 = console(ManualWallClock())  # another command's console says it again
    again.warning("kss.xml sends no ASPos", extra={ONCE: True})
    assert lines(stream2) == ["WARNING test_console_log.rsi: kss.xml sends no ASPos"]
    handler2.close()


def test_the_kind_masks_numbers_but_not_words() -> None:
    def record(msg: str, *args: object) -> logging.LogRecord:
        return logging.LogRecord("x", logging.WARNING, __file__, 1, msg, args, None)

    assert kind_of(record(LATE, "kuka", 3, 12)) == kind_of(record(LATE, "kuka", 517, 2068))
    assert kind_of(record("ignored a datagram from 127.0.0.1:40123")) == kind_of(record("ignored a datagram from 127.0.0.1:5999"))
    assert kind_of(record(LATE, "kuka", 3, 12)) != kind_of(record(LATE, "other robot", 3, 12))
    assert kind_of(record("%d of %d", "not", "numbers")) == ("x", logging.WARNING, "%d of %d")  # a record that cannot be formatted


def test_every_command_of_the_cli_logs_through_it_and_leaves_the_root_logger_as_it_was(monkeypatch: pytest.MonkeyPatch) -> None:
    """``main()`` installs the handler for its command and removes it again: a repeated warning of
    any module comes out as one counted line, on this command's own stream."""
    def noisy(args: object, out: object, err: object, extra: object = ()) -> int:
        for n in range(300):
            logging.getLogger("robot_bridges.kuka_rsi.backend").warning(LATE, "kuka_rsi 127.0.0.1:0 (simulated)", n + 1, n)
        return 0

    monkeypatch.setattr(cli, "dispatch", noisy)
    root = logging.getLogger()
    before = (list(root.handlers), root.level)
    out, err = io.StringIO(), io.StringIO()
    assert main(["functions"], out, err) == 0
    warnings = err.getvalue().splitlines()
    assert warnings[0] == "WARNING robot_bridges.kuka_rsi.backend: kuka_rsi 127.0.0.1:0 (simulated): the controller counts 1 late replies (IPOC 0)"
    assert len(warnings) == 2
    assert re.fullmatch(r".*: the controller counts 300 late replies \(IPOC 299\) \(x299 in the last [0-9.e-]+ s\)", warnings[1]), warnings[1]
    assert (list(root.handlers), root.level) == before


def test_console_log_sets_the_level_of_minus_v_and_puts_it_back() -> None:
    root = logging.getLogger()
    level = root.level
    stream = io.StringIO()
    with ConsoleLog(stream, verbose=True, wall_clock=ManualWallClock()):
        assert root.level == logging.INFO
        logging.getLogger("execution_engine.x").info("hello %d", 1)
    with ConsoleLog(stream, verbose=False, wall_clock=ManualWallClock()):
        logging.getLogger("execution_engine.x").info("not shown")
    assert root.level == level
    assert stream.getvalue() == "INFO execution_engine.x: hello 1\n"
