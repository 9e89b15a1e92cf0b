"""Jogging on the simulated clock: hold-to-move, the dead man, the caps, limits and collisions (operator_station/jog.py).

Every jog here runs the Nextage simulator in process on virtual time, with the heartbeats a page sends every
100 ms; "within one control cycle" is measured on that clock, and the arm not moving after the stop is read
from the simulator's own joints.
"""
from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.motion_profile import TcpLimits
from core_functions.primitives import MoveJoints
from core_functions.robots import NEXTAGE_OPEN, find_robot
from execution_engine.app_model.cell import Cell, load_cell
from node_transport.clock import Clock, run_with_clock, simulated_clock
from operator_station.jog_cartesian import ResolvedRates
from operator_station.jog import MAX_CARTESIAN, MAX_SPEED, Jogger, JogRequest, JogSettings, parse_request
from robot_bridges.backend import BackendOptions
from robot_bridges.collision import cell_boxes, scene_for
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
BEAT = 0.1  # s: the page's heartbeat


def jogging(body: Callable[[Clock, NextageSimBackend, Jogger], Awaitable[Any]], settings: JogSettings = JogSettings()) -> Any:
    """Run ``body`` with the simulator (collision check on) in the rivet cell and a jogger with its scene."""

    async def main(clock: Clock) -> Any:
        cell: Cell = load_cell(CELL).bind(NEXTAGE_OPEN)
        snapshot = cell.to_snapshot(NEXTAGE_OPEN)
        backend = NextageSimBackend(clock, check_collisions=True)
        backend.set_cell(snapshot)
        scene = scene_for(NEXTAGE_OPEN, margin=settings.clearance)
        scene.set_cell(cell_boxes(snapshot))
        jogger = Jogger(backend, clock, NEXTAGE_OPEN, settings, frames=cell.pose, scene=scene)
        try:
            return await body(clock, backend, jogger)
        finally:
            await jogger.stop("the test ends")
            await backend.close()

    return run_with_clock(main, simulated_clock())


async def hold(clock: Clock, jogger: Jogger, seconds: float, samples: list[tuple[float, np.ndarray]] | None = None) -> None:
    """Beat every 100 ms for ``seconds`` (the button held), sampling the joints each period if asked."""
    end = clock.now() + seconds
    next_beat = clock.now() + BEAT
    while clock.now() < end - 1e-9 and jogger.moving:
        await clock.sleep(jogger.period)
        if samples is not None:
            samples.append((clock.now(), np.array(jogger.backend.joint_state()[1])))
        if clock.now() >= next_beat - 1e-9:
            jogger.beat()
            next_beat += BEAT


def joint(backend: NextageSimBackend, name: str) -> float:
    names, positions = backend.joint_state()
    return positions[names.index(name)]


def test_a_joint_jog_moves_while_held_at_most_a_tenth_of_the_limit_and_stops_within_a_cycle_of_the_release() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> dict[str, Any]:
        start = joint(backend, "LARM_JOINT0")
        ok, _ = await jogger.start(JogRequest("left_arm", "joint", "LARM_JOINT0", 1))
        samples: list[tuple[float, np.ndarray]] = []
        await hold(clock, jogger, 3.0, samples)
        moved = joint(backend, "LARM_JOINT0") - start
        await jogger.stop("jog released")
        at_release = jogger.state
        await clock.sleep(1.0)  # nothing moves afterwards
        return {"ok": ok, "moved": moved, "samples": samples, "state": at_release, "after": joint(backend, "LARM_JOINT0"),
                "limit": backend.joint_limits("left_arm").velocity[0], "period": jogger.period}

    seen = jogging(body)
    assert seen["ok"] and seen["moved"] > 0.02  # it went the way asked while the beats came
    index = NEXTAGE_OPEN.joint_names.index("LARM_JOINT0")
    speeds = [abs(b[1][index] - a[1][index]) / (b[0] - a[0]) for a, b in zip(seen["samples"], seen["samples"][1:])]
    assert max(speeds) <= MAX_SPEED * seen["limit"] + 1e-9  # the cap: 10 % of the joint's speed limit
    reached = next(i for i, v in enumerate(speeds) if v >= 0.99 * MAX_SPEED * seen["limit"])
    assert seen["samples"][reached + 1][0] - seen["samples"][0][0] <= 0.1  # and at it within 0.1 s (full acceleration)
    state = seen["state"]
    assert not state.moving and state.reason == "jog released" and not state.refused
    assert state.stopped_at - state.stop_asked <= seen["period"] + 1e-9  # still within one control period
    assert state.travel_after_stop <= MAX_SPEED * seen["limit"] * seen["period"] + 1e-12  # at most one period's travel once asked
    assert seen["after"] == state.joints["LARM_JOINT0"]  # and nothing afterwards


def test_a_missed_heartbeat_stops_the_jog_within_a_control_cycle_of_the_lease() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> Any:
        await jogger.start(JogRequest("right_arm", "joint", "RARM_JOINT0", -1))
        await hold(clock, jogger, 1.0)
        last_beat = clock.now()
        jogger.beat()
        while jogger.moving and clock.now() < last_beat + 2.0:  # the page went quiet: no more beats
            await clock.sleep(jogger.period)
        return last_beat, jogger.state, jogger.period

    last_beat, state, period = jogging(body)
    lease = JogSettings().lease
    assert state.refused and "no heartbeat from the page for 0.30 s" in state.reason
    assert state.stop_asked == pytest.approx(last_beat + lease, abs=1e-9)  # asked the moment the lease ran out
    assert state.stopped_at - state.stop_asked <= period + 1e-9
    assert state.travel_after_stop <= MAX_SPEED * 1.0 * period + 1e-12  # the Nextage's joints: 1 rad/s


def test_a_jog_stops_at_the_joint_limit_and_a_jog_beyond_it_is_refused_naming_it() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> Any:
        limits = backend.joint_limits("left_arm")
        upper = limits.upper[limits.joint_names.index("LARM_JOINT5")]  # the wrist roll: 2.8449 rad
        await backend.execute("left_arm", MoveJoints((upper - 0.03,), ("LARM_JOINT5",)))  # 0.03 rad short of it
        await jogger.start(JogRequest("left_arm", "joint", "LARM_JOINT5", 1))
        await hold(clock, jogger, 60.0)
        reached, first = joint(backend, "LARM_JOINT5"), jogger.state
        ok, answer = await jogger.start(JogRequest("left_arm", "joint", "LARM_JOINT5", 1))
        return upper, reached, first, ok, answer

    upper, reached, first, ok, answer = jogging(body)
    assert reached == pytest.approx(upper, abs=1e-6) and reached <= upper + 1e-9  # stopped at the limit, never past
    assert first.refused and "LARM_JOINT5 is at its upper limit" in first.reason
    assert not ok and "LARM_JOINT5 is at its upper limit (2.8449 rad, 163.00 deg)" in answer


def test_a_jog_into_the_tray_is_stopped_before_it_touches_naming_the_bodies() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> Any:
        await jogger.start(JogRequest("right_arm", "cartesian", "z", -1, "world"))
        await hold(clock, jogger, 30.0)
        state = jogger.state
        names, positions = backend.joint_state()
        q = np.array(positions)[[names.index(n) for n in jogger.scene.joint_names]]
        touching = [c for c in jogger.scene.contacts(q) if c.distance <= 0]
        ok, answer = await jogger.start(JogRequest("right_arm", "cartesian", "z", -1, "world"))
        await hold(clock, jogger, 1.0)
        return state, touching, ok, answer, jogger.state

    state, touching, ok, answer, again = jogging(body)
    assert state.refused and state.reason.startswith("jog stopped before a collision: ")
    assert "cell rivet_tray" in state.reason or "cell part" in state.reason
    assert touching == []  # stopped short: nothing touches
    assert again.refused and again.reason.startswith("jog stopped before a collision")  # and pressing on is stopped again


def test_a_cartesian_jog_in_the_tool_frame_moves_along_the_tool_axis_and_keeps_the_orientation() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> Any:
        before = backend.tcp_pose("left_arm")
        await jogger.start(JogRequest("left_arm", "cartesian", "x", 1, "tool"))
        await hold(clock, jogger, 2.0)
        shown, now = jogger.state.tcp, backend.tcp_pose("left_arm")  # what the page is shown while it moves
        await jogger.stop("jog released")
        return before, backend.tcp_pose("left_arm"), shown, now

    before, after, shown, now = jogging(body)
    assert shown is not None and np.linalg.norm(np.array(shown[:3]) - np.array(now.position)) <= 0.05 * 0.1 + 1e-9  # at most 0.1 s behind
    moved = np.array(after.position) - np.array(before.position)
    axis = before.matrix()[:3, 0]  # the tool's x in the world
    assert np.linalg.norm(moved) > 0.005
    assert np.dot(moved, axis) / np.linalg.norm(moved) > 0.999  # along the tool's x, the way asked
    assert before.angle_to(after) < math.radians(0.2)
    assert 0.02 <= np.linalg.norm(moved) <= 0.05 * 2.0  # going within a fraction of a second, never above 50 mm/s


def test_a_cartesian_jog_in_a_cell_frame_moves_along_that_frames_axis() -> None:
    async def body(clock: Clock, backend: NextageSimBackend, jogger: Jogger) -> Any:
        before = backend.tcp_pose("left_arm")
        await jogger.start(JogRequest("left_arm", "cartesian", "x", 1, "drill_1"))  # drill_1's x is the world's y
        await hold(clock, jogger, 2.0)
        await jogger.stop("jog released")
        return before, backend.tcp_pose("left_arm"), jogger.frames("drill_1")

    before, after, frame = jogging(body)
    moved = np.array(after.position) - np.array(before.position)
    assert np.dot(moved, frame.matrix()[:3, 0]) / np.linalg.norm(moved) > 0.999


def test_requests_and_settings_out_of_their_ranges_are_one_line_refusals() -> None:
    frames = ("drill_1",)
    good = {"group": "left_arm", "mode": "joint", "axis": "LARM_JOINT0", "direction": 1}
    assert parse_request(good, NEXTAGE_OPEN, frames) == JogRequest("left_arm", "joint", "LARM_JOINT0", 1)
    for change, words in (({"group": "both"}, "group must be one of"), ({"axis": "RARM_JOINT0"}, "axis must be a joint of left_arm"),
                          ({"direction": 2}, "direction must be 1 or -1"), ({"direction": True}, "direction must be 1 or -1"),
                          ({"mode": "cartesian", "axis": "q"}, "axis must be one of x, y, z"),
                          ({"mode": "cartesian", "axis": "x", "frame": "drill_9"}, "frame must be world, tool or a frame"),
                          ({"speed": "fast"}, "speed must be a percentage")):
        with pytest.raises(ValueError, match=words):
            parse_request({**good, **change}, NEXTAGE_OPEN, frames)
    with pytest.raises(ValueError, match=r"jog speed must be in \(0, 10%\]"):
        JogSettings(speed=0.2)
    with pytest.raises(ValueError, match="percentage from 1 to 10"):
        JogSettings().slower(50.0 + 60.0)
    slower = JogSettings().slower(5.0)
    assert slower.speed == pytest.approx(0.05) and slower.cartesian_speed == pytest.approx(0.025)
    assert JogSettings().slower(50.0).speed == MAX_SPEED  # asking for more than the cap gives the cap


def test_on_vplus_a_jog_goes_in_short_legs_paced_to_the_cap_and_stops_at_the_end_of_the_leg_under_way() -> None:
    """V+ runs a motion to its end (AdeptServer): legs of 0.1 s of travel, whole-arm joint moves, never faster than the cap."""
    robot = find_robot("viper")

    async def main(clock: Clock) -> Any:
        backend = await create_backend("vplus", clock, BackendOptions(robot))  # its controller simulator, on loopback
        await backend.start()
        jogger = Jogger(backend, clock, robot)
        seen = []
        try:
            for request in (JogRequest("arm", "joint", "joint_1", 1), JogRequest("arm", "cartesian", "z", 1, "world")):
                before, began = backend.tcp_pose("arm"), clock.now()
                ok, answer = await jogger.start(request)
                await hold(clock, jogger, 2.0)
                await jogger.stop("jog released")
                seen.append((ok, answer, before.distance_to(backend.tcp_pose("arm")), clock.now() - began, jogger.state))
        finally:
            await backend.close()
        return seen

    (joint_ok, _, _, _, joint_state), (ok, _, moved, seconds, state) = run_with_clock(main, simulated_clock())
    assert joint_ok and joint_state.reason == "jog released"  # a whole-arm MoveJoints: V+ takes no single joint
    assert ok and state.reason == "jog released" and moved > 0.01
    assert moved / seconds <= MAX_CARTESIAN + 1e-9  # paced: the controller's own legs are quicker than the cap
    assert state.stopped_at - state.stop_asked <= JogSettings().short_leg + 1e-9  # at the latest, the end of the leg under way


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=12),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3), max_leaves=8)
FIELDS = {"group": st.sampled_from(["left_arm", "right_arm", "torso_head", "arm", ""]) | JSON,
          "mode": st.sampled_from(["joint", "cartesian", "Joint"]) | JSON,
          "axis": st.sampled_from(["LARM_JOINT0", "RARM_JOINT5", "CHEST_JOINT0", "x", "rz", "w"]) | JSON,
          "direction": st.sampled_from([1, -1, 0, 2, True, 1.0]) | JSON,
          "frame": st.sampled_from(["world", "tool", "drill_1", "nowhere"]) | JSON, "speed": st.none() | JSON}


@settings(max_examples=300, deadline=None)
@given(st.fixed_dictionaries({}, optional=FIELDS))
def test_any_message_of_a_page_is_a_jog_request_of_the_robot_or_a_one_line_refusal(body: dict[str, Any]) -> None:
    """A page's start message is outside input: whatever it holds, it is a request naming a group, a joint of that
    group (or an axis) and a direction of +-1, or ValueError in one line -- never another exception."""
    try:
        request = parse_request(body, NEXTAGE_OPEN, ("drill_1",))
    except ValueError as error:
        assert "\n" not in str(error) and str(error).startswith("jog: ")
        return
    assert request.group in NEXTAGE_OPEN.group_names and request.direction in (1, -1)
    joints = NEXTAGE_OPEN.group(request.group).joint_names
    assert request.axis in joints if request.mode == "joint" else request.axis in ("x", "y", "z", "rx", "ry", "rz")


def test_a_cartesian_leg_of_the_jogs_own_keeps_to_its_line_and_every_joint_under_its_cap() -> None:
    """Resolved rates (operator_station/jog_cartesian.py): the TCP on the line it was asked to follow, at most the
    Cartesian cap, every joint at most 10 % of its limit -- near the wrist's singularity too (the Nextage's
    initial pose has the wrist pitched -89.9 deg)."""
    scene = scene_for(NEXTAGE_OPEN)
    rates = ResolvedRates(scene)
    backend = NextageSimBackend(simulated_clock())
    names, positions = backend.joint_state()
    q = np.array(positions)[[names.index(n) for n in scene.joint_names]]
    limits = backend.joint_limits("left_arm")
    joints = NEXTAGE_OPEN.group("left_arm").joint_names
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.6, 0.8])):
        leg = rates.plan("left_arm", q, joints, limits, axis, False, MAX_SPEED, MAX_CARTESIAN, TcpLimits(), 1.0, 0.01)
        order = [scene.joint_names.index(n) for n in joints]
        tcps = []
        for point in leg.points:
            full = q.copy()
            full[order] = point
            scene.place(full)
            tcps.append(scene.tcp_matrix("left_arm")[:3, 3])
        steps = np.diff(np.array(leg.points), axis=0) / np.diff(leg.times)[:, None]
        assert np.all(np.abs(steps) <= MAX_SPEED * np.array(limits.velocity) + 1e-9)
        offsets = np.array(tcps) - tcps[0]
        along = offsets @ axis
        assert along[-1] > 0.005 and np.all(np.diff(along) >= -1e-9)  # forward along the axis, never back
        assert np.max(np.linalg.norm(offsets - np.outer(along, axis), axis=1)) < 5e-4  # on the line within 0.5 mm
        assert np.max(np.diff(along) / np.diff(leg.times)) <= MAX_CARTESIAN + 1e-9
