"""The waits of a run for flags and zones, and their totals: what the run report and the dry run split idle time into.

Both the flags (engine/flags.py) and the zones (engine/zones.py) keep every wait of a group as a
:class:`FlagWait`; the run report (engine/report.py) and the dry run's report add them up per flag
or zone.  Kept apart from both boards so that the reports need neither.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class FlagWait:
    """One wait of a group: for a flag (or a zone: ``kind``), from ``t_start`` to ``t_end``, and how it ended."""

    group: str
    operation: str
    flag: str
    t_start: float
    t_end: float
    outcome: str  # passed / timeout / stopped
    kind: str = "flag"

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


def wait_totals(waits: Iterable[FlagWait], group: str | None = None) -> dict[tuple[str, str], float]:
    """Seconds waited per (kind, flag or zone) -- of ``group``, or of every group -- in the order
    first waited: what a run report and the dry run split a group's idle time into."""
    totals: dict[tuple[str, str], float] = {}
    for wait in waits:
        if group is None or wait.group == group:
            totals[(wait.kind, wait.flag)] = totals.get((wait.kind, wait.flag), 0.0) + wait.duration
    return totals


def costliest(totals: dict[tuple[str, str], float], count: int | None = None) -> list[tuple[tuple[str, str], float]]:
    """The totals longest first (ties in the order first waited), the first ``count`` of them."""
    return sorted(totals.items(), key=lambda kv: -kv[1])[:count]
