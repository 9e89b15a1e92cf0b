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
from core_functions.catalog import Catalog
from operator_station.studio_options import add_parser


def cmd_studio(args: argparse.Namespace, catalog: Catalog, out: IO[str], err: IO[str]) -> int:
    """``studio``: the station, imported when it is asked for (the other subcommands start without it)."""
    from operator_station import cli as station  # slow to load: sessions and simulators load numpy, pinocchio and coal

    return station.cmd_studio(args, catalog, out, err)


STUDIO = cli.ExtraCommand("studio", add_parser, cmd_studio)


def build_parser() -> argparse.ArgumentParser:
    """The program's parser, every subcommand included."""
    return cli.build_parser((STUDIO,))


def main(argv: Sequence[str] | None = None, out: IO[str] = sys.stdout, err: IO[str] = sys.stderr) -> int:
    """Run the program on ``argv`` (default: the process's arguments); the exit code."""
    return cli.main(argv, out, err, (STUDIO,))
