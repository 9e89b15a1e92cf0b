"""Editing the paused run from the terminal of ``run --interactive``: key ``e``, then the edited application's file.

The studio's builder is one way to edit a paused run; an integrator at the cell's terminal has the file in an editor
instead.  ``e`` asks for the file (read as a line, then Enter; ``e FILE`` in line mode): it is read and validated as
``validate`` reads it, then handed to the engine, which swaps the operations not yet started for the file's only when
the run is paused, the done and running ones are unchanged and the dry run of the new remainder from where the robot
is finds nothing (:mod:`execution_engine.engine.remainder_swap`, the check of :mod:`cell_runner.dry_run.remainder`).
Whatever is refused is said in lines (the validator's ``FILE:LINE:COL`` messages, the dry run's findings, the
engine's one line) and changes nothing.  The checkpoint of the run follows a swap (it then names the edited file,
which ``run --resume`` needs).
"""
from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any

from cell_runner.dry_run.remainder import remainder_check
from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.dry_run.start import backend_measure, backend_source
from execution_engine.app_model import Application, Diagnostic, read_application
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.remainder_swap import PresentState, RemainderCheck, swap_remainder
from node_transport.clock import Clock

#: ``(file, source) -> lines for the console``: the edit of the paused run from a file.
Editor = Callable[[str, str], Awaitable[list[str]]]


async def _unchecked(new: Application, state: PresentState) -> Sequence[Diagnostic]:
    """``run --no-check``: the edit is swapped in unchecked, as the run started unchecked."""
    return ()


def console_editor(engine: ExecutionEngine, app: Application, backend: Any, clock: Clock, setup: DryRunSetup | None, trajectory_db: str | None) -> Editor:
    """The editor ``run`` gives its console: ``setup`` None (``--no-check``) swaps edits in without the dry run."""
    check: RemainderCheck = _unchecked if setup is None else remainder_check(
        setup, trajectory_db, backend_measure(app.robot, backend, backend_source(backend)), clock)

    async def edit(file: str, source: str) -> list[str]:
        path = Path(file).expanduser()
        if not file:
            return ["edit: name the edited application's file (e FILE)"]
        if not path.is_file():
            return [f"edit: {file}: no such file; nothing changed"]
        with clock.held():  # reading a long application takes a moment: simulated time waits for it
            new, diagnostics = await asyncio.to_thread(read_application, path, engine.catalog)
        if new is None:
            return [*map(str, diagnostics), f"edit: {file}: not swapped: {len(diagnostics)} problem(s); nothing changed"]
        answer = await swap_remainder(engine, new, check, str(path), source)
        return [*map(str, answer.findings), answer.message]

    return edit
