"""``studio --replay TRACE.jsonl``: a finished run's trace shown in the same views, with a time slider.

A trace holds every state change, function, primitive, error and operator command of a run
(:mod:`execution_engine.observers`), not the machines' published structure: that is Table 2,
the same for every group (:mod:`execution_engine.machine.table`), so it is rebuilt from there.
Joint positions come from the results the bridge reported at each primitive's end.  Lines that
are not trace records are skipped and counted, as ``trace_report`` does; the file is read line
by line with the same size limit per line.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from execution_engine.machine.table import FINISH, READY, TABLE_2
from execution_engine.trace_report import MAX_LINE
from operator_station.feed import Feed

#: Records read from one trace at most (a day of a busy cell is well below).
MAX_RECORDS = 2_000_000


def table_structure(group: str) -> dict[str, Any]:
    """A group machine's structure as the machines publish it, from Table 2."""
    return {
        "group": group, "initial": READY, "states": [*TABLE_2, FINISH],
        "transitions": [{"from": s, "signal": signal, "to": target} for s, row in TABLE_2.items() for signal, target in row.items()],
    }


def read_records(path: Path) -> tuple[list[dict[str, Any]], int]:
    """The trace's records in order and how many lines were not records."""
    records: list[dict[str, Any]] = []
    skipped = 0
    with open(path, "rb") as stream:
        while len(records) < MAX_RECORDS:
            raw = stream.readline(MAX_LINE + 1)
            if not raw:
                break
            if not raw.endswith(b"\n") and len(raw) > MAX_LINE:
                skipped += 1
                while raw and not raw.endswith(b"\n"):
                    raw = stream.readline(MAX_LINE + 1)
                continue
            try:
                record = json.loads(raw)
            except (UnicodeDecodeError, json.JSONDecodeError):
                skipped += 1
                continue
            if isinstance(record, dict) and isinstance(record.get("event"), str) and isinstance(record.get("t"), (int, float)):
                records.append(record)
            else:
                skipped += 1
    return records, skipped


def load_replay(feed: Feed, path: Path) -> int:
    """Put the trace at ``path`` into ``feed`` as a finished run; the number of records."""
    records, skipped = read_records(path)
    groups = list(dict.fromkeys(r["group"] for r in records if isinstance(r.get("group"), str) and r["group"] != "engine"))
    total = max((r.get("operations_total", 0) for r in records if r["event"] == "run_end"), default=0)
    messages = [{"severity": "warning", "message": f"{path}: {skipped} line(s) are not trace records and were skipped"}] if skipped else []
    if not any(r["event"] == "run_end" for r in records):
        messages.append({"severity": "warning", "message": f"{path}: no run_end record: the run was cut (killed or crashed)"})
    feed.begin("replay", path.name, groups, structures={g: table_structure(g) for g in groups}, messages=messages, ended=True,
               status={"state": "replay", "operation_count": total, "t": records[-1]["t"] if records else 0.0})
    joint_names = list(dict.fromkeys(n for r in records for n in _names(_result(r).get("joint_names")) if isinstance(n, str)))
    known = {name: float("nan") for name in joint_names}
    for record in records:
        feed.append(record)
        result = _result(record)
        if isinstance(result.get("joint_names"), list) and isinstance(result.get("positions"), list) and known:
            known.update((n, float(p)) for n, p in zip(result["joint_names"], result["positions"]) if n in known and isinstance(p, (int, float)))
            feed.joint_sample(float(record["t"]), list(known.values()), force=True)
    feed.update(joint_names=joint_names)
    return len(records)


def _names(value: Any) -> list[Any]:
    return value if isinstance(value, list) else []


def _result(record: dict[str, Any]) -> dict[str, Any]:
    """What the bridge reported at a primitive's end (joint names and positions of motions); {} otherwise."""
    result = record.get("result") if record.get("event") == "primitive_end" else None
    return result if isinstance(result, dict) else {}
