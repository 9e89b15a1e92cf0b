"""The Nextage simulator as a robot back end: every primitive, timing, pause/resume/stop, vision,
master/slave and full-body moves, all in simulated time."""
from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, TypeVar

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    RecordTrajectory,
    SetSpeed,
    Vision,
)
from core_functions.robots import NEXTAGE_OPEN
from node_transport.clock import Clock, run_with_clock, scaled_clock, simulated_clock
from node_transport import codec
from node_transport.wire import CellFrame, CellSnapshot
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.nextage_sim.backend import NextageSimBackend, create

T = TypeVar("T")
Run = Callable[[Callable[[Clock], Coroutine[Any, Any, T]]], T]
LEFT = NEXTAGE_OPEN.group("left_arm").joint_names
RIGHT = NEXTAGE_OPEN.group("right_arm").joint_names


def joints(backend: NextageSimBackend, names: tuple[str, ...]) -> np.ndarray:
    all_names, values = backend.joint_state()
    return np.array([values[all_names.index(n)] for n in names])


async def watch(clock: Clock, work: Awaitable[T], probe: Callable[[], Any], period: float = 0.01) -> tuple[T, list[tuple[float, Any]]]:
    """Run ``work`` while recording ``(run time, probe())`` every ``period``."""
    task = asyncio.ensure_future(work)
    samples = []
    while not task.done():
        samples.append((clock.now(), probe()))
        await clock.sleep(period)
    return await task, samples


async def timed(clock: Clock, work: Awaitable[T]) -> tuple[T, float]:
    start = clock.now()
    result = await work
    return result, clock.now() - start


# ------------------------------------------------------------------------- joint motion
def test_joint_move_duration_follows_velocity_acceleration_and_speed(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        move = MoveJoints((1.0,), joint_names=("LARM_JOINT0",), relative=True)  # 0.6 deg -> 57.9 deg
        _, full = await timed(clock, backend.execute("left_arm", move))
        assert full == pytest.approx(1.0 / 1.0 + 1.0 / 1.5, abs=1e-6)  # d/v + v/a
        await backend.execute("left_arm", SetSpeed(0.5))
        back = MoveJoints((-1.0,), joint_names=("LARM_JOINT0",), relative=True)
        result, half = await timed(clock, backend.execute("left_arm", back))
        assert half == pytest.approx(2 * full, abs=1e-6)
        assert result.positions[0] == pytest.approx(math.radians(0.6))
        assert backend.speed("right_arm") == 1.0  # speed is per group
        _, torso = await timed(clock, backend.execute("torso_head", MoveJoints((1.0, 0.0, 0.0))))
        assert torso == pytest.approx(1.0 / 0.5 + 0.5 / 1.5, abs=1e-6)  # torso: 0.5 rad/s

    run_sim(main)


def test_joint_move_is_visible_in_progress_synchronised_and_within_velocity(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = joints(backend, LEFT)
        goal = start + np.array([0.6, -0.4, 0.5, 0.2, -0.3, 1.2])
        result, samples = await watch(clock, backend.execute("left_arm", MoveJoints(tuple(goal))), lambda: joints(backend, LEFT))
        np.testing.assert_allclose(result.positions, goal, atol=1e-12)
        positions = np.array([s[1] for s in samples])
        times = np.array([s[0] for s in samples])
        assert len(samples) > 50  # the motion was observable while it ran
        fractions = (positions - start) / (goal - start)
        assert np.all(np.ptp(fractions, axis=1) < 1e-9)  # all joints the same share of the way
        speeds = np.abs(np.diff(positions, axis=0)) / np.diff(times)[:, None]
        assert speeds.max() <= 1.0 + 1e-6

    run_sim(main)


@settings(max_examples=25)
@given(st.data(), st.floats(0.1, 1.0))
def test_any_arm_move_takes_the_limiting_joints_trapezoid_time(data: st.DataObject, speed: float) -> None:
    """Arm joints share v = 1 rad/s and a = 1.5 rad/s^2, so the joint travelling farthest sets the time."""
    specs = NEXTAGE_OPEN.group("left_arm").joints
    goal = tuple(data.draw(st.floats(j.lower, j.upper), label=j.name) for j in specs)

    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        await backend.execute("left_arm", SetSpeed(speed))
        distance = float(np.max(np.abs(np.array(goal) - joints(backend, LEFT))))
        v, a = 1.0 * speed, 1.5 * speed * speed
        expected = distance / v + v / a if distance >= v * v / a else 2.0 * math.sqrt(distance / a)
        result, duration = await timed(clock, backend.execute("left_arm", MoveJoints(goal)))
        assert duration == pytest.approx(expected, abs=1e-6)
        np.testing.assert_allclose(result.positions, goal, atol=1e-12)

    run_with_clock(main, simulated_clock())


def test_joint_limit_target_is_refused_before_moving(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        before = backend.joint_state()
        with pytest.raises(BridgeError) as info:
            await backend.execute("right_arm", MoveJoints((0.0, 0.0, 0.3, 0.0, 0.0, 0.0)))
        assert info.value.kind is FaultKind.JOINT_LIMIT
        assert "RARM_JOINT2 = 0.3000 rad (17.19 deg)" in str(info.value)
        with pytest.raises(BridgeError) as relative:
            await backend.execute("left_arm", MoveJoints((-3.0,), joint_names=("LARM_JOINT4",), relative=True))
        assert relative.value.kind is FaultKind.JOINT_LIMIT and "LARM_JOINT4" in str(relative.value)
        assert backend.joint_state() == before and clock.now() == 0.0

    run_sim(main)


def test_bad_joint_requests_name_the_problem(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        with pytest.raises(BridgeError, match="6 joint positions needed, got 3"):
            await backend.execute("left_arm", MoveJoints((0.0, 0.0, 0.0)))
        with pytest.raises(BridgeError, match="RARM_JOINT0 not among its joints"):
            await backend.execute("left_arm", MoveJoints((0.0,), joint_names=("RARM_JOINT0",)))
        with pytest.raises(BridgeError, match="no group 'base'"):
            await backend.execute("base", Dwell(1.0))

    run_sim(main)


# --------------------------------------------------------------------- Cartesian motion
def test_ptp_and_linear_cartesian_moves_reach_the_target(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("right_arm")
        assert start is not None
        target = start.translated(0.08, 0.05, 0.06)
        ptp = await backend.execute("right_arm", MoveCartesian(target, "ptp"))
        assert ptp.tcp.distance_to(target) < 2e-5 and ptp.tcp.angle_to(target) < 2e-4
        back = await backend.execute("right_arm", MoveCartesian(start, "linear"))
        assert back.tcp.distance_to(start) < 2e-5

    run_sim(main)


def test_linear_move_stays_on_the_line_at_bounded_tcp_speed(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("left_arm")
        assert start is not None
        target = start.translated(0.12, -0.1, 0.1)
        _, samples = await watch(clock, backend.execute("left_arm", MoveCartesian(target, "linear")), lambda: backend.tcp_pose("left_arm"))
        p0, p1 = np.array(start.position), np.array(target.position)
        axis = (p1 - p0) / np.linalg.norm(p1 - p0)
        for _, tcp in samples:
            offset = np.array(tcp.position) - p0
            assert np.linalg.norm(offset - (offset @ axis) * axis) < 2e-4  # 0.2 mm off the line at most
            assert tcp.angle_to(start) < math.radians(0.05)  # same orientation all the way
        speeds = [b[1].distance_to(a[1]) / (b[0] - a[0]) for a, b in zip(samples, samples[1:])]
        assert max(speeds) <= 0.25 * 1.01
        assert max(speeds) > 0.1  # and it does go fast when it can

    run_sim(main)


def test_move_relative_in_world_and_tool_frames(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("left_arm")
        assert start is not None
        world = await backend.execute("left_arm", MoveRelative(Pose(0.0, 0.0, 0.05), "world"))
        assert world.tcp.distance_to(start.translated(0.0, 0.0, 0.05)) < 2e-5
        tool = await backend.execute("left_arm", MoveRelative(Pose(0.03, 0.0, 0.0), "tool"))
        # the flange x axis points up at the initial orientation: +3 cm along it is +3 cm in z
        assert tool.tcp.distance_to(start.translated(0.0, 0.0, 0.08)) < 2e-4
        turned = await backend.execute("left_arm", MoveRelative(Pose.from_xyz_rpy(0, 0, 0, 0, 0, 0.3), "world", "ptp"))
        assert turned.tcp.distance_to(tool.tcp) < 2e-5
        assert turned.tcp.angle_to(tool.tcp) == pytest.approx(0.3, abs=1e-4)

    run_sim(main)


def test_unreachable_target_fails_before_moving_and_names_arm_and_target(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        before = backend.joint_state()
        target = Pose.from_xyz_rpy(0.95, 0.2, 0.3)
        for interpolation in ("ptp", "linear"):
            with pytest.raises(BridgeError) as info:
                await backend.execute("left_arm", MoveCartesian(target, interpolation))  # type: ignore[arg-type]
            assert info.value.kind is FaultKind.UNREACHABLE
            assert "left_arm" in str(info.value) and "(0.9500, 0.2000, 0.3000) m" in str(info.value)
        assert backend.joint_state() == before and clock.now() == 0.0
        with pytest.raises(BridgeError) as no_tcp:
            await backend.execute("torso_head", MoveCartesian(target))
        assert no_tcp.value.kind is FaultKind.UNSUPPORTED

    run_sim(main)


def test_tool_offset_moves_the_tcp(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock, tools={"left_arm": Pose(-0.12, 0.0, 0.0)})
        tcp = backend.tcp_pose("left_arm")
        flange = backend.model.frame_pose(backend.model.named_pose("initial"), "LARM_JOINT5_Link")
        assert tcp is not None and tcp.z == pytest.approx(flange.z - 0.12, abs=1e-3)
        target = tcp.translated(0.05, 0.0, -0.02)
        result = await backend.execute("left_arm", MoveCartesian(target, "linear"))
        assert result.tcp.distance_to(target) < 2e-5

    run_sim(main)


# ----------------------------------------------------------------- pause, resume, stop
def test_pause_holds_mid_motion_and_resume_reaches_the_same_target(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("left_arm")
        assert start is not None
        target = start.translated(0.1, 0.0, 0.08)
        reference = NextageSimBackend(clock)
        _, duration = await timed(clock, reference.execute("left_arm", MoveCartesian(target, "linear")))
        t0 = clock.now()
        task = asyncio.ensure_future(backend.execute("left_arm", MoveCartesian(target, "linear")))
        await clock.sleep(0.4)
        await backend.pause("left_arm")
        held = backend.tcp_pose("left_arm")
        assert held is not None and 0.01 < held.distance_to(start) < target.distance_to(start) - 0.01
        await clock.sleep(1.0)
        assert backend.tcp_pose("left_arm") == held and not task.done()
        await backend.resume("left_arm")
        result = await task
        assert result.tcp.distance_to(target) < 2e-5
        assert clock.now() - t0 == pytest.approx(duration + 1.0, abs=1e-6)  # the pause added exactly its length

    run_sim(main)


def test_stop_abandons_the_motion_raises_stopped_and_frees_the_group(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        task = asyncio.ensure_future(backend.execute("right_arm", MoveJoints((0.0, -0.5, -1.0, 0.0, 0.0, 0.0))))
        await clock.sleep(0.3)
        await backend.stop("right_arm")
        with pytest.raises(BridgeError) as info:
            await task
        assert info.value.kind is FaultKind.STOPPED
        stopped_at = joints(backend, RIGHT)
        await clock.sleep(1.0)
        np.testing.assert_array_equal(joints(backend, RIGHT), stopped_at)  # holds where it stopped
        assert abs(stopped_at[1] - (-0.5)) > 0.1  # short of the target
        done = await backend.execute("right_arm", Dwell(0.1))  # the group is free again
        assert done.positions == tuple(stopped_at)

    run_sim(main)


def test_paused_dwell_and_stop_while_paused(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        task = asyncio.ensure_future(backend.execute("torso_head", Dwell(1.0)))
        await clock.sleep(0.5)
        await backend.pause("torso_head")
        await clock.sleep(2.0)
        await backend.resume("torso_head")
        await task
        assert clock.now() == pytest.approx(3.0)
        paused = asyncio.ensure_future(backend.execute("torso_head", Dwell(1.0)))
        await clock.sleep(0.2)
        await backend.pause("torso_head")
        await backend.stop("torso_head")
        with pytest.raises(BridgeError, match="stopped"):
            await paused

    run_sim(main)


def test_second_primitive_for_a_busy_group_is_refused(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        task = asyncio.ensure_future(backend.execute("left_arm", Dwell(1.0)))
        await clock.sleep(0.1)
        with pytest.raises(BridgeError) as info:
            await backend.execute("left_arm", SetSpeed(0.5))
        assert info.value.kind is FaultKind.BUSY
        await backend.execute("right_arm", Dwell(0.2))  # other groups are independent
        await task
        assert backend.speed("left_arm") == 1.0

    run_sim(main)


# ------------------------------------------------------------ full body, master/slave
def test_full_body_move_holds_all_groups_and_moves_fifteen_joints(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        off = NEXTAGE_OPEN.poses["off"]
        names = NEXTAGE_OPEN.joint_names
        move = FullBodyMove(names, tuple(off[n] for n in names))
        task = asyncio.ensure_future(timed(clock, backend.execute("left_arm", move)))
        await clock.sleep(0.1)
        for group in ("right_arm", "torso_head"):
            with pytest.raises(BridgeError) as info:
                await backend.execute(group, Dwell(0.1))
            assert info.value.kind is FaultKind.BUSY
        result, duration = await task
        assert result.joint_names == names
        np.testing.assert_allclose(result.positions, [off[n] for n in names], atol=1e-12)
        assert duration > 2.0  # LARM_JOINT1 travels 140 deg at <= 1 rad/s
        await backend.execute("right_arm", Dwell(0.1))

    run_sim(main)


def test_the_same_full_body_move_from_two_groups_is_one_motion(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        names = NEXTAGE_OPEN.joint_names
        move = FullBodyMove(names, tuple(0.0 for _ in names))
        (first, t_first), (second, t_second) = await asyncio.gather(
            timed(clock, backend.execute("left_arm", move)), timed(clock, backend.execute("right_arm", move))
        )
        assert t_first == pytest.approx(t_second) and first.positions == second.positions
        assert second.tcp == backend.tcp_pose("right_arm")  # each group gets its own TCP
        other = FullBodyMove(names[:1], (0.3,))
        task = asyncio.ensure_future(backend.execute("left_arm", other))
        await clock.sleep(0.1)
        with pytest.raises(BridgeError) as info:  # a different command is no partner: busy
            await backend.execute("torso_head", FullBodyMove(names[:1], (0.2,)))
        assert info.value.kind is FaultKind.BUSY
        await task

    run_sim(main)


def test_master_slave_keeps_the_offset_along_the_path(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        left, right = backend.tcp_pose("left_arm"), backend.tcp_pose("right_arm")
        assert left is not None and right is not None
        offset = left.inverse().compose(right)
        path = (left.translated(0.06, 0.0, 0.04), left.translated(0.06, 0.0, 0.1).compose(Pose.from_xyz_rpy(0, 0, 0, 0.15, 0, 0)))
        move = MasterSlaveMove("left_arm", "right_arm", path)  # offset None: keep the one at the start

        def relative() -> tuple[Pose, Pose]:
            a, b = backend.tcp_pose("left_arm"), backend.tcp_pose("right_arm")
            assert a is not None and b is not None
            return a, a.inverse().compose(b)

        result, samples = await watch(clock, backend.execute("left_arm", move), relative)
        assert len(samples) > 20
        for _, (_, rel) in samples:
            assert rel.distance_to(offset) < 3e-4 and rel.angle_to(offset) < math.radians(0.05)
        assert result.tcp.distance_to(path[-1]) < 2e-5
        slave = backend.tcp_pose("right_arm")
        assert slave is not None and slave.distance_to(path[-1].compose(offset)) < 5e-5

    run_sim(main)


def test_master_slave_with_an_explicit_offset_first_joins_it(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        left = backend.tcp_pose("left_arm")
        assert left is not None
        offset = Pose(0.0, -0.3, 0.0)  # slave 30 cm along the master's -y
        path = (left.translated(0.05, 0.0, 0.0), left.translated(0.05, 0.0, 0.06))
        await backend.execute("left_arm", MasterSlaveMove("left_arm", "right_arm", path, offset))
        a, b = backend.tcp_pose("left_arm"), backend.tcp_pose("right_arm")
        assert a is not None and b is not None
        assert a.inverse().compose(b).distance_to(offset) < 5e-5
        with pytest.raises(BridgeError, match="without a master path"):
            await backend.execute("right_arm", MasterSlaveMove("left_arm", "right_arm"))

    run_sim(main)


# -------------------------------------------------------------------- trajectories
def test_planned_trajectory_does_not_move_and_replays_at_the_set_speed(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        start = backend.tcp_pose("left_arm")
        assert start is not None
        waypoints = (start.translated(0.05, 0.0, 0.05), start.translated(0.1, -0.05, 0.05))
        before = backend.joint_state()
        plan = await backend.execute("left_arm", RecordTrajectory("approach", "plan", waypoints, "linear", sample_period=0.05))
        assert backend.joint_state() == before and clock.now() == 0.0
        assert plan.joint_names == LEFT and len(plan.points) == len(plan.times) > 5
        await backend.execute("left_arm", SetSpeed(0.5))
        replay = ExecuteTrajectory("approach", plan.joint_names, plan.points, plan.times)
        result, duration = await timed(clock, backend.execute("left_arm", replay))
        assert duration == pytest.approx(plan.times[-1] / 0.5, abs=1e-6)
        assert result.tcp.distance_to(waypoints[-1]) < 2e-5

    run_sim(main)


def test_taught_trajectory_samples_what_the_hand_did(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        with pytest.raises(ValueError, match="not teaching"):
            backend.guide("right_arm", (0.0,) * 6)
        task = asyncio.ensure_future(backend.execute("right_arm", RecordTrajectory("taught", "teach", duration=1.0, sample_period=0.25)))
        start = joints(backend, RIGHT)
        await clock.sleep(0.6)
        guided = start + np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
        backend.guide("right_arm", tuple(guided))
        trajectory = await task
        assert trajectory.times == pytest.approx((0.0, 0.25, 0.5, 0.75, 1.0))
        np.testing.assert_allclose(trajectory.points[2], start)
        np.testing.assert_allclose(trajectory.points[3], guided)

    run_sim(main)


def test_trajectory_checks_limits_and_joint_names(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        beyond = ExecuteTrajectory("bad", ("LARM_JOINT0",), ((0.0,), (2.0,)), (0.0, 5.0))
        with pytest.raises(BridgeError) as limit:
            await backend.execute("left_arm", beyond)
        assert limit.value.kind is FaultKind.JOINT_LIMIT and "point 1 of trajectory 'bad'" in str(limit.value)
        too_fast = ExecuteTrajectory("fast", ("LARM_JOINT0",), ((0.0,), (1.0,)), (0.0, 0.5))
        with pytest.raises(BridgeError) as speed:
            await backend.execute("left_arm", too_fast)
        assert speed.value.kind is FaultKind.JOINT_LIMIT and "LARM_JOINT0 would move at" in str(speed.value)
        with pytest.raises(BridgeError, match="outside"):
            await backend.execute("left_arm", ExecuteTrajectory("other", ("RARM_JOINT0",), ((0.0,),), (0.0,)))

    run_sim(main)


# ---------------------------------------------------------------- hands and cameras
def test_end_effector_actions_take_time_and_set_outputs(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        result, duration = await timed(clock, backend.execute("left_arm", EndEffector("gripper_close")))
        assert result.io["gripper_closed"] is True and duration == pytest.approx(0.5)
        result = await backend.execute("left_arm", EndEffector("hand_draw_in"))
        assert result.io["hand_draw_in"] and not result.io["hand_release"]
        result = await backend.execute("left_arm", EndEffector("hand_release"))
        assert result.io["hand_release"] and not result.io["hand_draw_in"]
        assert backend.hand_io("right_arm")["gripper_closed"] is False  # hands are independent
        with pytest.raises(BridgeError) as info:
            await backend.execute("torso_head", EndEffector("air_on"))
        assert info.value.kind is FaultKind.UNSUPPORTED

    run_sim(main)


def _cell(backend: NextageSimBackend, nominal: Pose, truth: Pose) -> None:
    backend.set_cell(
        CellSnapshot(
            name="cell",
            frames=(CellFrame("hole_1", nominal), CellFrame("gauge", nominal, attributes={"value": "0.0125"})),
            truth={"hole_1": truth},
        )
    )


def test_vision_locate_returns_the_true_pose(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock, seed=7)
        tcp = backend.tcp_pose("left_arm")
        assert tcp is not None
        nominal = Pose(tcp.x + 0.1, tcp.y, tcp.z - 0.1)
        truth = nominal.translated(0.002, -0.0015, 0.0)
        _cell(backend, nominal, truth)
        result, duration = await timed(clock, backend.execute("left_arm", Vision("locate", "hole_1")))
        assert result.pose.distance_to(truth) < 1e-3 and result.pose.distance_to(nominal) > 2e-3
        assert duration > 0.0
        head = await backend.execute("torso_head", Vision("locate", "hole_1", camera="head_camera_left"))
        assert head.pose.distance_to(truth) < 1e-3
        measured = await backend.execute("left_arm", Vision("measure", "gauge"))
        assert measured.value == pytest.approx(0.0125, abs=1e-3)
        again = NextageSimBackend(clock, seed=7)
        _cell(again, nominal, truth)
        assert (await again.execute("left_arm", Vision("locate", "hole_1"))).pose == result.pose  # seeded

    run_sim(main)


def test_vision_fails_for_unknown_or_distant_features(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        tcp = backend.tcp_pose("right_arm")
        assert tcp is not None
        _cell(backend, Pose(tcp.x + 0.1, tcp.y, tcp.z), Pose(tcp.x + 0.1, tcp.y, tcp.z))
        with pytest.raises(BridgeError) as unknown:
            await backend.execute("right_arm", Vision("locate", "hole_99"))
        assert unknown.value.kind is FaultKind.VISION and "hole_99" in str(unknown.value)
        far = Pose(tcp.x + 1.0, tcp.y, tcp.z)
        with pytest.raises(BridgeError) as distant:
            await backend.execute("right_arm", Vision("locate", "far", nominal=far))
        assert distant.value.kind is FaultKind.VISION and "right_hand_camera" in str(distant.value)
        near = await backend.execute("right_arm", Vision("locate", "near", nominal=Pose(tcp.x + 0.2, tcp.y, tcp.z)))
        assert near.pose is not None

    run_sim(main)


# ------------------------------------------------------------------- clocks, options
def test_the_simulator_runs_on_a_scaled_real_clock() -> None:
    async def main(clock: Clock) -> tuple[float, float]:
        backend = NextageSimBackend(clock, control_period=0.05)
        move = MoveJoints((0.3,), joint_names=("LARM_JOINT0",), relative=True)
        result, duration = await timed(clock, backend.execute("left_arm", move))
        return duration, result.positions[0]

    duration, reached = run_with_clock(main, scaled_clock(200.0))
    assert duration >= 2.0 * math.sqrt(0.3 / 1.5) - 1e-9  # run time: never sooner than planned (a 0.3 rad triangle)
    assert reached == pytest.approx(math.radians(0.6) + 0.3)


def test_registry_factory_reads_the_options(run_sim: Run[None]) -> None:
    async def main(clock: Clock) -> None:
        options = BackendOptions(
            NEXTAGE_OPEN, faults=("right_arm:joint_limit@0.5",), seed=3, extra={"initial_pose": "off", "control_period": "0.02"}
        )
        backend = await create(clock, options)
        assert backend.control_period == 0.02
        assert joints(backend, RIGHT)[1] == pytest.approx(math.radians(-140))
        assert [str(f) for f in backend.pending_faults] == ["right_arm:joint_limit@0.5"]
        with pytest.raises(ValueError, match="takes no host"):
            await create(clock, BackendOptions(NEXTAGE_OPEN, host="10.0.0.2"))
        with pytest.raises(ValueError, match="unknown option"):
            await create(clock, BackendOptions(NEXTAGE_OPEN, extra={"speed": "2"}))

    run_sim(main)


def test_every_result_survives_the_wire_codec(run_sim: Run[None]) -> None:
    """The bridge node sends results as JSON; numpy scalars or arrays must not leak into them."""

    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        tcp = backend.tcp_pose("left_arm")
        assert tcp is not None
        _cell(backend, tcp.translated(0.1, 0, 0), tcp.translated(0.1, 0.001, 0))
        primitives: list[Primitive] = [
            MoveJoints((0.1,), ("LARM_JOINT0",), True),
            Vision("inspect", "hole_1"),
            Vision("measure", "hole_1"),
            EndEffector("air_on"),
            RecordTrajectory("x", waypoints=(tcp,)),
        ]
        for primitive in primitives:
            result = await backend.execute("left_arm", primitive)
            assert codec.from_primitive(type(result), codec.to_primitive(result), source="test") == result

    run_sim(main)
