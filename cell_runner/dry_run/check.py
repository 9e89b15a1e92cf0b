"""The dry run as the command line shows it: findings like validation diagnostics, then the prediction.

``validate --simulate`` and the check before ``run`` share this, so both print the same lines and
a dry run that breaks down is one clear message and an exit code, never a traceback.
"""
from __future__ import annotations

import logging
import math
from typing import IO

from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.runner import DryRunError, dry_run
from cell_runner.dry_run.simulators import setup_for
from execution_engine.app_model.model import Application
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import check_options

log = logging.getLogger(__name__)

OK, FOUND, SETUP = 0, 1, 2  # the CLI's EXIT_OK, EXIT_INVALID, EXIT_USAGE


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
) -> tuple[int, DryRunReport | None]:
    """Dry-run ``app``; print its findings to ``err`` and (with ``summary``) the prediction to ``out``.

    Returns (status, report): ``FOUND`` when anything was found or the dry run could not check
    everything, ``SETUP`` when the back end refuses the options (the run would refuse them too).
    """
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
    return (OK if report.ok else FOUND), report


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
