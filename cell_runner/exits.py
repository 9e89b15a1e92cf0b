"""The program's exit codes (the command line's docstring says when each is given) and the traceback a developer asks for.

A module of its own so the subcommands' modules, which the command line imports only when their
subcommand runs, give the same codes without importing the command line back.
"""
from __future__ import annotations

import traceback
from typing import IO

EXIT_OK, EXIT_INVALID, EXIT_USAGE, EXIT_STOPPED, EXIT_OUTPUT, EXIT_PEER, EXIT_INTERNAL = 0, 1, 2, 3, 4, 5, 70


def explain(error: BaseException, verbose: bool, err: IO[str]) -> None:
    """The traceback, for a developer, only with ``-v``."""
    if verbose:
        traceback.print_exception(error, file=err)
