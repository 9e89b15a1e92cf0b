"""The whole ``python -m execution_engine`` program: the cell runner's commands plus the operator station's ``studio``.

The command line lives in :mod:`cell_runner.cli`, below the station, and so cannot import it;
this module, on top, hands the ``studio`` subcommand in.  ``execution_engine/__main__.py`` runs
:func:`main`; tests that drive every subcommand in-process call it too.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import IO

from cell_runner import cli
from operator_station.cli import add_parser, cmd_studio

STUDIO = cli.ExtraCommand("studio", add_parser, cmd_studio)


def build_parser() -> argparse.ArgumentParser:
    """The program's parser, every subcommand included."""
    return cli.build_parser((STUDIO,))


def main(argv: Sequence[str] | None = None, out: IO[str] = sys.stdout, err: IO[str] = sys.stderr) -> int:
    """Run the program on ``argv`` (default: the process's arguments); the exit code."""
    return cli.main(argv, out, err, (STUDIO,))
