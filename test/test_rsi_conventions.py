"""The controller's set-point convention, found in the first cycles, and the cross-check that goes with it (issue 23 item 3).

A KR C4 is expected to report the set point with the corrections in it; ROS-Industrial's ``kuka_rsi_simulator``
reports ``ASPos`` frozen at the start while its ``AIPos`` follows; kroshu's configurations send no set point.
The bridge serves each -- an application runs to FINISHED with kroshu's KSS configuration and against
ROS-I's simulator at its defaults, never beyond the axis speeds in what the controller received -- and still
catches a controller that lies: a report fitting neither convention, one that changes convention, an actual
position off the commanded path.  The first half drives :class:`ReportCheck` cycle by cycle; the second runs
the loop against the simulated controller in lockstep, and the command line.
"""
from __future__ import annotations

import io
import logging
import math
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import rsi_peer_configs as peers
from cell_runner.cli import main as cli_main
from core_functions.robots import KUKA_KR
from robot_bridges.kuka_rsi.config import parse_config
from robot_bridges.kuka_rsi.convention import Convention, ReportCheck
from robot_bridges.kuka_rsi.external import RobotLink
from robot_bridges.kuka_rsi.guard import joint_outside_tube
from robot_bridges.kuka_rsi.krc_model import KrcModel, RsiContext, like_peer
from robot_bridges.kuka_rsi.otg import VectorOTG
from robot_bridges.kuka_rsi.sim_faults import Quirks
from test_rsi_loop import DT, READY, Rig, rig  # noqa: F401 - rig is the fixture

ROOT = Path(__file__).resolve().parents[1]
TOL = np.radians([0.1] * 6)
START = np.radians(READY)


class Cycles:
    """A ReportCheck fed one commanded set point per cycle, as Motion feeds it (report lag 1, a 25-cycle window)."""

    def __init__(self, has_setpoint: bool = True) -> None:
        self.notes: list[tuple[int, str]] = []
        self.check = ReportCheck(TOL, (0.001, math.radians(0.1)), has_setpoint, 100, lambda level, text: self.notes.append((level, text)))
        self.check.begin(START.copy() if has_setpoint else None, None)
        self.track: deque[np.ndarray] = deque([START.copy()] * 3, maxlen=3)
        self.window: deque[np.ndarray] = deque([START.copy()], maxlen=26)

    def step(self, commanded: np.ndarray, setpoint: np.ndarray | None, actual: np.ndarray) -> str | None:
        self.track.append(commanded.copy())
        self.window.append(commanded.copy())
        return self.check.joints(list(self.track)[-2:], self.window, setpoint, actual)


def _ramp(cycles: int, axis: int = 4, rate_deg: float = 0.5) -> list[np.ndarray]:
    """Commanded set points moving one axis at ``rate_deg`` per cycle from the start."""
    out = []
    for k in range(1, cycles + 1):
        q = START.copy()
        q[axis] += math.radians(rate_deg * k)
        out.append(q)
    return out


# ------------------------------------------------------------------------ the check, cycle by cycle
def test_a_set_point_that_follows_is_found_and_then_held_to_the_commanded_one() -> None:
    c = Cycles()
    path = _ramp(40)
    for k, q in enumerate(path[:20]):
        assert c.step(q, q, q) is None, k
    assert c.check.convention is Convention.FOLLOWS and c.notes == [(logging.INFO, c.notes[0][1])] and "follows the corrections" in c.notes[0][1]
    # Mis-detection guarded: the same controller freezing its report later is a fault, as before -- the
    # report may lag a cycle, not two.
    assert c.step(path[20], path[19], path[20]) is None
    problem = c.step(path[21], path[19], path[21])
    assert problem is not None and problem.startswith("A5: commanded 40.500 deg, the controller reports 40.000 deg (tolerance 0.100 deg)")


def test_a_set_point_frozen_at_the_start_is_found_and_the_actual_axes_are_checked_instead() -> None:
    c = Cycles()
    lagging = START.copy()
    for q in _ramp(60):
        lagging = lagging + 0.5 * (q - lagging)  # a servo trailing the set point
        assert c.step(q, START, lagging) is None
    assert c.check.convention is Convention.FROZEN and len(c.notes) == 1
    level, text = c.notes[0]
    assert level == logging.WARNING and "frozen at the start pose" in text and "the cross-check compares the actual axes (AIPos" in text


def test_a_frozen_report_with_a_little_noise_is_not_taken_for_a_following_one() -> None:
    """Slow first steps (0.06 deg a cycle) and a frozen report 0.05 deg off the start: one tolerance from the
    start, the report would still fit the commanded set point; the decision waits for two."""
    c = Cycles()
    noisy = START + np.radians([0, 0, 0, 0, 0.05, 0])
    for q in _ramp(30, rate_deg=0.06):
        assert c.step(q, noisy, q) is None
    assert c.check.convention is Convention.FROZEN


def test_a_frozen_report_that_starts_moving_is_a_fault() -> None:
    c = Cycles()
    path = _ramp(10)
    for q in path[:5]:
        c.step(q, START, q)
    assert c.check.convention is Convention.FROZEN
    problem = c.step(path[5], path[5], path[5])
    assert problem is not None and problem.startswith("A5: the controller's set point (ASPos) stayed at the start, 30.000 deg, and now reads 33.000 deg")


def test_a_robot_that_does_not_follow_a_frozen_report_is_caught_within_the_follow_time() -> None:
    """Frozen ASPos, and AIPos stuck at the start too: the controller ignores the corrections.  Once the
    last 100 ms of commanded set points have all left the start by more than the tolerance, it is a fault."""
    c = Cycles()
    faults = [k for k, q in enumerate(_ramp(60)) if c.step(q, START, START) is not None]
    assert c.check.convention is Convention.FROZEN
    first = faults[0]
    assert 24 <= first <= 27  # the 26-set-point window (100 ms at 4 ms) has moved off the start
    problem = c.step(_ramp(61)[-1], START, START)
    assert problem is not None and problem.startswith("A5: the actual axis (AIPos) reads 30.000 deg, outside the ")


def test_a_report_that_fits_neither_convention_is_a_fault_at_once() -> None:
    c = Cycles()
    drifted = START + np.radians([0, 0, 0.3, 0, 0, 0])  # neither the commanded set point nor the start
    problem = c.step(START, drifted, START)
    assert problem is not None and problem.startswith("A3: the controller reports its set point (ASPos) at 85.300 deg, neither the commanded 85.000 deg")
    assert "nor the start 85.000 deg (a set point frozen at the start)" in problem and c.check.convention is Convention.UNDECIDED


def test_without_a_set_point_the_actual_axes_must_trail_the_commanded_path() -> None:
    c = Cycles(has_setpoint=False)
    assert c.check.convention is Convention.ABSENT
    lagging = START.copy()
    for q in _ramp(30):
        lagging = lagging + 0.3 * (q - lagging)
        assert c.step(q, None, lagging) is None
    ahead = _ramp(31)[-1] + np.radians([0, 0, 0, 0, 0.2, 0])  # ahead of anything commanded
    problem = c.step(_ramp(31)[-1], None, ahead)
    assert problem is not None and problem.startswith("A5: the actual axis (AIPos) reads ") and c.notes == []


@given(
    st.lists(st.lists(st.floats(-40.0, 40.0), min_size=6, max_size=6), min_size=1, max_size=3),
    st.floats(0.0, 0.010),
    st.booleans(),
    st.floats(0.1, 1.0),
)
def test_a_servo_trailing_any_commanded_motion_never_faults(targets: list[list[float]], tau: float, frozen: bool, fraction: float) -> None:
    """Moves the generator makes at up to the axes' speeds, retargeted while moving, followed by a servo lagging
    up to 10 ms behind (the simulated KR C4's: 6 ms): with a frozen report or none, the actual axes always
    lie within the 100 ms tube of what was commanded -- no false fault from the convention's check."""
    link = RobotLink("kr", "127.0.0.1")
    c = Cycles(has_setpoint=frozen)
    otg = VectorOTG([1] * 6, DT)
    otg.reset(START)
    vmax, amax = np.array(link.max_joint_speed) * fraction, np.array(link.max_joint_accel)
    alpha = 1.0 - math.exp(-DT / tau) if tau > 0 else 1.0
    actual = START.copy()
    for k, target in enumerate(targets):
        otg.set_target(START + np.radians(target), vmax, amax)
        for _ in range(60 if k + 1 < len(targets) else 3000):  # the next target arrives mid-motion
            if otg.done:
                break
            otg.step()
            q = otg.position.copy()
            assert c.step(q, START if frozen else None, actual) is None
            actual = actual + alpha * (q - actual)  # the controller applies it in the cycle after


@given(
    st.lists(st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6), min_size=1, max_size=30),
    st.lists(st.floats(-3.5, 3.5), min_size=6, max_size=6),
    st.floats(1e-4, 0.1),
)
def test_the_tube_is_the_box_of_every_set_point_of_the_window(window: list[list[float]], actual: list[float], tolerance: float) -> None:
    """The check's shortcut (between the window's two ends) never decides otherwise than the whole window's box."""
    span, here, tol = np.array(window), np.array(actual), np.full(6, tolerance)
    inside = bool(((here >= span.min(axis=0) - tol) & (here <= span.max(axis=0) + tol)).all())
    found = joint_outside_tube(here, [np.array(v) for v in window], tol)
    assert (found is None) == inside
    if found is not None:
        axis, low, high = found
        assert (low, high) == (span[:, axis].min(), span[:, axis].max()) and not low - tolerance <= here[axis] <= high + tolerance


def test_an_infinite_tolerance_switches_the_check_off_whatever_is_reported() -> None:
    c = Cycles()
    c.check.tolerance = np.full(6, math.inf)
    for q in _ramp(40):
        assert c.step(q, START + 1.0, START - 1.0) is None


# --------------------------------------------------------------------- the loop and the simulator
def _wait_correcting(r: Rig) -> None:
    r.wait(lambda: r.iface.state(0).correcting, "RSI_MOVECORR (no handshake configured: at once)")


def test_kroshus_kss_configuration_moves_the_robot_within_its_axis_speeds(rig: Callable[..., Rig]) -> None:
    config = parse_config(peers.KSS, "kss.xml")
    r = rig(config=config, context=RsiContext(start_deg=READY)).start()
    _wait_correcting(r)
    target = np.radians([20, -70, 80, 10, 40, 10])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 10.0, 60.0))
    assert ok, message
    trace = np.array(r.sim.model.trace)  # type: ignore[arg-type]
    vmax = np.array(r.iface.links[0].max_joint_speed)
    assert np.allclose(trace[-1], target, atol=1e-7) and np.all(np.abs(np.diff(trace, axis=0)) <= vmax * DT + 1e-9)
    assert r.iface.events.notes == [] and r.iface.events.faults == []


def test_kroshus_kss_configuration_catches_a_robot_running_off_its_path(rig: Callable[..., Rig]) -> None:
    config = parse_config(peers.KSS, "kss.xml")
    r = rig(config=config, quirks=Quirks(drift_axis=2, drift_deg=0.05, drift_actual=True)).start()
    _wait_correcting(r)
    ok, message, kind = r.done(r.iface.set_axial_pos(0, np.radians([20, -70, 80, 10, 40, 10]), 10.0, 60.0))
    assert not ok and kind == "controller" and message.startswith("kr0: A2: the actual axis (AIPos) reads ")


def test_ros_industrials_simulator_is_served_and_its_convention_reported(rig: Callable[..., Rig]) -> None:
    context, quirks = like_peer("ros-industrial", RsiContext(), Quirks())
    r = rig(config=parse_config(peers.ROS_I_KR_C4, "kr_c4.xml"), context=context, quirks=quirks).start()
    _wait_correcting(r)
    target = np.radians([20, -70, 80, 10, 40, 10])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 10.0, 60.0))
    assert ok, message
    r.wait(lambda: bool(r.iface.events.notes), "the convention's note")
    assert len(r.iface.events.notes) == 1 and "frozen at the start pose" in r.iface.events.notes[0]
    trace = np.array(r.sim.model.trace)  # type: ignore[arg-type]
    assert np.all(np.abs(np.diff(trace, axis=0)) <= np.array(r.iface.links[0].max_joint_speed) * DT + 1e-9)
    assert np.allclose(trace[-1], target, atol=1e-7) and r.iface.events.faults == []


@pytest.mark.parametrize("drift", [0.0, 0.02], ids=["follows", "runs off"])
def test_a_frozen_tcp_set_point_under_cartesian_corrections_checks_the_actual_tcp(rig: Callable[..., Rig], drift: float) -> None:
    """The default configuration (RKorr, RSol, RIst) with RSol and ASPos frozen: a linear move is served, the
    actual TCP checked against the path the commanded poses took -- and one running off it caught."""
    r = rig(quirks=Quirks(frozen_setpoint=True, drift_axis=1 if drift else 0, drift_deg=drift, drift_actual=True)).start()
    r.correcting()
    here = r.iface.state(0).tcp()
    ok, message, kind = r.done(r.iface.set_cart_pos(0, here.translated(0.0, 0.1, -0.1), 0.3, 2.0))
    if drift:
        assert not ok and kind == "controller" and message.startswith("kr0: TCP: the actual TCP (RIst) lies ")
        return
    assert ok, message
    assert len(r.iface.events.notes) == 1 and "set point (RSol) frozen at the start pose" in r.iface.events.notes[0]


def test_a_correction_kept_from_an_earlier_connection_holds_the_robot_where_it_stands(rig: Callable[..., Rig]) -> None:
    """ROS-I's simulator keeps its absolute correction between connections: ASPos at its start, the robot where the
    last run left it.  A first reply without that correction would send it back in one cycle (its simulator has
    no speed limit; ours stops RSI on it); the bridge takes it as in force, says so, and goes on from there."""
    context, quirks = like_peer("ros-industrial", RsiContext(), Quirks())
    r = rig(config=parse_config(peers.ROS_I_KR_C4, "kr_c4.xml"), context=context, quirks=quirks)
    r.sim.model.carry_correction((10.0, 5.0, -5.0, 0.0, -60.0, 0.0))  # where the last run left it
    r.start()
    _wait_correcting(r)
    target = np.radians([20, -70, 80, 10, 40, 10])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 10.0, 60.0))
    assert ok, message
    assert r.sim.running and r.sim.stop_reason is None
    trace = np.array(r.sim.model.trace)  # type: ignore[arg-type]
    assert np.all(np.abs(np.diff(trace, axis=0)) <= np.array(r.iface.links[0].max_joint_speed) * DT + 1e-9)
    assert np.allclose(trace[0], np.radians([10.0, -85.0, 85.0, 0.0, 30.0, 0.0]), atol=1e-9)  # the first cycle held it there
    r.wait(lambda: len(r.iface.events.notes) == 2, "the two notes")
    kept, frozen = r.iface.events.notes
    assert "as RSI_MOVECORR begins A5 stands -60.000 deg from the reported set point (ASPos)" in kept and "frozen at the start" in frozen


# ---------------------------------------------------------------------------- the command line
@pytest.fixture
def controllers(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[KrcModel]]:
    """Every simulated controller started in this process, recording the set point of every cycle."""
    made: list[KrcModel] = []
    original = KrcModel.__init__

    def recording(self: KrcModel, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        self.trace = []
        made.append(self)

    monkeypatch.setattr(KrcModel, "__init__", recording)
    yield made


@pytest.mark.parametrize(
    ("config", "options", "said"),
    [
        (peers.KSS, [], "kss.xml sends no ASPos (the axes' set point): corrections count from the actual axes (AIPos)"),
        (peers.ROS_I_KR_C4, ["sim_peer=ros-industrial"], "the controller reports its set point (ASPos) frozen at the start pose"),
    ],
    ids=["kroshu KSS", "ROS-I simulator"],
)
def test_an_application_runs_to_finished_never_beyond_the_axis_speeds(
    tmp_path: Path, controllers: list[KrcModel], config: str, options: list[str], said: str
) -> None:
    (tmp_path / "kss.xml").write_text(config)
    app = tmp_path / "joint_only.xml"
    app.write_text(peers.JOINT_ONLY_APP.format(cell=ROOT / "apps_xml" / "cells" / "kuka_rsi_cell.xml"))
    out, err = io.StringIO(), io.StringIO()
    flags = [a for o in ["simulator=accelerated", f"config={tmp_path / 'kss.xml'}", *options] for a in ("--backend-option", o)]
    code = cli_main(["run", str(app), "--robot", "kuka-rsi", *flags], out, err)
    assert code == 0, err.getvalue()
    assert "FINISHED" in out.getvalue() and "operations: 6/6" in out.getvalue()
    assert err.getvalue().count(said) == 1  # stated once, though a checked run starts the back end twice
    assert "Traceback" not in err.getvalue() and "ERROR" not in err.getvalue()
    moved = [np.array(m.trace) for m in controllers if m.trace is not None and len(m.trace) > 100]
    assert moved, "the run's controller recorded its set points"
    vmax = np.array([j.max_velocity for j in KUKA_KR.group("arm").joints])  # the robot model's axis speeds (rad/s)
    for trace in moved:
        steps = np.abs(np.diff(trace, axis=0)) / DT
        assert np.all(steps <= vmax * (1 + 1e-9)), np.degrees(steps.max(axis=0))


def test_ros_industrials_simulator_in_its_own_process_in_real_time(tmp_path: Path) -> None:
    """The same application against ROS-I's simulator (``--peer ros-industrial``) as a process on the wall clock, as
    the back end starts it without a real controller: FINISHED, the convention said once.  The simulated controller
    stops RSI on any set point beyond an axis speed (KrcModel._check_motion), which would end the run in a fault."""
    (tmp_path / "kr_c4.xml").write_text(peers.ROS_I_KR_C4)
    app = tmp_path / "joint_only.xml"
    app.write_text(peers.JOINT_ONLY_APP.format(cell=ROOT / "apps_xml" / "cells" / "kuka_rsi_cell.xml"))
    out, err = io.StringIO(), io.StringIO()
    feedback = tmp_path / "packets.txt"  # the real run's packets (the dry runs save none)
    options = ["simulator=process", f"config={tmp_path / 'kr_c4.xml'}", "sim_peer=ros-industrial", f"feedback={feedback}"]
    code = cli_main(["run", str(app), "--robot", "kuka-rsi", *(a for o in options for a in ("--backend-option", o))], out, err)
    assert code == 0, err.getvalue()
    assert "FINISHED" in out.getvalue() and "operations: 6/6" in out.getvalue()
    assert err.getvalue().count("the controller reports its set point (ASPos) frozen at the start pose") == 1
    # The process played ROS-I's simulator: IPOC counting packets from 0, RIst at zero.
    rows = [line.split() for line in feedback.read_text().splitlines()[1:]]
    ipocs = [int(row[1]) for row in rows]
    steps = [b - a for a, b in zip(ipocs, ipocs[1:])]
    assert len(rows) > 500 and ipocs[0] < 50 and min(steps) > 0 and sorted(steps)[len(steps) // 2] == 1  # a KR C4 counts 4 ms
    assert all(float(v) == 0.0 for row in rows for v in row[3:9])
