"""The V+ back end against the AdeptServer simulator: SI primitives in, V+ skills out, faults as BridgeErrors."""
from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from core_functions.geometry import Pose
from core_functions.primitives import (
    Dwell,
    EndEffector,
    FullBodyMove,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    SetSpeed,
    Vision,
)
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN
from node_transport.clock import Clock, real_clock, run_with_clock, scaled_clock, simulated_clock
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.vplus.backend import VPlusBackend, create
from robot_bridges.vplus.codec import Skill
from robot_bridges.vplus.kinematics import HOME_DEG, location_to_matrix, pose_to_location
from robot_bridges.vplus.measurement import SimulatedFocusCamera
from robot_bridges.vplus.sim_arm import AIR_SIGNAL, GRIPPER_CLOSE_SIGNAL
from robot_bridges.vplus.simulator import VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
READY = tuple(math.radians(v) for v in (0.0, -60.0, 150.0, 0.0, 60.0, 0.0))
DOWN = Pose(0.45, 0.1, 0.4, 0.0, 1.0, 0.0, 0.0)  # tool pointing straight down (180 deg about y)


@contextlib.asynccontextmanager
async def rig(clock: Clock, *, ack_timeout: float = 2.0, **sim_args: Any) -> AsyncIterator[tuple[VPlusSimulator, VPlusBackend]]:
    async with VPlusSimulator(clock, **sim_args) as sim:
        backend = VPlusBackend(clock, "127.0.0.1", sim.port, ack_timeout=ack_timeout, measurement=SimulatedFocusCamera(noise=0.0))
        await backend.start()
        try:
            yield sim, backend
        finally:
            await backend.close()


def skills(sim: VPlusSimulator) -> list[Skill]:
    return [m.command.skill for m in sim.received]


def sim_tcp(sim: VPlusSimulator) -> Pose:
    return Pose.from_matrix(sim.arm.kin.forward(sim.arm.joints()))


# ----------------------------------------------------------------------------- state
def test_start_learns_where_the_robot_is(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            assert skills(sim) == [Skill.BREAK]  # a lone break: harmless, and it reports the pose
            tcp = backend.tcp_pose("arm")
            assert tcp is not None and tcp.position == pytest.approx((0.48, 0.0, 0.71), abs=1e-6)
            names, positions = backend.joint_state()
            assert names == ADEPT_VIPER_S850.group("arm").joint_names
            assert np.degrees(positions) == pytest.approx(HOME_DEG, abs=1e-6)

    run_sim(main)


# --------------------------------------------------------------------------- motions
def test_joint_move_in_si_reaches_the_joints_in_degrees(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            result = await backend.execute("arm", MoveJoints(READY))
            assert isinstance(result, MotionResult)
            assert sim.received[-2].command.args == pytest.approx(np.degrees(READY))
            assert skills(sim)[-2:] == [Skill.MOVE_JOINTS, Skill.BREAK]
            assert sim.arm.joints() == pytest.approx(READY, abs=1e-9)
            assert result.positions == pytest.approx(READY, abs=1e-9)
            assert result.tcp is not None and result.tcp.distance_to(sim_tcp(sim)) < 1e-6

    run_sim(main)


def test_joint_names_in_another_order_are_put_in_group_order(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            names = ADEPT_VIPER_S850.group("arm").joint_names
            await backend.execute("arm", MoveJoints(tuple(reversed(READY)), tuple(reversed(names))))
            assert sim.arm.joints() == pytest.approx(READY, abs=1e-9)

    run_sim(main)


def test_relative_joint_move(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            delta = (math.radians(10), 0, 0, 0, 0, math.radians(-5))
            result = await backend.execute("arm", MoveJoints(delta, relative=True))
            assert skills(sim)[-2] is Skill.MOVE_REL_JOINTS
            expected = np.radians(HOME_DEG) + np.array(delta)
            assert sim.arm.joints() == pytest.approx(expected, abs=1e-9)
            assert result.positions == pytest.approx(expected, abs=1e-6)

    run_sim(main)


def test_a_joint_target_beyond_a_limit_fails_before_anything_is_sent(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            sent = len(sim.received)
            with pytest.raises(BridgeError, match=r"joint_1 180\.000 deg outside \[-170, 170\]") as caught:
                await backend.execute("arm", MoveJoints((math.pi, *READY[1:])))
            assert caught.value.kind is FaultKind.JOINT_LIMIT
            assert len(sim.received) == sent

    run_sim(main)


def test_cartesian_move_reaches_the_pose_through_mm_and_zyz_degrees(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", MoveCartesian(DOWN))
            x, y, z, yaw, pitch, roll = sim.received[-2].command.args
            assert (x, y, z) == pytest.approx((450, 100, 400), abs=1e-3)
            assert pitch == pytest.approx(180.0, abs=1e-3)  # the tool points down: pitch 180 in V+ terms
            reached = sim_tcp(sim)
            assert reached.distance_to(DOWN) < 2e-6 and reached.angle_to(DOWN) < 1e-4

    run_sim(main)


def test_the_euler_convention_on_the_wire_is_v_plus_z_y_z() -> None:
    # roll 0, pitch 90, yaw 90 about fixed axes (our rpy) is Rz(90) Ry(90): V+ yaw 90, pitch 90, roll 0
    pose = Pose.from_xyz_rpy(0.3, -0.2, 0.5, roll=0.0, pitch=math.pi / 2, yaw=math.pi / 2)
    assert pose_to_location(pose) == pytest.approx((300, -200, 500, 90, 90, 0), abs=1e-9)
    assert np.allclose(location_to_matrix(pose_to_location(pose)), pose.matrix(), atol=1e-12)


def test_an_unreachable_target_fails_before_anything_is_sent(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            sent = len(sim.received)
            with pytest.raises(BridgeError, match="outside the workspace") as caught:
                await backend.execute("arm", MoveCartesian(Pose(2.0, 0, 0.3, 0, 1, 0, 0)))
            assert caught.value.kind is FaultKind.UNREACHABLE
            assert len(sim.received) == sent

    run_sim(main)


def test_tool_relative_move_uses_move_rel_tool(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", MoveCartesian(DOWN))
            result = await backend.execute("arm", MoveRelative(Pose(0, 0, 0.01), reference="tool"))
            assert skills(sim)[-2] is Skill.MOVE_REL_TOOL
            assert sim.received[-2].command.args == pytest.approx((0, 0, 10, 0, 0, 0), abs=1e-9)
            assert result.tcp is not None and result.tcp.position == pytest.approx((0.45, 0.1, 0.39), abs=2e-6)

    run_sim(main)


def test_world_relative_translation_uses_move_rel_world(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", MoveCartesian(DOWN))
            await backend.execute("arm", MoveRelative(Pose(0.02, -0.01, 0.005)))
            assert skills(sim)[-2] is Skill.MOVE_REL_WORLD
            assert sim.received[-2].command.args == pytest.approx((20, -10, 5, 0, 0, 0), abs=1e-9)
            assert sim_tcp(sim).position == pytest.approx((0.47, 0.09, 0.405), abs=2e-6)

    run_sim(main)


def test_world_relative_rotation_turns_about_world_axes(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", MoveCartesian(DOWN))
            turn = Pose.from_xyz_rpy(0, 0, 0.01, yaw=math.radians(30))
            await backend.execute("arm", MoveRelative(turn))
            assert skills(sim)[-2] is Skill.MOVE_TO  # AdeptServer would add ZYZ angles component-wise
            expected = Pose(0.45, 0.1, 0.41, *Pose.from_matrix(turn.matrix() @ DOWN.matrix()).quaternion)
            reached = sim_tcp(sim)
            assert reached.distance_to(expected) < 2e-6 and reached.angle_to(expected) < 1e-4

    run_sim(main)


def test_linear_moves_can_be_refused_instead_of_run_joint_interpolated(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            backend = VPlusBackend(clock, "127.0.0.1", sim.port, linear="reject")
            await backend.start()
            with pytest.raises(BridgeError, match="joint-interpolated") as caught:
                await backend.execute("arm", MoveCartesian(DOWN, "linear"))
            assert caught.value.kind is FaultKind.UNSUPPORTED
            await backend.close()

    run_sim(main)


def test_speed_is_sent_before_every_motion_because_v_plus_speed_lasts_one_motion(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            start = clock.now()
            await backend.execute("arm", MoveJoints(READY))
            fast = clock.now() - start
            await backend.execute("arm", SetSpeed(0.1))
            start = clock.now()
            await backend.execute("arm", MoveJoints(tuple(np.radians(HOME_DEG))))
            slow = clock.now() - start
            await backend.execute("arm", MoveJoints(READY))
            assert skills(sim)[-6:] == [Skill.SET_SPEED, Skill.MOVE_JOINTS, Skill.BREAK] * 2
            assert [m.command.payload() for m in sim.received if m.command.skill is Skill.SET_SPEED] == ["set_speed:10"] * 2
            assert slow > 2.5 * fast

    run_sim(main)


# ------------------------------------------------------------------------ other skills
def test_air_and_gripper(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            result = await backend.execute("arm", EndEffector("air_on"))
            assert sim.arm.signals[AIR_SIGNAL] and result.io == {"air": True, "gripper_closed": False}
            result = await backend.execute("arm", EndEffector("gripper_close"))
            assert sim.arm.signals[GRIPPER_CLOSE_SIGNAL] and result.io == {"air": True, "gripper_closed": True}
            result = await backend.execute("arm", EndEffector("air_off"))
            assert not sim.arm.signals[AIR_SIGNAL] and result.io["air"] is False
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", EndEffector("hand_draw_in"))
            assert caught.value.kind is FaultKind.UNSUPPORTED

    run_sim(main)


def test_vision_goes_to_the_measurement_port(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (_, backend):
            await backend.execute("arm", MoveCartesian(DOWN))
            plane = DOWN.offset_local(dz=0.001)  # focus plane 1 mm further along the tool
            result = await backend.execute("arm", Vision("measure", target="focus_plane", nominal=plane))
            camera = backend.measurement
            assert isinstance(camera, SimulatedFocusCamera)
            assert result.value == pytest.approx(camera.sharpness(-0.001), rel=1e-6)
            with pytest.raises(BridgeError, match="focus plane") as caught:
                await backend.execute("arm", Vision("measure", target="nowhere"))
            assert caught.value.kind is FaultKind.VISION

    run_sim(main)


def test_what_adeptserver_cannot_do_is_unsupported(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            backend = VPlusBackend(clock, "127.0.0.1", sim.port)  # no measurement port
            await backend.start()
            for primitive in (FullBodyMove(("joint_1",), (0.0,)), Vision("measure", target="x")):
                with pytest.raises(BridgeError) as caught:
                    await backend.execute("arm", primitive)
                assert caught.value.kind is FaultKind.UNSUPPORTED
            with pytest.raises(BridgeError, match="no group 'left_arm'"):
                await backend.execute("left_arm", Dwell(0.1))
            await backend.close()

    run_sim(main)


# ------------------------------------------------------------------------------- faults
def test_a_skill_the_server_lacks_times_out_naming_peer_and_message(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        no_gripper = [s for s in Skill if s is not Skill.GRIPPER_OPEN]
        async with rig(clock, ack_timeout=1.5, skills=no_gripper) as (sim, backend):
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", EndEffector("gripper_open"))
            error = caught.value
            assert error.kind is FaultKind.TIMEOUT
            assert f"127.0.0.1:{sim.port}" in str(error) and "gripper_open" in str(error) and "no ack within 1.5 s" in str(error)
            await backend.execute("arm", MoveJoints(READY))  # resyncs and carries on
            assert skills(sim)[-3:] == [Skill.BREAK, Skill.MOVE_JOINTS, Skill.BREAK]  # the lone break resyncs first

    run_sim(main)


def test_a_lost_connection_is_a_connection_fault_and_the_motion_is_never_resent(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            sim.faults.drop_on.add("break")
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", MoveJoints(READY))
            error = caught.value
            assert error.kind is FaultKind.CONNECTION
            assert "unknown (sent, not acked)" in str(error) and ":break" in str(error)
            # the next primitive reconnects, learns where the arm went, and moves on
            result = await backend.execute("arm", MoveJoints(tuple(np.radians(HOME_DEG))))
            assert skills(sim).count(Skill.MOVE_JOINTS) == 2  # READY once (never resent), then home
            assert result.positions == pytest.approx(np.radians(HOME_DEG), abs=1e-9)

    run_sim(main)


def test_a_garbled_ack_is_a_protocol_fault(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            sim.faults.garble_acks = 1
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", EndEffector("air_on"))
            assert caught.value.kind is FaultKind.PROTOCOL and "malformed ack" in str(caught.value)

    run_sim(main)


def test_no_controller_is_a_connection_fault(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        sim = await VPlusSimulator(clock).start()
        port = sim.port
        await sim.close()
        backend = VPlusBackend(clock, "127.0.0.1", port, retries=1)
        with pytest.raises(BridgeError, match=r"cannot connect after 2 attempt\(s\)") as caught:
            await backend.start()
        assert caught.value.kind is FaultKind.CONNECTION and str(port) in str(caught.value)

    run_sim(main)


# ------------------------------------------------------------------- pause, resume, stop
def test_pause_lands_at_the_end_of_the_motion_and_resume_releases_the_result(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            call = asyncio.ensure_future(backend.execute("arm", MoveJoints(READY)))
            await clock.sleep(0.05)
            await backend.pause("arm")
            await clock.sleep(5.0)
            assert not sim.arm.moving and not call.done()  # arrived, result held while paused
            await backend.resume("arm")
            result = await call
            assert result.positions == pytest.approx(READY, abs=1e-9)

    run_sim(main)


def test_stop_abandons_at_once_and_the_next_primitive_queues_behind_the_motion(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (sim, backend):
            await backend.execute("arm", SetSpeed(0.05))
            call = asyncio.ensure_future(backend.execute("arm", MoveJoints(READY)))
            await clock.sleep(0.1)
            await backend.stop("arm")
            with pytest.raises(BridgeError) as caught:
                await call
            assert caught.value.kind is FaultKind.STOPPED
            assert sim.arm.moving  # the controller finishes the motion it started
            await backend.execute("arm", SetSpeed(1.0))
            result = await backend.execute("arm", MoveJoints(tuple(np.radians(HOME_DEG))))
            assert result.positions == pytest.approx(np.radians(HOME_DEG), abs=1e-9)
            assert sim.arm.joints() == pytest.approx(np.radians(HOME_DEG), abs=1e-9)

    run_sim(main)


def test_a_dwell_pauses_resumes_and_stops_exactly(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (_, backend):
            start = clock.now()
            call = asyncio.ensure_future(backend.execute("arm", Dwell(2.0)))
            await clock.sleep(0.5)
            await backend.pause("arm")
            await clock.sleep(3.0)
            await backend.resume("arm")
            await call
            assert clock.now() - start == pytest.approx(5.0, abs=1e-6)
            call = asyncio.ensure_future(backend.execute("arm", Dwell(10.0)))
            await clock.sleep(1.0)
            await backend.stop("arm")
            with pytest.raises(BridgeError) as caught:
                await call
            assert caught.value.kind is FaultKind.STOPPED

    run_sim(main)


def test_a_second_primitive_while_one_runs_is_busy(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with rig(clock) as (_, backend):
            call = asyncio.ensure_future(backend.execute("arm", Dwell(1.0)))
            await clock.sleep(0.1)
            with pytest.raises(BridgeError) as caught:
                await backend.execute("arm", Dwell(1.0))
            assert caught.value.kind is FaultKind.BUSY
            await call

    run_sim(main)


# ------------------------------------------------------------------------------ factory
def test_the_factory_starts_a_simulator_when_no_host_is_given(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = await create(clock, BackendOptions(robot=ADEPT_VIPER_S850))
        await backend.start()
        result = await backend.execute("arm", MoveJoints(READY))
        assert result.positions == pytest.approx(READY, abs=1e-9)
        assert isinstance(backend.measurement, SimulatedFocusCamera)
        await backend.close()

    run_sim(main)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (BackendOptions(robot=NEXTAGE_OPEN), "drives adept_viper_s850"),
        (BackendOptions(robot=ADEPT_VIPER_S850, rsi_listen="0.0.0.0:49152"), "rsi_listen"),
        (BackendOptions(robot=ADEPT_VIPER_S850, faults=("arm:joint_limit@0.5",)), "no --fault"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"speed": "2"}), "unknown option"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"timeout": "soon"}), "timeout must be a number"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"linear": "curvy"}), "linear must be"),
        (BackendOptions(robot=ADEPT_VIPER_S850, host="10.0.0.2", port=99999), "port must be"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"camera": "webcam"}), "camera must be"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"tolerance_mm": "0"}), r"vplus: tolerance_mm must be a number in \[0.01, 50\] mm, got 0$"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"tolerance_mm": "inf"}), r"tolerance_mm must be a number in \[0.01, 50\] mm, got inf$"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"tolerance_deg": "11"}), r"tolerance_deg must be a number in \[0.01, 10\] deg, got 11$"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"tolerance_deg": "wide"}), r"tolerance_deg must be a number in \[0.01, 10\] deg, got 'wide'$"),
        (BackendOptions(robot=ADEPT_VIPER_S850, extra={"sim_frozen_pose": "yes"}), "sim_frozen_pose is 0 or 1, got 'yes'"),
        (BackendOptions(robot=ADEPT_VIPER_S850, host="10.0.0.2", extra={"sim_frozen_pose": "1"}), r"a real one \(--host\) takes none"),
    ],
)
def test_the_factory_refuses_options_it_cannot_honour(options: BackendOptions, message: str) -> None:
    async def main(clock: Clock) -> None:
        with pytest.raises(ValueError, match=message):
            await create(clock, options)

    run_with_clock(main, real_clock())  # a real controller takes no speed factor


def test_the_factory_points_at_a_real_controller_without_a_simulator() -> None:
    async def main(clock: Clock) -> None:
        backend = await create(clock, BackendOptions(robot=ADEPT_VIPER_S850, host="192.0.2.10"))
        assert backend.client.peer == "192.0.2.10:1234" and backend.measurement is None
        demo = await create(clock, BackendOptions(robot=ADEPT_VIPER_S850, host="127.0.0.1", port=4321, extra={"camera": "simulated"}))
        assert isinstance(demo.measurement, SimulatedFocusCamera)
        assert backend.label == "vplus 192.0.2.10:1234" and backend.name == "vplus"

    run_with_clock(main, real_clock())


@pytest.mark.parametrize("clock_kind", ["scaled", "simulated"])
def test_a_real_controller_refuses_a_speed_factor(clock_kind: str) -> None:
    """Run time faster than real time would shorten every ack timeout of real motions."""

    async def main(clock: Clock) -> None:
        with pytest.raises(ValueError, match=r"the controller at 10.0.0.2 runs at x1 \(a real one in real time\): run with --speed 1"):
            await create(clock, BackendOptions(robot=ADEPT_VIPER_S850, host="10.0.0.2", port=1234))
        fast = BackendOptions(robot=ADEPT_VIPER_S850, host="127.0.0.1", port=1234, extra={"controller_speed": "10"})
        if clock.simulated:  # a network peer never runs on simulated time
            with pytest.raises(ValueError, match="runs at x10"):
                await create(clock, fast)
        else:  # a simulator at x10 behind --host, and the user said so
            assert (await create(clock, fast)).client.peer == "127.0.0.1:1234"

    run_with_clock(main, scaled_clock(10.0) if clock_kind == "scaled" else simulated_clock())
