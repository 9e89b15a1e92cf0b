"""The dry run as the command line shows it: findings like validation diagnostics, then the prediction.

``validate --simulate`` and the check before ``run`` share this, so both print the same lines and
a dry run that breaks down is one clear message and an exit code, never a traceback.  A passed
verdict is kept (:mod:`.verdict_cache`): the same application, cell, robot, options, trajectory
database and program are not dry-run again, and one line says whose verdict holds.
"""
from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from cell_runner.dry_run.app_digest import NotDigestible
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.runner import DryRunError, dry_run
from cell_runner.dry_run.simulators import DryRunSetup, setup_for
from cell_runner.dry_run.verdict_cache import Verdict, VerdictCache, verdict_key
from execution_engine.app_model.model import Application
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import check_options

log = logging.getLogger(__name__)

OK, FOUND, SETUP = 0, 1, 2  # the CLI's EXIT_OK, EXIT_INVALID, EXIT_USAGE
#: An application or cell file changed this little before it was read may have changed while it was read (file
#: systems keep modification times to a second or two): its verdict is neither taken from the cache nor kept.
SETTLED = 2.0


def check(
    app: Application,
    file: str,
    backend: str,
    options: BackendOptions,
    trajectory_db: str | None,
    out: IO[str],
    err: IO[str],
    *,
    summary: bool = True,
    read_at: float | None = None,
    avoid: Iterable[str | Path] = (),
    cache: VerdictCache | None = None,
) -> tuple[int, DryRunReport | None]:
    """Dry-run ``app``; print its findings to ``err`` and (with ``summary``) the prediction to ``out``.

    Returns (status, report): ``FOUND`` when anything was found or the dry run could not check
    everything, ``SETUP`` when the back end refuses the options (the run would refuse them too).
    ``read_at``: when (``time.time()``) reading ``app``'s files began; with it, a passed verdict is
    kept in ``cache`` (default: the per-user one) and a kept one is used instead of a dry run (one
    line to ``out`` with ``summary``); never over a file of ``avoid`` (the run's inputs and outputs):
    :func:`keeping_for`, which the station and the engine nodes use too.
    """
    try:
        keeping = keeping_for(app, setup_for(backend, options), trajectory_db, read_at, cache) if read_at is not None else None
    except (KeyError, ValueError):  # options the back end refuses: the dry run below says which
        keeping = None
    kept = keeping.kept() if keeping is not None else None
    if kept is not None:
        if summary:
            out.write(kept.line() + "\n")
        return OK, kept.report
    try:
        report = dry_run(app, backend, options, trajectory_db)
    except (KeyError, ValueError, OSError, ConnectionError) as error:
        err.write(f"error: cannot dry-run {file} on {backend}: {error}\n")
        return SETUP, None
    except DryRunError as error:
        err.write(f"error: the dry run of {file} broke down: {error}\n")
        return FOUND, None
    except Exception as error:  # noqa: BLE001 - a defect of the dry run: one line, the trace with -v
        log.info("dry run of %s", file, exc_info=True)
        err.write(f"error: the dry run of {file} failed (a defect, please report it): {type(error).__name__}: {error}\n")
        return FOUND, None
    for diagnostic in report.diagnostics():
        err.write(f"{diagnostic}\n")
    if summary:
        out.write("\n".join(report.summary_lines()) + "\n")
    elif report.notes:
        err.write("".join(f"{file}: not checked: {note}\n" for note in report.notes))
    if keeping is not None:
        keeping.keep(report, avoid)
    return (OK if report.ok else FOUND), report


@dataclass(frozen=True)
class Keeping:
    """The kept verdict of one dry run of one application from the simulator's start: what ``run``,
    ``validate --simulate``, the station and an engine node look up before dry-running, and keep after."""

    app: Application
    setup: DryRunSetup
    trajectory_db: str | None
    read_at: float | None
    cache: VerdictCache
    key: str

    def kept(self) -> Verdict | None:
        """The passed verdict kept for this dry run, or None (none, or one that cannot be trusted)."""
        return self.cache.get(self.key)

    def keep(self, report: DryRunReport, avoid: Iterable[str | Path] = ()) -> bool:
        """Keep ``report`` if it passed and nothing it depends on changed while it ran (the key again); never
        over a file of ``avoid`` (the run's inputs and outputs)."""
        if not report.ok or _key(self.app, self.setup, self.trajectory_db, self.read_at) != self.key:
            return False
        return self.cache.put(self.key, Verdict(report, time.time()), avoid)


def keeping_for(
    app: Application, setup: DryRunSetup, trajectory_db: str | None, read_at: float | None = None, cache: VerdictCache | None = None
) -> Keeping | None:
    """The :class:`Keeping` of a dry run of ``app`` on ``setup`` reading ``trajectory_db``; None when no verdict
    may be kept: no folder for them, a file that cannot be read, an application that cannot be digested.

    ``read_at``: when (``time.time()``) reading the application's file began -- the command line's; then a file
    modified since (or just before: :data:`SETTLED`) keeps nothing either.  The key holds the application as read
    (:mod:`.app_digest`), so a caller holding it in memory (the station's page, a goal's XML) needs none."""
    try:
        cache = cache if cache is not None else VerdictCache()
    except RuntimeError as error:  # no home folder to keep it in (HOME unset, no password entry): checked every time
        log.info("dry run: no kept verdicts: %s", error)
        return None
    key = _key(app, setup, trajectory_db, read_at)
    return None if key is None else Keeping(app, setup, trajectory_db, read_at, cache, key)


def _key(app: Application, setup: DryRunSetup, trajectory_db: str | None, read_at: float | None) -> str | None:
    """The verdict's key (:func:`.verdict_key`), None when none may be used: a file that cannot be read, an
    application that cannot be digested, or (with ``read_at``) an application or cell file modified since
    reading began (or just before: :data:`SETTLED`)."""
    sources = [app.path] + ([app.cell.path] if app.cell is not None and app.cell.path is not None else [])
    try:
        if read_at is not None and any(os.stat(path).st_mtime > read_at - SETTLED for path in sources):
            return None
        return verdict_key(app, setup, trajectory_db)
    except (OSError, NotDigestible) as error:
        log.info("dry run: no kept verdict: %s", error)
        return None


def options_refusal(file: str, backend: str, options: BackendOptions, speed: float, *, dry_run_first: bool) -> str | None:
    """The line refusing a back-end option of ``run`` before anything runs, or None when every one is good.

    The options the dry run would use (``dry_run_first``: when the run is checked) are read first and
    refused as the dry run refuses them, then the run's own on a clock of ``speed`` (``math.inf``:
    simulated time) as the run would: the same words as when they were refused after seconds of
    dry run, or by the run after it (docs/faults.md rows 140-159)."""
    if dry_run_first:
        setup = setup_for(backend, options)
        try:
            check_options(backend, setup.options, math.inf if setup.simulated_clock else 1.0)
        except (KeyError, ValueError, OSError) as error:
            return f"error: cannot dry-run {file} on {backend}: {error}"
    try:
        check_options(backend, options, speed)
    except (KeyError, ValueError, OSError) as error:
        return f"error: cannot run {file}: {error}"
    return None
