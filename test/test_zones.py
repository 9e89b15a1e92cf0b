"""Interference zones at run time, in both modes (issue 15): a group's motion that enters a zone
waits until no other group is inside, in application order; the zone is held from the motion that
enters it to the motion that leaves it, so the other arm gets in as soon as the first is out, not
when its function ends.  Traced and reported like flag waits; all on simulated time.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

import app_functions.registry as registry
from core_functions.catalog import ParamSpec, ParamType, skill
from core_functions.functions import CoreFunctions, Skill
from core_functions.primitives import Dwell, MoveCartesian
from test_flags import call, param, run, write

AWAY = "0.34,0.16,0.05,180deg,0,90deg"  # beside the part, on the left arm's side: outside the zones
AWAY_RIGHT = "0.34,-0.16,0.05,180deg,0,90deg"  # ... and on the right arm's side
#: The rivet cell's zones: hands_left over holes 1-3, hands_right over holes 2-4 (hole 2 is in both).
ZONE = "hands_left"
DWELL = 5.0


class ZoneVisits(CoreFunctions):
    """A function that works in a zone, leaves it and goes on working elsewhere."""

    @skill(
        ParamSpec("hole", ParamType.FRAME, "the hole to visit"),
        ParamSpec("away", ParamType.TARGET, "where to go afterwards", unit="m, rad"),
        states=("Motion",),
    )
    def visit_then_work_away(self, hole: str, away: object) -> Skill:
        """Above the hole, then away from the part, then a dwell there (work outside the zone)."""
        yield MoveCartesian(self.cell.pose(hole).offset_local(dz=-0.05), "ptp", frame=f"{hole} clearance")
        yield MoveCartesian(self.resolve(away), "ptp", frame="away")  # type: ignore[arg-type]
        yield Dwell(DWELL)


    @skill(
        ParamSpec("hole", ParamType.FRAME, "the hole to visit"),
        ParamSpec("away", ParamType.TARGET, "where to go in between", unit="m, rad"),
        states=("Motion",),
    )
    def visit_twice(self, hole: str, away: object) -> Skill:
        """Above the hole, away, a moment there, above the hole again, away."""
        for _ in range(2):
            yield MoveCartesian(self.cell.pose(hole).offset_local(dz=-0.05), "ptp", frame=f"{hole} clearance")
            yield MoveCartesian(self.resolve(away), "ptp", frame="away")  # type: ignore[arg-type]
            yield Dwell(0.5)


@pytest.fixture
def visits(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Every machine and the validator offer ``visit_then_work_away`` (a library of this test)."""
    monkeypatch.setitem(registry.LIBRARIES, "zone_visits", ZoneVisits)
    registry.catalog_of.cache_clear()
    yield
    monkeypatch.delitem(registry.LIBRARIES, "zone_visits")
    registry.catalog_of.cache_clear()


def events(records: list[dict], group: str, event: str, operation: str) -> list[dict]:
    return [r for r in records if r.get("group") == group and r["event"] == event and r.get("operation") == operation]


@pytest.mark.parametrize("sync", ["operation", "flags"])
def test_the_second_arm_enters_as_soon_as_the_first_has_left_not_when_its_function_ends(tmp_path: Path, visits: None, sync: str) -> None:
    path, _ = write(tmp_path, [
        {"left_arm": call("visit_then_work_away", param("drill_1"), param(AWAY)), "right_arm": call("approach", param("drill_2"))},
    ], sync)
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    left_moves = [r for r in events(records, "left_arm", "primitive_end", "1") if "move" in str(r.get("primitive"))]
    left_out = left_moves[1]["t"]  # the move away from the part ended: the left arm is out
    left_end = events(records, "left_arm", "function_end", "1")[0]["t"]
    right_in = events(records, "right_arm", "primitive_start", "1")[0]["t"]
    right_start = events(records, "right_arm", "function_start", "1")[0]["t"]
    assert right_start < 0.1  # the function started at once; its motion into the zone waited
    assert right_in == pytest.approx(left_out, abs=0.05)  # in as soon as the left arm left
    assert left_end - right_in > DWELL - 0.1  # not when the left arm's function ended
    zone = [(r["group"], r["state"]) for r in records if r["event"] == "flag" and r["flag"] == ZONE]
    assert zone[:4] == [("left_arm", "passed"), ("right_arm", "waiting"), ("left_arm", "left"), ("right_arm", "passed")]
    assert "right_arm" in text and f"waiting for zone '{ZONE}'" in text  # the run summary splits the idle time
    assert f"waits that cost most: zone '{ZONE}'" in text  # and the run passed the dry run's checks: no deadlock, no collision


def test_a_zone_lets_one_group_in_at_a_time_in_application_order(tmp_path: Path) -> None:
    """sync="flags": the left arm's motion to hole 1 waits while the right arm, first in the zone's
    order, is at hole 2; the engine status and the trace say so."""
    path, _ = write(tmp_path, [
        {"left_arm": call("wait", param("2")), "right_arm": call("approach", param("drill_2"))},
        {"left_arm": call("approach", param("drill_1")), "right_arm": call("move_to_joint_pose", param("initial"))},
    ])
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    right_done = events(records, "right_arm", "function_end", "1")[0]["t"]
    zone = [(r["group"], r["state"], r["t"]) for r in records if r["event"] == "flag" and r["flag"] == ZONE]
    assert zone[0][:2] == ("right_arm", "passed")
    assert zone[1] == ("left_arm", "waiting", 2.0) and zone[2][:2] == ("right_arm", "left")  # the call ended inside: it leaves with it
    assert zone[3][:2] == ("left_arm", "passed") and zone[3][2] == pytest.approx(right_done, abs=1e-6)
    left_moves = events(records, "left_arm", "primitive_start", "2")
    assert left_moves[0]["t"] >= right_done  # not inside while the right arm still works there
    assert f"waiting for zone '{ZONE}'" in text


def test_two_arms_in_different_zones_work_at_once(tmp_path: Path) -> None:
    """Holes 1 and 4 share no zone (two hands fit there): lock-step, both arms at once, no wait."""
    path, _ = write(tmp_path, [
        {"left_arm": call("approach", param("drill_1")), "right_arm": call("approach", param("drill_4"))},
    ], "operation")
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    assert not any(r["event"] == "flag" and r["state"] == "waiting" for r in records)
    assert events(records, "right_arm", "primitive_start", "1")[0]["t"] == events(records, "left_arm", "primitive_start", "1")[0]["t"]


def test_coming_back_into_a_zone_waits_behind_the_arm_inside(tmp_path: Path, visits: None) -> None:
    """The left arm leaves hole 1, the right arm goes in (hole 2), the left arm's way back in waits
    until the right arm is out again: a zone left is asked for again, not kept."""
    path, _ = write(tmp_path, [
        {"left_arm": call("visit_twice", param("drill_1"), param(AWAY)), "right_arm": call("visit_then_work_away", param("drill_2"), param(AWAY_RIGHT))},
    ], "operation")
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    left_moves = [r for r in events(records, "left_arm", "primitive_start", "1") if "move" in str(r.get("primitive"))]
    right_ends = [r for r in events(records, "right_arm", "primitive_end", "1") if "move" in str(r.get("primitive"))]
    right_out = right_ends[1]["t"]
    assert left_moves[2]["t"] == pytest.approx(right_out, abs=0.05)  # back in only once the right arm was out
    zone = [(r["group"], r["state"]) for r in records if r["event"] == "flag" and r["flag"] == ZONE]
    assert zone == [("left_arm", "passed"), ("right_arm", "waiting"), ("left_arm", "left"), ("right_arm", "passed"),
                    ("left_arm", "waiting"), ("right_arm", "left"), ("left_arm", "passed"), ("left_arm", "left")]
