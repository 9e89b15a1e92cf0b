"""The plan reader (execution_engine/run_plan.py) on anything a trace or a recording from outside may hold.

A plan record is read from files of other computers: any JSON in its fields, any parts in any order, any object
in place of a recorded RunPlan message.  Whatever it is, it is taken whole or left out with one line naming why --
never a traceback, never half a plan; and a plan written is read back as it was, in however many parts.
"""
from __future__ import annotations

import json
import math
from types import SimpleNamespace
from typing import Any

from hypothesis import given, settings, strategies as st

from execution_engine.record_limits import TIME_BOUND
from execution_engine.run_plan import BASES, PlanError, PlanReader, RunPlan, plan_from_fields, plan_records

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=8) | st.sampled_from(["a\nb", "\u202e", "x" * 2000]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)
names = st.text(min_size=1, max_size=12)
seconds = st.floats(min_value=0.0, max_value=TIME_BOUND, allow_nan=False)


@st.composite
def plans(draw: st.DrawFn) -> RunPlan:
    ops = draw(st.lists(names, unique=True, max_size=12))
    keys = draw(st.lists(st.tuples(names, st.sampled_from(ops) if ops else names), unique=True, max_size=12))
    return RunPlan(draw(seconds), draw(st.sampled_from(BASES)), tuple((o, draw(seconds)) for o in ops),
                   tuple((g, o, draw(seconds)) for g, o in keys), draw(st.text(max_size=10)))


def well_formed(plan: RunPlan | None) -> bool:
    if plan is None:
        return True
    every = [plan.cycle_time, *plan.durations, *(s for _, _, s in plan.functions)]
    return plan.basis in BASES and all(math.isfinite(s) and 0 <= s <= TIME_BOUND for s in every) \
        and len({o for o, _ in plan.operations}) == len(plan.operations)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.dictionaries(st.sampled_from(["t", "event", "part", "parts", "basis", "cycle_time", "operations", "functions", "app", "damaged"]),
                                json_values, max_size=10), max_size=6))
def test_any_plan_records_are_taken_whole_or_left_out_in_one_line(records: list[dict[str, Any]]) -> None:
    reader = PlanReader("run.jsonl")
    for record in records:
        assert reader.take({**record, "event": "plan"})
    assert not reader.take({"t": 0.0, "event": "function_start"})
    assert well_formed(reader.finish())
    assert all("\n" not in note and note.startswith("run.jsonl: ") for note in reader.notes)


@settings(max_examples=200, deadline=None)
@given(plans(), st.integers(min_value=1, max_value=7), st.floats(min_value=0.0, max_value=1e6))
def test_a_plan_written_in_parts_is_read_back_as_it_was(plan: RunPlan, part_items: int, t: float) -> None:
    reader = PlanReader()
    for record in plan_records(plan, t, part_items):
        assert reader.take(json.loads(json.dumps(record)))
    read = reader.finish()
    assert read is not None and not reader.notes
    assert (read.basis, read.app, [o for o, _ in read.operations], [(g, o) for g, o, _ in read.functions]) == \
        (plan.basis, plan.app, [o for o, _ in plan.operations], [(g, o) for g, o, _ in plan.functions])
    for got, wrote in zip([read.cycle_time, *read.durations, *(s for *_, s in read.functions)],
                          [plan.cycle_time, *plan.durations, *(s for *_, s in plan.functions)]):
        assert abs(got - wrote) <= 1e-6  # written to the microsecond


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from(["app", "basis", "cycle_time", "operations", "operation_seconds", "functions", "header"]),
                       json_values | st.lists(st.builds(SimpleNamespace, group=json_values, operation=json_values, seconds=json_values), max_size=3),
                       max_size=7))
def test_any_recorded_message_is_a_plan_or_a_plan_error(fields: dict[str, Any]) -> None:
    try:
        plan = plan_from_fields(SimpleNamespace(**fields))
    except PlanError as error:
        assert "\n" not in str(error)
        return
    assert well_formed(plan)
