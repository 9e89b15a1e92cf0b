"""The station's side of editing a paused run: the run an edit goes to, and where the findings land in the builder.

The station's run lives on its own thread and loop (:mod:`operator_station.session`); an edit arrives on the
web server's.  :class:`EditTarget` is what the session leaves for it while a run is going: the run's loop,
its engine, and the check an edit must pass -- the dry run of the new remainder from where the robot is
(:func:`cell_runner.dry_run.remainder.remainder_check`, from the back end's joints as the Start's check), or
none when the station runs with ``--no-check``, as its Start does.  The swap itself is the engine's
(:func:`execution_engine.engine.remainder_swap.swap_remainder`), on the run's loop.

The findings are diagnostics at lines of the edited application as the builder writes it, so they are placed
at their cells through the same line map as the validator's messages (:func:`placer`).
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cell_runner.dry_run.remainder import remainder_check
from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.dry_run.start import backend_measure, backend_source
from core_functions.catalog import Catalog
from execution_engine.app_model import Application, Diagnostic
from execution_engine.app_model.model import Operation
from execution_engine.app_model.document import AppDocument, serialize
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.remainder_groups import bare_wait
from execution_engine.engine.remainder_swap import PresentState, RemainderCheck, SwapAnswer, swap_remainder
from node_transport.clock import Clock
from operator_station.blocks import BlockDocument
from operator_station.blocks_xml import write_blocks
from operator_station.builder import PlacedMessage, place, place_steps

#: Wall seconds an edit may take on the run's loop (the dry run of a long remainder included).
EDIT_TIMEOUT = 120.0


async def _unchecked(new: Application, state: PresentState) -> Sequence[Diagnostic]:
    """``studio --no-check``: the edit is swapped in unchecked, as the Start runs unchecked."""
    return ()


@dataclass
class EditTarget:
    """The station's running run, as an edit needs it."""

    loop: asyncio.AbstractEventLoop
    engine: ExecutionEngine
    check: RemainderCheck

    @staticmethod
    def of(engine: ExecutionEngine, app: Application, backend: Any, clock: Clock, setup: DryRunSetup | None, trajectory_db: str) -> EditTarget:
        """On the run's loop: ``setup`` None (``--no-check``) swaps edits in without the dry run."""
        check = _unchecked if setup is None else remainder_check(setup, trajectory_db, backend_measure(app.robot, backend, backend_source(backend)), clock)
        return EditTarget(asyncio.get_running_loop(), engine, check)

    async def swap(self, app: Application, file: str, source: str) -> SwapAnswer:
        """From the web server's loop: the engine's answer to the edit."""
        future = asyncio.run_coroutine_threadsafe(swap_remainder(self.engine, app, self.check, file, source), self.loop)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), EDIT_TIMEOUT)
        except asyncio.TimeoutError:
            future.cancel()
            return SwapAnswer(False, f"edit: the engine did not answer within {EDIT_TIMEOUT:g} s; nothing changed")


def placer(document: AppDocument | BlockDocument, path: Path) -> Callable[[list[Diagnostic]], list[PlacedMessage]]:
    """Places diagnostics of ``document`` as the builder writes it (the dry run's findings) at their cells."""
    display = str(path)
    if isinstance(document, BlockDocument) and not document.is_flat():
        _, lines = write_blocks(document)
        return lambda diagnostics: place_steps(diagnostics, lines, document, display)
    flat = document.flat() if isinstance(document, BlockDocument) else document
    _, placements = serialize(flat)
    return lambda diagnostics: place(diagnostics, placements, display)


def operations_json(app: Application, catalog: Catalog) -> list[dict[str, Any]]:
    """The run's operations as the page's snapshot lists them (id, name, calls, iteration, line, breakpoint); with
    ``sync="flags"`` also ``steps``, the groups whose call there is one of their own steps (not a wait of no time they
    sit out): with each group's ``position`` in the engine's status, which operations some group has started --
    the builder's marks of a paused run (paused_edit.js), the same as the engine's refusals count them."""
    def row(op: Operation) -> dict[str, Any]:
        out: dict[str, Any] = {"id": op.id, "name": op.name, "calls": {g: c.function for g, c in op.calls.items()}, "iteration": op.origin, "line": op.line}
        if op.breakpoint:
            out["break"] = True
        if app.sync == "flags":
            out["steps"] = [g for g, c in op.calls.items() if not c.implicit and not bare_wait(c, catalog, app)]
        return out

    return [row(op) for op in app.operations]
