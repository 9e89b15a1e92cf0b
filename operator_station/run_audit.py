"""A run's end in the audit trail: its outcome, under the name of whoever started it.

The start is audited by the route that started it; the outcome comes minutes later on the run's
own thread.  :func:`watch_run` waits for that thread on the server's loop -- in bounded joins, so
a station that is ending is never held up by it -- and records ``run end`` with the engine's
outcome (``finished``, ``stopped``, ``failed``, ...), the operations done, and why a run that
never started was refused (the dry run's findings), as the page showed them.  What happens during
the run without the page -- every safety stop the engine obeyed, commands from the terminal or the
ROS graph -- is audited from the run's records as they come (:mod:`operator_station.cell_audit`).
"""
from __future__ import annotations

import asyncio
import logging
from typing import Any

from operator_station.access import Who
from operator_station.audit import AuditLog, log_of, requester

log = logging.getLogger(__name__)

#: Wall seconds of one join of the run's thread: how soon a watch notices the station ending.
JOIN_STEP = 0.25
#: The watches going on, kept so the loop does not drop them half-way (asyncio keeps weak references).
WATCHES: set[asyncio.Task[None]] = set()


def watch_run(station: Any, connection: Any, started: dict[str, Any]) -> None:
    """Record the end of the run ``connection``'s requester just started (``started``: the start's entry)."""
    audit = log_of(connection) or station.audit_log
    task = asyncio.get_running_loop().create_task(_watch(station, audit, requester(connection), started))
    WATCHES.add(task)
    task.add_done_callback(WATCHES.discard)


async def _watch(station: Any, audit: AuditLog, who: Who | None, started: dict[str, Any]) -> None:
    session = station.session
    try:
        while session.running and not station.stopped:
            await asyncio.to_thread(session.join, JOIN_STEP)
        report = getattr(session, "report", None)
        if session.running:  # the station ends with the run going: its shutdown stops it (operator_station.serving)
            audit.append(who, "run end", ok=False, answer="the station ended during the run", details={"started": started["seq"]})
        elif report is not None:
            audit.append(who, "run end", ok=bool(report.ok), answer=str(report.outcome),
                         details={"started": started["seq"], "operations_done": report.operations_done, "operations_total": report.operations_total})
        else:  # refused by the dry run from where the robot is, or broke down: the page's messages say why
            why = "; ".join(str(m.get("message", "")) for m in station.feed.snapshot.messages[:3]) or "the run did not start"
            audit.append(who, "run end", ok=False, answer=why, details={"started": started["seq"]})
    except Exception:  # noqa: BLE001 - a watch must not die silently; the run itself is unaffected
        log.exception("studio: the audit of the run's end failed")

