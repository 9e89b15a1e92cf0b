"""Conservative advancement finds what dense sampling finds, and what a fixed 20 ms sampling steps over.

Must show (issue 22 item 2): the dry run's guarantee is not weakened -- on random two-arm motions
every pair of bodies that 1 ms sampling finds closer than the margin (less the sweep's stated
resolution) and every pair it finds touching, the sweep finds too; a thin obstacle that the
former fixed 20 ms samples step over is found; the speed bounds the sweep steps by are never
exceeded by the simulator's own motions; the simulator checks each motion once, not every tick,
and still stops where two bodies touch.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.primitives import MoveJoints
from core_functions.robots import KUKA_KR, NEXTAGE_OPEN
from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.collision import CellBox, scene_for
from robot_bridges.collision.sweep import RESOLUTION, Track, sweep_tracks
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.nextage_sim.model import NextageModel
from robot_bridges.nextage_sim.trajectory import Chain, plan_joint_move, plan_replay

MODEL = NextageModel()
NEXTAGE = scene_for(NEXTAGE_OPEN)
NEXTAGE.set_cell([
    CellBox("part", Pose.from_xyz_rpy(0.34, 0.0, -0.005), (0.12, 0.2, 0.01)),
    CellBox("tray", Pose.from_xyz_rpy(0.30, 0.25, 0.0), (0.1, 0.1, 0.04)),
    CellBox("post", Pose.from_xyz_rpy(0.45, -0.2, 0.1), (0.004, 0.004, 0.3)),
])
INITIAL = MODEL.named_pose("initial")
LEFT = NEXTAGE_OPEN.group("left_arm").joint_names


def line(scene, group: str, a: np.ndarray, b: np.ndarray, start: float, duration: float) -> Track:
    columns = np.array([scene.joint_names.index(n) for n in scene.robot.group(group).joint_names])

    def at(t: float) -> np.ndarray:
        return a + (b - a) * min(max(t / duration, 0.0), 1.0)

    return Track(columns, start, duration, at, np.abs(b - a) / duration)


def sampled(scene, q: np.ndarray, tracks: list[Track], step: float) -> dict[tuple[str, str], float]:
    """The closest distance of each pair closer than the margin at samples every ``step`` s (and at the ends)."""
    end = max(t.end for t in tracks)
    times = sorted({*np.arange(0.0, end, step).tolist(), *(t.end for t in tracks)})
    found: dict[tuple[str, str], float] = {}
    for time in times:
        probe = q.copy()
        for track in tracks:
            probe[track.columns] = track.at(time - track.start)
        for c in scene.contacts(probe):
            key = (c.a.label(), c.b.label())
            found[key] = min(found.get(key, math.inf), c.distance)
    return found


def swept(scene, q: np.ndarray, tracks: list[Track], threshold: float) -> dict[tuple[str, str], float]:
    found: dict[tuple[str, str], float] = {}
    for _, contacts in sweep_tracks(scene, q, tracks, threshold, start=0.0):
        for c in contacts:
            key = (c.a.label(), c.b.label())
            found[key] = min(found.get(key, math.inf), c.distance)
    return found


def arm_joints(draw: Callable, group: str) -> np.ndarray:
    idx = MODEL.indices(NEXTAGE_OPEN.group(group).joint_names)
    low, high = MODEL.lower[idx], MODEL.upper[idx]
    home = INITIAL[idx]
    return np.array([draw(st.floats(max(lo, h - 0.8), min(hi, h + 0.8))) for lo, hi, h in zip(low, high, home)])


@st.composite
def two_arm_motions(draw: Callable) -> list[Track]:
    tracks = []
    for group in ("left_arm", "right_arm"):
        a, b = arm_joints(draw, group), arm_joints(draw, group)
        speed = draw(st.floats(0.5, 1.0))  # rad/s of the joint that moves most (the Nextage's limit is 1)
        duration = max(float(np.max(np.abs(b - a))) / speed, 0.05)
        tracks.append(line(NEXTAGE, group, a, b, draw(st.floats(0.0, 0.5)), duration))
    return tracks


@settings(max_examples=10, deadline=None)
@given(two_arm_motions())
def test_the_sweep_finds_every_contact_dense_sampling_finds(tracks: list[Track]) -> None:
    """1 ms sampling against conservative advancement on random moves of both arms (straight in joint space,
    up to the Nextage's 1 rad/s), with the cell's plate, a tray and a 4 mm post: every pair sampling finds
    closer than the margin less the resolution, and every pair it finds touching, is in the sweep's findings,
    no closer than the sweep says by more than the resolution."""
    q = INITIAL.copy()
    margin = NEXTAGE.margin
    dense = sampled(NEXTAGE, q, tracks, 0.001)
    found = swept(NEXTAGE, q, tracks, margin)
    for pair, distance in dense.items():
        if distance < margin - RESOLUTION or distance <= 0.0:
            assert pair in found, (pair, distance, found)
            assert found[pair] <= max(distance, 0.0) + 2 * RESOLUTION + 0.5 * max(distance, 0.0), (pair, distance, found[pair])
    assert all(d < margin for d in found.values())


def test_a_thin_post_the_fixed_20_ms_samples_step_over_is_found() -> None:
    """A KUKA KR 6 R900 stretched out (TCP 0.89 m from A1) swings A1 at its 156 deg/s limit with a 200 mm tool
    pointing down; a 2 mm post pokes 2 mm into the tool's path.  The 20 ms samples fall 24 mm either side
    of it (11.7 mm clear, above the 10 mm margin): the former sweep saw nothing.  Conservative advancement
    finds the tool touching the post, as 0.5 ms sampling does."""
    scene = scene_for(KUKA_KR)
    scene.set_tool("arm", Pose.from_xyz_rpy(0.0, 0.0, 0.2, 0.0, 0.0, 0.0))
    q = np.array([0.0, -0.25, 0.3, 0.0, 1.5, 0.0])
    scene.place(q)
    tip = scene.tcp_matrix("arm")[:3, 3]
    top = tip[2] - 0.015 + 0.002  # the tool's capsule ends 15 mm past the TCP: 2 mm into it
    scene.set_cell([CellBox("post", Pose.from_xyz_rpy(tip[0], tip[1], top - 0.1), (0.002, 0.002, 0.2))])
    speed = 2.722713633111154  # rad/s: A1's limit in the URDF
    half = 4.5 * speed * 0.02  # 4.5 samples either side: the post falls half-way between two
    a, b = q.copy(), q.copy()
    a[0], b[0] = -half, half
    duration = 2 * half / speed
    swing = Track(np.arange(6), 0.0, duration, lambda t: a + (b - a) * min(max(t / duration, 0.0), 1.0), np.abs(b - a) / duration)

    assert sampled(scene, q, [swing], 0.02) == {}  # the former fixed step: nothing
    dense = sampled(scene, q, [swing], 0.0005)
    assert dense[("arm tool", "cell post")] < 0.0  # it does touch
    found = swept(scene, q, [swing], scene.margin)
    assert set(found) == {("arm tool", "cell post")} and found[("arm tool", "cell post")] <= 0.0


def random_motion(rng: np.random.Generator) -> tuple[object, np.ndarray]:
    idx = MODEL.indices(NEXTAGE_OPEN.group("left_arm").joint_names)
    velocity, acceleration = MODEL.velocity[idx], MODEL.acceleration[idx]
    a = INITIAL[idx] + rng.uniform(-0.5, 0.5, len(idx))
    b = INITIAL[idx] + rng.uniform(-0.5, 0.5, len(idx))
    move = plan_joint_move(idx, a, b, velocity, acceleration, float(rng.uniform(0.1, 1.0)))
    times = np.cumsum(np.r_[0.0, rng.uniform(0.2, 0.5, 4)])
    points = np.array([b + rng.uniform(-0.05, 0.05, len(idx)) * k for k in range(5)])
    replay = plan_replay(idx, [str(i) for i in idx], b, times, points, velocity * 10, acceleration, 1.0)
    return Chain([move, replay]), idx


@pytest.mark.parametrize("seed", range(5))
def test_no_joint_of_a_planned_motion_is_faster_than_its_speed_bound(seed: int) -> None:
    """The bound the sweep steps by holds at every half millisecond of a trapezoid move followed by a replay,
    over the whole motion and over any stretch of it (the bound of a stretch, smaller on a ramp)."""
    rng = np.random.default_rng(seed)
    motion, _ = random_motion(rng)
    times = np.arange(0.0, motion.duration, 0.0005)
    positions = np.array([motion.at(float(t)) for t in times])
    speeds = np.abs(np.diff(positions, axis=0)) / np.diff(times)[:, None]
    bound = motion.speed_bound()
    assert np.all(speeds <= bound * (1 + 1e-6) + 1e-9)
    assert np.all(np.max(speeds, axis=0) >= 0.9 * bound)  # and it is not loose
    for _ in range(20):
        a, b = sorted(rng.uniform(0.0, motion.duration, 2))
        inside = (times[:-1] >= a) & (times[1:] <= b)
        assert np.all(speeds[inside] <= motion.speed_bound(a, b) * (1 + 1e-6) + 1e-9)


def test_the_simulator_sweeps_a_motion_once_and_stops_it_where_the_arm_touches() -> None:
    """A 4 mm post stands where the left hand passes half-way through a shoulder turn: the simulator sweeps the
    motion once as it starts (not at each of its control periods), fails it with a collision fault naming the
    post, and leaves the arm where it touched (no deeper than the guard's 0.1 mm resolution, plus the margin
    of coal's distance), not a control period further in."""
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock, check_collisions=True)
        scene = backend.collisions
        assert scene is not None
        names, values = backend.joint_state()
        start = np.array(values)
        goal = start.copy()
        goal[names.index("LARM_JOINT0")] += 0.6
        mid = 0.5 * (start + goal)
        scene.place(np.array([mid[names.index(n)] for n in scene.joint_names]))
        hand = scene.gdata.oMg[[s.body.name for s in scene.layout().solids].index("LARM_JOINT5_Link")].translation
        scene.set_cell([CellBox("post", Pose.from_xyz_rpy(float(hand[0]), float(hand[1]), float(hand[2])), (0.004, 0.004, 0.4))])
        with pytest.raises(BridgeError) as info:
            await backend.execute("left_arm", MoveJoints(positions=tuple(goal[names.index(n)] for n in LEFT), joint_names=LEFT))
        assert info.value.kind is FaultKind.COLLISION and "collision between left_arm" in info.value.detail and "cell post" in info.value.detail
        ticks = round(float(info.value.detail.split("at t = ")[1].split(" s")[0]) / backend.control_period)
        assert ticks > 20 and backend._guard is not None and backend._guard.sweeps <= 2
        names, values = backend.joint_state()
        q = np.array([values[names.index(n)] for n in scene.joint_names])
        touching = [c.distance for c in scene.contacts(q) if "post" in (c.a.name, c.b.name)]
        assert touching and -0.001 <= min(touching) <= 0.0

    run_with_clock(main, simulated_clock())
