"""Peers that do not tell the truth: the external system plans from what it commanded, checks what
the controller reports, and says clearly what it refused.

The peers are the project's simulated KR C4 with :class:`Quirks` and :class:`Faults`: a set point
frozen at the start pose (ROS-Industrial's ``kuka_rsi_simulator`` never updates ``ASPos``), dropped
replies, a drifting report, ``<Rob TYPE="KUKA">`` and an IPOC counting packets (ROS-I's again),
packets that are refused.  The simulator runs in lockstep over loopback (see test_rsi_loop.py), so
every outcome follows from what the loop answered.
"""
from __future__ import annotations

import io
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cell_runner.cli import main as cli_main
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from test_rsi_loop import ARM, DT, READY, WAIT, Rig, holdon_config, rig  # noqa: F401 - rig is the fixture

VMAX = np.array(RobotLink("kr", "127.0.0.1").max_joint_speed)  # rad/s, the robot model's axis speeds
OFF = {"setpoint_tolerance_deg": (math.inf,) * 6}  # the cross-check switched off, to see what is planned


def _steps(trace: list[np.ndarray]) -> np.ndarray:
    return np.diff(np.array(trace), axis=0)


def test_a_peer_spelling_type_in_capitals_and_counting_packets_is_served(rig: Callable[..., Rig]) -> None:
    """ROS-I's simulator sends ``<Rob TYPE="KUKA">`` and steps IPOC by one per packet."""
    r = rig(quirks=Quirks(root_attribute="TYPE", ipoc_step=1)).start()
    r.correcting()
    target = np.radians([20, -80, 85, 0, 40, 0])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 1.0, 5.0))
    assert ok, message
    assert r.iface.loop is not None and r.iface.loop.stats.rejected == 0
    assert np.allclose(r.sim.model.trace[-1], target, atol=1e-7)  # type: ignore[index]


def test_a_frozen_set_point_whose_robot_does_not_follow_is_a_controller_fault_before_the_robot_moves_far(rig: Callable[..., Rig]) -> None:
    """A set point frozen at the start is a convention (ROS-I's simulator: test_rsi_conventions.py); then the
    actual axes must follow what was commanded, and a peer whose AIPos runs off on its own is caught at once."""
    r = rig(quirks=Quirks(frozen_setpoint=True, drift_axis=5, drift_deg=0.2, drift_actual=True)).start()
    r.correcting()
    ok, message, kind = r.done(r.iface.set_axial_pos(0, np.radians([0, -80, 85, 0, 90, 0]), 10.0, 60.0))
    assert not ok and kind == "controller"
    assert message.startswith("kr0: A5: the actual axis (AIPos) reads ") and "(tolerance 0.100 deg); the controller does not follow" in message
    r.wait(lambda: bool(r.iface.events.faults), "the fault event")
    assert r.iface.events.faults[0][:2] == (0, "controller")
    # The robot moved no further than the tolerance, plus the cycle of lag the check allows and the
    # reply already sent, before holding: a third of a degree of a 60 degree move.
    end = r.iface.state(0).cycles + 50
    r.iface.wake_at(0, end)
    r.wait(lambda: r.iface.state(0).cycles >= end, "50 cycles of holding")
    trace = np.degrees(np.array(r.sim.model.trace))  # type: ignore[arg-type]
    assert np.max(np.abs(trace[:, 4] - 30.0)) < 0.5
    assert np.all(trace[-40:] == trace[-1])  # holding: no correction changes any more
    assert np.all(np.abs(_steps(r.sim.model.trace)) <= VMAX * DT + 1e-9)  # type: ignore[arg-type]
    # The fault sticks: the controller must be looked at before anything moves again.
    ok, again, kind = r.done(r.iface.set_axial_pos(0, np.radians(READY), 1.0, 5.0))
    assert not ok and kind == "controller" and again == message


def test_a_frozen_set_point_and_dropped_replies_never_send_the_robot_back(rig: Callable[..., Rig]) -> None:
    """With the cross-check off, what is planned shows: every catch-up after a dropped reply starts
    from the set point the loop commanded, not from the start pose the peer keeps reporting."""
    r = rig(quirks=Quirks(frozen_setpoint=True), faults=Faults(drop=0.05, seed=11), link=OFF).start()
    r.correcting()
    first = len(r.sim.model.trace)  # type: ignore[arg-type]
    target = np.radians([0, -80, 85, 0, 90, 200])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 10.0, 60.0))
    assert ok, message
    assert r.sim.running and r.sim.stop_reason is None  # the controller never refused a step
    trace = np.array(r.sim.model.trace[first:])  # type: ignore[index]
    steps = _steps(list(trace))
    moving = np.nonzero(np.any(np.abs(steps) > 0, axis=1))[0]
    held = [i for i in range(moving[0], moving[-1]) if not np.any(steps[i])]
    assert held, "a reply must have been dropped mid-motion"
    assert r.iface.loop is not None and r.iface.loop.channels[0].catch_ups >= len(held) > 0
    assert np.all(np.abs(steps) <= VMAX * DT + 1e-9)  # no two corrections further apart than the axes allow
    assert np.all(steps[:, 4] >= -1e-12) and np.all(steps[:, 5] >= -1e-12)  # never back toward the start pose
    assert np.allclose(trace[-1], target, atol=1e-7)


def test_a_drifting_report_during_a_cartesian_move_is_a_controller_fault(rig: Callable[..., Rig]) -> None:
    """Under Cartesian corrections the reported RSol is checked, in millimetres."""
    r = rig(quirks=Quirks(drift_axis=1, drift_deg=0.01), link=OFF).start()
    r.correcting()
    here = r.iface.state(0).tcp()
    ok, message, kind = r.done(r.iface.set_cart_pos(0, here.translated(0.0, 0.0, -0.15), 0.2, 1.0))
    assert not ok and kind == "controller"
    assert message.startswith("kr0: TCP: commanded [") and "tolerance 1 mm, 0.1 deg" in message


@pytest.mark.parametrize(
    ("faults", "quirks", "words"),
    [
        (Faults(), Quirks(root_attribute="Kind"), "12 x root attribute: <Rob> has no Type attribute (its attributes: Kind)"),
        (Faults(garbage=1.0, loss=1.0, seed=5), Quirks(), " x xml: not well-formed XML"),
    ],
)
def test_a_peer_whose_every_packet_is_refused_ends_the_wait_with_what_was_wrong(
    rig: Callable[..., Rig], faults: Faults, quirks: Quirks, words: str
) -> None:
    clock = [0]
    settings = LoopSettings(port=0, connect_timeout=10.0)
    r = rig(quirks=quirks, faults=faults, cycles=12, settings=settings, reply_grace=0.01, now_ns=lambda: clock[0]).start()
    assert r.sim.join(WAIT)
    loop = r.iface.loop
    assert loop is not None
    r.wait(lambda: loop.channels[0].rejected == 12, "the twelve refused packets")
    clock[0] += 11 * 10**9  # the loop's injected clock passes the connect timeout
    r.wait(lambda: bool(r.iface.events.faults), "the loop to give up")
    robot, kind, message = r.iface.events.faults[0]
    assert (robot, kind) == (0, "timeout")
    assert message.startswith(f"no valid packet from kr0 (127.0.0.1) within 10 s: 12 packets arrived from 127.0.0.1:{r.sim.address[1]}, all refused: ")
    assert words in message and "Traceback" not in message
    counted = loop.channels[0].refused
    assert sum(counted.values()) == 12 and all(n > 0 for n in counted.values())
    r.iface.request_stats()
    r.wait(lambda: r.iface.events.stats is not None, "the loop's statistics")
    assert r.iface.events.stats[9] == [counted]  # type: ignore[index]  # refusals by reason, per robot


def test_the_command_line_ends_a_refused_peer_in_one_line_without_a_traceback() -> None:
    app = Path(__file__).resolve().parents[1] / "apps_xml" / "kuka_rsi_demo.xml"
    out, err = io.StringIO(), io.StringIO()
    options = ["simulator=accelerated", "sim_root_attribute=Kind", "connect_timeout=0.5"]
    code = cli_main(["run", str(app), "--robot", "kuka-rsi", *(a for o in options for a in ("--backend-option", o)), "-q"], out, err)
    assert code != 0
    text = err.getvalue()
    assert "no valid packet from kuka (127.0.0.1) within 0.5 s:" in text and "all refused: " in text
    assert "root attribute: <Rob> has no Type attribute (its attributes: Kind)" in text
    assert "Traceback" not in text + out.getvalue()


@pytest.mark.parametrize("holdon", ["1", "0"])
def test_relative_corrections_with_dropped_replies_still_end_on_every_target(rig: Callable[..., Rig], holdon: str) -> None:
    """Relative mode: a dropped increment is repeated (HOLDON=1) or lost (HOLDON=0) by the
    controller; the external system knows which from RSI's rules and goes on from there."""
    context = RsiContext(start_deg=READY, correction_mode="relative")
    r = rig(context=context, config=holdon_config(holdon), faults=Faults(drop=0.05, seed=3)).start()
    r.correcting()
    here = r.iface.state(0).tcp()
    goal = here.translated(0.05, 0.1, -0.05)
    ok, message, _ = r.done(r.iface.set_cart_pos(0, goal, 0.3, 2.0))
    assert ok, message
    assert np.linalg.norm(ARM.fk(r.sim.model.trace[-1])[:3, 3] - goal.position) < 1e-9  # type: ignore[index]
    target = np.radians([20, -70, 80, 10, 40, 10])
    ok, message, _ = r.done(r.iface.set_axial_pos(0, target, 1.0, 5.0))
    assert ok, message
    assert np.allclose(r.sim.model.trace[-1], target, atol=1e-9)  # type: ignore[index]
    assert r.sim.model.stats.dropped > 0 and r.sim.model.stats.late > 0 and r.sim.running
    loop = r.iface.loop
    assert loop is not None and loop.channels[0].motion.clamped == 0 and loop.channels[0].fault is None
    assert np.all(np.abs(_steps(r.sim.model.trace)) <= VMAX * DT + 1e-9)  # type: ignore[arg-type]
