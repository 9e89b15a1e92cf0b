"""``studio --replay RUN.mcap|TRACE.jsonl``: a finished run's record shown in the same views, with a time slider.

A trace holds every state change, function, primitive, error and operator command of a run
(:mod:`execution_engine.observers`), and a recording the same events as messages; neither holds
the machines' published structure: that is Table 2, the same for every group
(:mod:`execution_engine.machine.table`), so it is rebuilt from there.  Joint positions come from
the results the bridge reported at each primitive's end.
A run checked by its dry run holds the plan it was checked against (``plan`` records, the recording's
``execution_engine/plan`` topic: :mod:`execution_engine.run_plan`): the replay draws the same planned bars and
compares the cycle time with the same prediction as the live run; an older record without it shows none, and
a damaged plan is left out with one line saying so.

The file is read as ``report`` reads it (:func:`~execution_engine.record_reader.read_record`):
in bounded time and memory, at most 64 groups, times a run can have, and a file that asks more
than a run's record can is refused in the same one line naming it (exit 1, nothing served).
What the page shows of the file -- ids, names, error texts -- has its control and bidirectional
characters escaped.  The station keeps every record for its slider, so a replay holds at most
:data:`MAX_RECORDS` of them and says how many more the file has.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from core_functions.printable import printable
from execution_engine.machine.table import FINISH, READY, TABLE_2
from execution_engine.record_reader import printable_record, read_record
from execution_engine.run_plan import PlanReader, RunPlan
from operator_station.feed import Feed
from operator_station.run_summary import summarize
from operator_station.scene3d_recording import load_scene

#: Records a replay keeps (a day of a busy cell is well below); the rest are counted and said.
MAX_RECORDS = 2_000_000


def table_structure(group: str) -> dict[str, Any]:
    """A group machine's structure as the machines publish it, from Table 2."""
    return {
        "group": group, "initial": READY, "states": [*TABLE_2, FINISH],
        "transitions": [{"from": s, "signal": signal, "to": target} for s, row in TABLE_2.items() for signal, target in row.items()],
    }


def read_records(path: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The record's records in order, escaped, at most :data:`MAX_RECORDS`, and the notes on the file
    (lines skipped, cut, records beyond the bound).  OSError, NotARecording or OverLimit as
    :func:`~execution_engine.record_reader.read_record` raises them."""
    records: list[dict[str, Any]] = []
    beyond = 0

    def keep(record: dict[str, Any]) -> None:
        nonlocal beyond
        if len(records) < MAX_RECORDS:
            records.append(printable_record(record))
        else:
            beyond += 1

    read = read_record(path, keep)
    notes = read.notes()
    if beyond:
        notes.append(f"{printable(path)}: only the first {MAX_RECORDS:,} records are replayed; {beyond:,} more follow (report summarises them all)")
    return records, notes


def show_plan(feed: Feed, plan: RunPlan | None) -> None:
    """The plan the run was checked against into ``feed``: the timeline's planned bars (``plan_functions``), the
    ETA's and the summary's planned seconds per operation (``plan``); None: no plan (a run with ``--no-check``)."""
    if plan is not None:
        feed.update(plan=plan.durations, plan_functions=plan.functions_json())


def load_replay(feed: Feed, path: Path) -> int:
    """Put the run's record at ``path`` into ``feed`` as a finished run; the number of records."""
    records, notes = read_records(path)
    planned = PlanReader(printable(path))  # the plan records (kept as records, as the live page had them): the feed's plan
    for record in records:
        planned.take(record)
    plan = planned.finish()
    notes += planned.notes
    groups = list(dict.fromkeys(r["group"] for r in records if isinstance(r.get("group"), str) and r["group"] != "engine"))
    ended = [r["operations_total"] for r in records if r["event"] == "run_end" and _count(r.get("operations_total"))]
    # a recording has no run_end: the operations it shows started are what is known of them
    total = max(ended) if ended else len({r["operation"] for r in records if r["event"] == "function_start" and r.get("operation")})
    messages = [{"severity": "warning", "message": note} for note in notes]
    feed.begin("replay", printable(path.name), groups, structures={g: table_structure(g) for g in groups}, messages=messages, ended=True,
               summary=summarize(records, plan.durations if plan else (), groups).to_json(), status={"state": "replay", "operation_count": total, "t": records[-1]["t"] if records else 0.0})
    show_plan(feed, plan)  # the planned bars against the actual ones, as the live run showed them
    load_scene(feed, path)  # a recording's 3D scene and joint states for the 3D view (operator_station/scene3d_recording.py)
    joint_names = list(dict.fromkeys(n for r in records for n in _names(_result(r).get("joint_names")) if isinstance(n, str)))
    known = {name: float("nan") for name in joint_names}
    for record in records:
        feed.append(record)
        result = _result(record)
        if isinstance(result.get("joint_names"), list) and isinstance(result.get("positions"), list) and known:
            known.update((n, float(p)) for n, p in zip(result["joint_names"], result["positions"]) if n in known and _number(p))
            feed.joint_sample(float(record["t"]), list(known.values()), force=True)
    feed.update(joint_names=joint_names)
    return len(records)


def _count(value: Any) -> bool:
    """A whole number of operations (a record's ``operations_total``), not a flag, a text or a float."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 1 << 53


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) < 1e300


def _names(value: Any) -> list[Any]:
    return value if isinstance(value, list) else []


def _result(record: dict[str, Any]) -> dict[str, Any]:
    """What the bridge reported at a primitive's end (joint names and positions of motions); {} otherwise."""
    result = record.get("result") if record.get("event") == "primitive_end" else None
    return result if isinstance(result, dict) else {}
