"""The ETA the monitor shows: in run time, and in the wall time it takes at the clock's speed.

The run is the station's own (RunSession: dry run, then the run, the page's records through the same
writer) on a clock at 10x whose wall is its event loop's time -- simulated, so the test takes no
wall time for the robot's.  At every estimate the station pushed, the wall seconds it says are left are
checked against the wall seconds that were actually left (the loop's time at the end less its time then),
within the dry run's own prediction error over the operations still to run: the sum over them of
|planned - actual| seconds, at 10x.  The estimator's rule (eta.py) bounds its error by exactly that.
"""
from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from app_functions.registry import full_catalog
from cell_runner.settings import Outputs, RunSettings
from execution_engine.app_model import load_application
from execution_engine.observers import engine_record
from node_transport.clock import Clock
from node_transport.wire import EngineEvent
from operator_station.eta import EtaTracker
from operator_station.feed import Feed
from operator_station.session import RunSession

ROOT = Path(__file__).resolve().parents[1]
SPEED = 10.0


@dataclass(frozen=True)
class AtTenTimes(RunSettings):
    """``run``'s settings with a clock at 10x whose wall is the (virtual) event loop's time."""

    def clock(self) -> Clock:
        return Clock(SPEED, simulated=True)


class Watched(Feed):
    """A feed that notes the loop's time (the run's wall) at each ETA pushed."""

    def __init__(self) -> None:
        super().__init__()
        self.etas: list[tuple[float, dict[str, Any]]] = []

    def update(self, **fields: Any) -> None:
        if fields.get("eta") is not None:
            self.etas.append((asyncio.get_running_loop().time(), fields["eta"]))
        super().update(**fields)


def operation_times(records: list[dict[str, Any]], ids: list[str]) -> list[float]:
    """Each operation's actual seconds as the plan counts them (run_plan.operation_durations): from its first
    function's start to the next one's (the last: to the end), on a clock that never goes back (sync="flags":
    an operation may start before one listed ahead of it)."""
    starts: dict[str, float] = {}
    for r in records:
        if r["event"] == "function_start":
            starts.setdefault(r["operation"], r["t"])
    end = next(r["t"] for r in records if r["event"] == "run_end")
    position, at = 0.0, []
    for i in ids:
        position = max(position, starts.get(i, position))
        at.append(position)
    return [b - a for a, b in zip(at, at[1:] + [end])]


# Lock-step, where the simulator's prediction is exact to the microsecond; and sync="flags", where the dry run
# counts an operation from its first primitive and the trace from its first function (a set_flag has no
# primitive), so its per-operation error is a quarter of the cycle -- the bound still holds at every instant.
@pytest.mark.parametrize(("application", "error_share"), [("rivet_installation.xml", 0.001), ("rivet_async.xml", 0.3)])
def test_the_eta_at_10x_is_the_wall_time_actually_left_within_the_dry_runs_error(tmp_path: Path, application: str, error_share: float) -> None:
    app = load_application(ROOT / "apps_xml" / application, full_catalog())
    feed = Watched()
    session = RunSession(feed, AtTenTimes(speed=SPEED, outputs=Outputs(trajectory_db=str(tmp_path / "t.sqlite"))))
    operations = [{"id": op.id, "name": op.name, "calls": {}, "iteration": op.origin} for op in app.operations]
    ok, answer = session.start(app, operations)
    assert ok, answer
    session.join(120.0)
    assert not session.running
    snapshot, records, _, _ = feed.read(0, 0)
    assert records[-1]["event"] == "run_end" and records[-1]["outcome"] == "finished", snapshot.messages
    plan = snapshot.plan
    ids = [op.id for op in app.operations]
    actual = operation_times(records, ids)
    error = [abs(p - a) for p, a in zip(plan, actual)]
    wall_end = next(wall for wall, eta in reversed(feed.etas) if eta["remaining"] == 0.0)  # pushed with the run_end record
    checked = 0
    for wall, eta in feed.etas:
        assert eta["speed"] == SPEED and eta["planned"] == sum(plan)
        assert math.isclose(eta["wall"], eta["remaining"] / SPEED)
        left = wall_end - wall  # wall seconds actually left then
        tolerance = sum(error[max(eta["operation"] - 1, 0):]) / SPEED + 1e-6
        assert abs(eta["wall"] - left) <= tolerance, f"at run time {eta['t']:.3f} s (operation {eta['operation']}): ETA {eta['wall']:.3f} s, left {left:.3f} s, tolerance {tolerance:.3f} s"
        if eta["operation"]:
            checked += 1
    assert checked >= len(ids)  # at least once in every operation
    # the tolerance is the dry run's error, not a number picked to pass: under the time left at the start
    assert sum(error) < error_share * sum(plan), (plan, actual)


def test_a_pause_holds_the_estimate_and_the_run_goes_on_from_it() -> None:
    tracker = EtaTracker([10.0, 20.0, 30.0], ["1", "2", "3"])
    assert tracker.at(0.0, 10.0).remaining == 60.0  # type: ignore[union-attr]
    tracker.see({"t": 0.5, "event": "function_start", "operation": "1"})
    tracker.see({"t": 10.5, "event": "function_start", "operation": "2"})
    at = tracker.at(15.5, 10.0)
    assert at is not None and at.remaining == 45.0 and at.operation == 2 and math.isclose(at.wall, 4.5)
    tracker.see({"t": 15.5, "event": "engine_state", "to": "paused"})
    held = tracker.at(100.0, 10.0)
    assert held is not None and held.remaining == 45.0 and held.held
    tracker.see({"t": 100.0, "event": "engine_state", "to": "running"})
    going = tracker.at(105.0, 10.0)
    assert going is not None and going.remaining == 40.0 and not going.held
    tracker.see({"t": 106.0, "event": "function_start", "operation": "2"})  # another function of the same operation: no restart
    assert tracker.at(106.0, 10.0).remaining == 39.0  # type: ignore[union-attr]
    tracker.see({"t": 110.0, "event": "run_end"})
    assert tracker.at(110.0, 10.0).remaining == 0.0  # type: ignore[union-attr]


def test_no_plan_no_estimate_and_simulated_time_has_no_wall_to_wait() -> None:
    assert EtaTracker([], []).at(1.0, 10.0) is None
    eta = EtaTracker([5.0], ["1"]).at(0.0, math.inf)
    assert eta is not None and eta.remaining == 5.0 and eta.wall == 0.0 and eta.to_json()["speed"] is None


def test_a_speed_override_changes_the_pace_of_what_is_left_and_0_percent_holds_the_estimate() -> None:
    """Planned at 100 %: after the override goes to 50 % at 4 s into a 10 s operation, the next 2 run seconds do one
    planned second of work and what is left takes twice its planned time; at 0 % the estimate holds as in a pause."""
    tracker = EtaTracker([10.0, 10.0], ["1", "2"], start_percent=100.0)
    tracker.see({"t": 0.0, "event": "function_start", "operation": "1"})
    tracker.see({"t": 4.0, "event": "operator", "command": "speed_override", "accepted": True, "percent": 50.0})
    at = tracker.at(6.0, 1.0)
    assert at is not None and math.isclose(at.remaining, (10.0 - 5.0 + 10.0) * 2.0) and math.isclose(at.wall, 30.0)
    tracker.see({"t": 6.0, "event": "operator", "command": "speed_override", "accepted": False, "percent": 500.0})  # refused: no change
    tracker.see({"t": 6.0, "event": "operator", "command": "speed_override", "accepted": True, "percent": 0.0})
    held = tracker.at(50.0, 1.0)
    assert held is not None and held.held and math.isclose(held.remaining, 15.0)
    tracker.see({"t": 50.0, "event": "operator", "command": "speed_override", "accepted": True, "percent": 100.0})
    going = tracker.at(53.0, 1.0)
    assert going is not None and not going.held and math.isclose(going.remaining, 12.0)


def test_a_run_started_at_half_speed_is_planned_at_it() -> None:
    """The dry run planned at the start's 50 %: at 50 % the plan is the pace; raised to 100 %, the rest takes half."""
    tracker = EtaTracker([8.0], ["1"], start_percent=50.0)
    tracker.see({"t": 0.0, "event": "function_start", "operation": "1"})
    assert math.isclose(tracker.at(2.0, 1.0).remaining, 6.0)  # type: ignore[union-attr]
    tracker.see({"t": 2.0, "event": "operator", "command": "speed_override", "accepted": True, "percent": 100.0})
    assert math.isclose(tracker.at(3.0, 1.0).remaining, (8.0 - 2.0 - 2.0) / 2.0)  # type: ignore[union-attr]


def test_the_trace_record_of_an_accepted_override_carries_its_percent() -> None:
    """What the tracker reads: the engine's event for a change (engine/speed.py) becomes a record with ``percent``."""
    event = EngineEvent("operator", 4.0, "running", "1", message="50", command="speed_override", source="studio", accepted=True,
                        answer="speed override 50 % (was 100 %)")
    record = engine_record(event)
    assert record["percent"] == 50.0 and "target" not in record
    tracker = EtaTracker([10.0], ["1"])
    tracker.see({"t": 0.0, "event": "function_start", "operation": "1"})
    tracker.see(record)
    assert math.isclose(tracker.at(4.0, 1.0).remaining, 12.0)  # type: ignore[union-attr]
