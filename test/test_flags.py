"""``sync="flags"``: each group in its own order, waiting only where the application says (issue 15).

Must show: an application of timed waits takes its critical path, not the lock-step sum; no group
passes a wait_flag before the flag is set; a flag nobody sets and a circular wait are refused by
``validate`` at their lines, naming the flags; lock-step is unchanged; flag waits appear in the
engine status, the trace, the run report (idle split) and the timeline.  All on simulated time.
"""
from __future__ import annotations

import asyncio
import json
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app_functions.registry import full_catalog
from cell_runner.deployment import deploy_local
from execution_engine.app_model import load_application
from execution_engine.timeline import build_timeline
from execution_engine.timeline_plot import plot_timeline
from node_transport.clock import run_with_clock, simulated_clock
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend
from test_dry_run import RIVET_CELL, call, cli, param, write_app

GROUPS = ("left_arm", "right_arm")


def write(folder: Path, operations: list[dict[str, str]], sync: str = "flags") -> tuple[Path, dict[tuple[int, str], int]]:
    """An application with one line per call (test_dry_run's), in ``sync`` mode; (operation number, group) -> line."""
    path, where = write_app(folder, "nextage", RIVET_CELL, operations)
    path.write_text(path.read_text(encoding="utf-8").replace('robot="nextage"', f'robot="nextage" sync="{sync}"', 1), encoding="utf-8")
    return path, {(int(op), group): int(place.split(":")[-2]) for (op, group), place in where.items()}


def wait(seconds: float) -> str:
    return call("wait", param(f"{seconds:g}"))


def total(out: str) -> float:
    line = next(x for x in out.splitlines() if x.strip().startswith("total"))
    return float(line.split()[1])


def run(path: Path, tmp: Path) -> tuple[int, str, list[dict]]:
    trace = tmp / "trace.jsonl"
    code, out, err = cli("run", str(path), "--speed", "max", "--trace", str(trace))
    return code, out + err, [json.loads(line) for line in trace.read_text().splitlines()]


durations = st.lists(st.tuples(st.integers(1, 4), st.integers(1, 4)), min_size=1, max_size=3)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(durations)
def test_timed_waits_take_their_critical_path_not_the_lock_step_sum(tmp_path: Path, pairs: list[tuple[int, int]]) -> None:
    ops = [{"left_arm": wait(a), "right_arm": wait(b)} for a, b in pairs]
    flags, _ = write(tmp_path, ops, "flags")
    code, text, _ = run(flags, tmp_path)
    assert code == 0, text
    assert abs(total(text) - max(sum(a for a, _ in pairs), sum(b for _, b in pairs))) < 0.05
    lock, _ = write(tmp_path, ops, "operation")
    code, text, _ = run(lock, tmp_path)
    assert code == 0 and abs(total(text) - sum(max(a, b) for a, b in pairs)) < 0.05


def test_no_group_passes_a_wait_flag_before_the_flag_is_set(tmp_path: Path) -> None:
    path, _ = write(tmp_path, [
        {"left_arm": wait(3), "right_arm": call("wait_flag", param("left_ready"))},
        {"left_arm": call("set_flag", param("left_ready")), "right_arm": wait(1)},
    ])
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    flag = [r for r in records if r["event"] == "flag"]
    assert [(r["group"], r["state"], r["t"]) for r in flag] == [
        ("right_arm", "waiting", 0.0), ("left_arm", "set", 3.0), ("right_arm", "passed", 3.0),
    ]
    right_wait = [r for r in records if r["group"] == "right_arm" and r["event"] == "function_start" and r.get("function") == "wait"]
    assert right_wait and right_wait[0]["t"] >= 3.0  # its next function only after the flag
    assert abs(total(text) - 4.0) < 0.05
    assert "right_arm    idle     3.00 s: 3.00 s waiting for flag 'left_ready'" in text
    assert "waits that cost most: flag 'left_ready' 3.00 s" in text
    timeline = build_timeline(records, GROUPS)
    waits = [g for g in timeline.lanes["right_arm"].idle if g.waiting]
    assert [(g.waiting, g.t_start, g.t_end) for g in waits] == [("flag left_ready", 0.0, 3.0)]
    svg = plot_timeline(timeline, tmp_path / "timeline.svg").read_text()  # the Fig. 12 plot names the wait
    assert "waiting for flag left_ready" in svg and "waiting (flag, zone)" in svg


def test_a_wait_flag_that_times_out_fails_the_function(tmp_path: Path) -> None:
    path, where = write(tmp_path, [
        {"left_arm": wait(5), "right_arm": call("wait_flag", param("late"), param("2"))},
        {"left_arm": call("set_flag", param("late"))},
    ])
    code, _, err = cli("validate", "--simulate", str(path))  # the dry run meets the timeout first
    assert code == 1 and f"{path}:{where[(1, 'right_arm')]}:" in err and "flag 'late' was not set within 2 s" in err, err
    code, out, err = cli("run", str(path), "--speed", "max", "--no-check")
    assert code == 1 and "flag 'late' was not set within 2 s" in out + err


def test_a_flag_nobody_sets_is_refused_at_its_line(tmp_path: Path) -> None:
    path, where = write(tmp_path, [
        {"left_arm": call("wait_flag", param("ghost")), "right_arm": call("set_flag", param("other"))},
        {"right_arm": call("wait_flag", param("other"))},
    ])
    code, _, err = cli("validate", str(path))
    assert code == 1
    assert f"{path}:{where[(1, 'left_arm')]}:" in err and "wait_flag('ghost') of left_arm can never end: no other group sets flag 'ghost'" in err
    assert f"{path}:{where[(2, 'right_arm')]}:" in err and "no other group sets flag 'other' (only right_arm itself sets it" in err


def test_a_circular_wait_is_refused_naming_every_flag_and_line(tmp_path: Path) -> None:
    path, where = write(tmp_path, [
        {"left_arm": call("wait_flag", param("a")), "right_arm": call("wait_flag", param("b"))},
        {"left_arm": call("set_flag", param("b")), "right_arm": call("set_flag", param("a"))},
    ])
    code, _, err = cli("validate", str(path))
    assert code == 1
    left, right = where[(1, "left_arm")], where[(1, "right_arm")]
    for line in (left, right):
        message = next(x for x in err.splitlines() if x.startswith(f"{path}:{line}:"))
        assert "circular wait (deadlock)" in message
        assert f"left_arm at line {left} (wait_flag) waits for flag 'a', which right_arm sets only at line {where[(2, 'right_arm')]}" in message
        assert f"right_arm at line {right} (wait_flag) waits for flag 'b', which left_arm sets only at line {where[(2, 'left_arm')]}" in message


def test_in_lock_step_a_flag_set_only_in_a_later_operation_is_a_deadlock(tmp_path: Path) -> None:
    path, where = write(tmp_path, [
        {"left_arm": call("wait_flag", param("a"))},
        {"right_arm": call("set_flag", param("a"))},
    ], "operation")
    code, _, err = cli("validate", str(path))
    assert code == 1 and f"{path}:{where[(1, 'left_arm')]}:" in err and "circular wait (deadlock)" in err
    same, _ = write(tmp_path, [{"left_arm": call("wait_flag", param("a")), "right_arm": call("set_flag", param("a"))}], "operation")
    code, _, err = cli("validate", str(same))
    assert code == 0, err
    code, text, _ = run(same, tmp_path)
    assert code == 0, text


def test_a_master_slave_pair_meets_its_partner_in_flags_mode(tmp_path: Path) -> None:
    path, _ = write(tmp_path, [
        {"left_arm": wait(2), "right_arm": call("approach", param("drill_4"))},
        {"left_arm": call("approach", param("drill_1")), "right_arm": call("gripper_open")},
        {"left_arm": call("master_move", param("0.34,0.06,0.10,180deg,0,90deg"), param("right_arm")), "right_arm": call("slave_follow", param("left_arm"))},
    ])
    code, text, records = run(path, tmp_path)
    assert code == 0, text
    ends = {r["group"]: r["t"] for r in records if r["event"] == "function_end" and r.get("operation") == "3"}
    starts = {r["group"]: r["t"] for r in records if r["event"] == "function_start" and r.get("operation") == "3"}
    assert set(ends) == {"left_arm", "right_arm"} and abs(ends["left_arm"] - ends["right_arm"]) < 0.05  # one motion of both
    assert starts["right_arm"] < starts["left_arm"]  # the slave got there first and waited for its master


# ------------------------------------------------------------------ interference zones
def write_zoned(folder: Path, operations: list[dict[str, str]]) -> tuple[Path, dict[tuple[int, str], int]]:
    """The rivet cell has the zones ``hands_left`` (holes 1-3) and ``hands_right`` (holes 2-4) over the part."""
    assert '<zone name="hands_left"' in RIVET_CELL.read_text(encoding="utf-8")
    return write(folder, operations)


def test_a_zone_order_that_deadlocks_with_a_flag_is_refused(tmp_path: Path) -> None:
    path, where = write_zoned(tmp_path, [
        {"left_arm": call("wait_flag", param("go"))},
        {"left_arm": call("approach", param("drill_2")), "right_arm": call("approach", param("drill_3"))},
        {"right_arm": call("set_flag", param("go"))},
    ])
    code, _, err = cli("validate", str(path))
    assert code == 1
    message = next(x for x in err.splitlines() if x.startswith(f"{path}:{where[(2, 'right_arm')]}:"))
    assert f"waits for zone 'hands_left', where left_arm works first, at line {where[(2, 'left_arm')]}" in message
    assert f"waits for flag 'go', which right_arm sets only at line {where[(3, 'right_arm')]}" in message


def test_an_operator_stop_ends_a_wait_for_a_flag(tmp_path: Path) -> None:
    """A group waiting for a flag nobody will set soon: a stop ends the run at once, not at the timeout."""
    path, _ = write(tmp_path, [
        {"left_arm": wait(500), "right_arm": call("wait_flag", param("late"))},
        {"left_arm": call("set_flag", param("late"))},
    ])
    app = load_application(path, full_catalog())

    async def main(clock):  # type: ignore[no-untyped-def]
        backend = await create_backend("nextage-sim", clock, BackendOptions(app.robot))
        deployment = await deploy_local(clock, app.robot, backend)
        try:
            engine = deployment.engine
            running = asyncio.ensure_future(engine.run(app))
            await clock.sleep(5.0)
            assert engine.flags.waiting_for("right_arm") == "flag late"
            ok, answer = await engine.operator_command("stop", "test")
            assert ok, answer
            report = await clock.wait_for(running, 30.0)
            return report, clock.now()
        finally:
            await deployment.close()

    report, t = run_with_clock(main, simulated_clock())
    assert report.outcome == "stopped" and t < 10.0
    assert [w.outcome for w in report.flag_waits] == ["stopped"]
