"""Dry runs: the whole application on the robot's simulator before anything moves.

``python -m execution_engine validate --simulate APP.xml`` and the check before ``run`` use
:func:`dry_run`; the :class:`DryRunReport` it returns lists every problem at its XML line and
each group's timeline (docs/application_xml.md, "Checking before anything moves").  This is
wiring: it builds back ends, so it may import ``robot_bridges``.
"""
from cell_runner.dry_run.report import DryRunReport, Finding, GroupTime, Span, TimeBase
from cell_runner.dry_run.runner import DryRunError, dry_run, run_dry
from cell_runner.dry_run.simulators import DryRunSetup, setup_for

__all__ = ["DryRunError", "DryRunReport", "DryRunSetup", "Finding", "GroupTime", "Span", "TimeBase", "dry_run", "run_dry", "setup_for"]
