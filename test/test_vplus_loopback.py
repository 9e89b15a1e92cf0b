"""Client and simulator over loopback TCP, on one virtual-time loop."""
from __future__ import annotations

import asyncio
import contextlib
import math
import socket
from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.vplus import codec
from robot_bridges.vplus.client import (
    CommandTimeout,
    ConnectError,
    ConnectionLost,
    ProtocolError,
    VPlusClient,
)
from robot_bridges.vplus.codec import Skill
from robot_bridges.vplus.kinematics import HOME_DEG, location_to_matrix, matrix_to_location
from robot_bridges.vplus.sim_arm import AIR_SIGNAL, GRIPPER_CLOSE_SIGNAL, GRIPPER_OPEN_SIGNAL
from robot_bridges.vplus.simulator import Faults, VPlusSimulator

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, Any]]], Any]
READY = (0.0, -60.0, 150.0, 0.0, 60.0, 0.0)  # a comfortable pose away from home


@contextlib.asynccontextmanager
async def cell(clock: Clock, **sim_args: Any) -> AsyncIterator[tuple[VPlusSimulator, VPlusClient]]:
    async with VPlusSimulator(clock, **sim_args) as sim:
        client = VPlusClient("127.0.0.1", sim.port, clock, timeout=30.0)
        await client.connect()
        try:
            yield sim, client
        finally:
            await client.close()


def close_to(a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float], tol: float = 2e-3) -> bool:
    return bool(np.allclose(a, b, atol=tol))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -------------------------------------------------------------------------- skills
def test_move_joints_then_break_reports_the_reached_pose(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            move, brk = await client.execute(codec.move_joints(READY))
            expected = matrix_to_location(sim.arm.kin.forward(np.radians(READY)))
            assert close_to(brk.pose, expected)
            assert not close_to(move.pose, expected)  # the move is acked when it starts
            assert brk.t_done > move.t_done + 0.1  # break waited for the arm
            assert brk.t_done == pytest.approx(sim.arm.motion_end - sim._t0, abs=2e-3)

    run_sim(main)


def test_move_to_and_both_relative_moves(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            target = (400.0, 100.0, 500.0, 0.0, 180.0, 0.0)
            *_, at = await client.execute(codec.move_to(target))
            assert close_to(at.pose, target)
            *_, world = await client.execute(codec.move_rel_world((10, -20, 30, 0, 0, 0)))
            assert close_to(world.pose, (410, 80, 530, 0, 180, 0))
            # tool z points down (pitch 180): +5 mm along the tool is -5 mm in world z
            *_, tool = await client.execute(codec.move_tool_z(5))
            assert close_to(tool.pose[:3], (410, 80, 525))
            *_, turned = await client.execute(codec.move_rel_tool((0, 0, 0, 0, 0, 30)))
            expected = location_to_matrix(tool.pose) @ location_to_matrix((0, 0, 0, 0, 0, 30))
            assert close_to(turned.pose, matrix_to_location(expected))

    run_sim(main)


def test_move_rel_world_adds_angles_componentwise_like_adeptserver(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (_, client):
            await client.execute(codec.move_to((400, 0, 500, 0, 150, 0)))
            *_, after = await client.execute(codec.move_rel_world((0, 0, 0, 10, 10, 0)))
            assert close_to(after.pose, (400, 0, 500, 10, 160, 0))

    run_sim(main)


def test_relative_joint_move_and_movehome(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            await client.execute(codec.move_joints(READY))
            await client.execute(codec.move_rel_joints((10, 0, 0, 0, 0, -20)))
            assert close_to(np.degrees(sim.arm.joints()), np.add(READY, (10, 0, 0, 0, 0, -20)), 1e-9)
            acks = await client.execute((codec.MOVEHOME, codec.BREAK))
            assert close_to(np.degrees(sim.arm.joints()), HOME_DEG, 1e-9)
            assert close_to(acks[-1].pose, (480, 0, 710, 0, 180, 0))

    run_sim(main)


def test_set_speed_scales_only_the_next_motion(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (_, client):
            def duration(acks: list[codec.Ack]) -> float:
                return acks[-1].t_done - acks[0].t_done

            swing = (120, 0, 0, 0, 0, 0)
            back = (-120, 0, 0, 0, 0, 0)
            slow = duration(await client.execute(codec.set_speed(10), codec.move_rel_joints(swing)))
            fast = duration(await client.execute(codec.move_rel_joints(back)))
            assert slow > 5 * fast > 0
            again = duration(await client.execute(codec.move_rel_joints(swing)))
            assert again == pytest.approx(fast, abs=2e-3)

    run_sim(main)


def test_air_and_gripper_drive_the_controller_outputs(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            sig = sim.arm.signals
            await client.execute(codec.ENABLE_AIR)
            assert sig[AIR_SIGNAL]
            await client.execute(codec.DISABLE_AIR)
            assert not sig[AIR_SIGNAL]
            await client.execute(codec.GRIPPER_CLOSE)
            assert sig == {AIR_SIGNAL: True, GRIPPER_CLOSE_SIGNAL: True, GRIPPER_OPEN_SIGNAL: False}
            await client.execute(codec.GRIPPER_OPEN)
            assert sig == {AIR_SIGNAL: True, GRIPPER_CLOSE_SIGNAL: False, GRIPPER_OPEN_SIGNAL: True}

    run_sim(main)


def test_timestamps_are_controller_seconds_since_the_server_started(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            await clock.sleep(12.3456)
            (ack,) = await client.execute(codec.ENABLE_AIR)
            assert ack.t_recv == pytest.approx(12.346, abs=2e-3)  # millisecond resolution
            assert ack.t_done >= ack.t_recv

    run_sim(main)


# ------------------------------------------------------------------------------ joined
def test_joined_commands_go_out_in_one_write_and_all_acks_come_back(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            acks = await client.execute_joined(codec.set_speed(50), codec.move_tool_z(2.0))
            assert [m.command.skill for m in sim.received] == [Skill.SET_SPEED, Skill.MOVE_REL_TOOL, Skill.BREAK]
            assert [a.id for a in acks] == [m.id for m in sim.received]
            assert len({a.t_recv for a in acks}) == 1  # read by the server as one chunk
            assert acks[-1].pose[2] == pytest.approx(708.0, abs=2e-3)

    run_sim(main)


def test_execute_waits_for_each_commands_acks_before_the_next(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            acks = await client.execute(codec.move_joints(READY), codec.ENABLE_AIR)
            # enable_air was written only after break's ack: the server read it later
            assert acks[2].t_recv >= acks[1].t_done

    run_sim(main)


# ------------------------------------------------------------------------ segmentation
SEED_CHAIN = b"eae86869:move_to:400.000,0.000,500.000,0.000,180.000,0.000\r\nnee861124:break\r\n"


def test_the_server_reassembles_commands_cut_at_every_byte_boundary(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            reader, writer = await asyncio.open_connection("127.0.0.1", sim.port)
            for cut in range(1, len(SEED_CHAIN)):
                writer.write(SEED_CHAIN[:cut])
                await writer.drain()
                await clock.sleep(0.001)  # let the server read the first piece on its own
                writer.write(SEED_CHAIN[cut:])
                await writer.drain()
                first = codec.decode_ack((await reader.readuntil(b"\r\n"))[:-2])
                second = codec.decode_ack((await reader.readuntil(b"\r\n"))[:-2])
                assert (first.id, second.id) == ("eae86869", "nee861124"), cut
            assert sim.errors == []
            writer.close()

    run_sim(main)


@pytest.mark.parametrize("piece", [1, 2, 3, 7, 50])
def test_the_client_reassembles_acks_cut_into_pieces(run_sim: Run, piece: int) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock, faults=Faults(split_acks=piece)) as (sim, client):
            acks = await client.execute_joined(codec.set_speed(20), *codec.move_joints(READY))
            assert [a.id for a in acks] == [m.id for m in sim.received]
            assert close_to(acks[-1].pose, matrix_to_location(sim.arm.kin.forward(np.radians(READY))))

    run_sim(main)


# ---------------------------------------------------------------------------- failures
def test_an_unknown_skill_is_never_acked_so_the_client_times_out_clearly(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        no_gripper = [s for s in Skill if s not in (Skill.GRIPPER_OPEN, Skill.GRIPPER_CLOSE)]
        async with cell(clock, skills=no_gripper) as (sim, client):
            start = clock.now()
            with pytest.raises(CommandTimeout, match=r"no ack within 2 s .*gripper_open") as caught:
                await client.execute(codec.GRIPPER_OPEN, timeout=2.0)
            assert clock.now() - start == pytest.approx(2.0, abs=0.01)
            assert f"127.0.0.1:{sim.port}" in str(caught.value)
            assert [m.command.skill for m in caught.value.exchange.unknown] == [Skill.GRIPPER_OPEN]
            assert "unknown skill 'gripper_open'" in sim.errors[-1]
            (ack,) = await client.execute(codec.ENABLE_AIR)  # the connection carries on
            assert ack.status == "done"

    run_sim(main)


def test_raw_unknown_skills_and_garbage_get_no_ack_and_do_not_stop_the_server(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            reader, writer = await asyncio.open_connection("127.0.0.1", sim.port)
            writer.write(b"c0ffee00:fly_to_moon:1.000\r\n\xff\xfe garbage\r\na1:move_to:1,2\r\nb2:enable_air\r\n")
            ack = codec.decode_ack((await reader.readuntil(b"\r\n"))[:-2])
            assert ack.id == "b2"
            assert len(sim.errors) == 3 and "fly_to_moon" in sim.errors[0]
            writer.close()

    run_sim(main)


@settings(max_examples=40)
@given(st.lists(st.binary(max_size=80).map(lambda b: b.replace(b"\r\n", b"")), max_size=4))
def test_garbage_lines_never_stop_the_server_from_acking_the_next_message(lines: list[bytes]) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            reader, writer = await asyncio.open_connection("127.0.0.1", sim.port)
            writer.write(b"".join(line + b"\r\n" for line in lines) + b"ok1:enable_air\r\n")
            acks = []
            while not acks or acks[-1].id != "ok1":
                acks.append(codec.decode_ack((await reader.readuntil(b"\r\n"))[:-2]))
            assert sim.arm.signals[AIR_SIGNAL]
            writer.close()

    run_with_clock(main, simulated_clock())


def test_an_unreachable_target_is_not_acked_and_the_simulator_says_why(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            with pytest.raises(CommandTimeout):
                await client.execute(codec.move_to((3000, 0, 0, 0, 180, 0)), timeout=1.0)
            assert "location out of range" in sim.errors[-1]

    run_sim(main)


def test_an_ack_with_an_unknown_id_is_a_protocol_error(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            call = asyncio.ensure_future(client.execute(codec.move_joints(READY)))
            await clock.sleep(0.05)  # the move is acked, break waits for the arm
            await sim.send_raw(b"deadbeef:done:0.000,0.000:1.000,2.000,3.000,0.000,0.000,0.000\r\n")
            with pytest.raises(ProtocolError, match="ack for unknown id 'deadbeef'") as caught:
                await call
            exchange = caught.value.exchange
            assert [m.command.skill for m, _ in exchange.acked] == [Skill.MOVE_JOINTS]
            assert [m.command.skill for m in exchange.unknown] == [Skill.BREAK]
            await clock.sleep(5)
            assert [m.command.skill for m, _ in client.late_acks] == [Skill.BREAK]  # tolerated when it comes

    run_sim(main)


def test_a_garbled_ack_is_a_protocol_error_naming_the_bytes(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock, faults=Faults(garble_acks=1)) as (_, client):
            with pytest.raises(ProtocolError, match=r"malformed ack: control characters"):
                await client.execute(codec.ENABLE_AIR)
            (ack,) = await client.execute(codec.DISABLE_AIR)
            assert ack.status == "done"

    run_sim(main)


def test_disconnect_during_break_reports_acked_and_unknown_and_never_resends(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock, faults=Faults(drop_on={"break"})) as (sim, client):
            with pytest.raises(ConnectionLost, match="closed the connection") as caught:
                await client.execute(codec.set_speed(30), codec.move_joints(READY), codec.ENABLE_AIR)
            exchange = caught.value.exchange
            assert [m.command.skill for m, _ in exchange.acked] == [Skill.SET_SPEED, Skill.MOVE_JOINTS]
            assert [m.command.skill for m in exchange.unknown] == [Skill.BREAK]
            assert [m.command.skill for m in exchange.unsent] == [Skill.ENABLE_AIR]
            assert not client.connected
            with pytest.raises(ConnectionLost, match="not connected"):
                await client.execute(codec.ENABLE_AIR)
            # the arm finished its motion on its own; nothing was re-sent
            await client.connect()
            *_, brk = await client.execute(codec.BREAK)
            assert close_to(brk.pose, matrix_to_location(sim.arm.kin.forward(np.radians(READY))))
            assert [m.command.skill for m in sim.received].count(Skill.MOVE_JOINTS) == 1
            # and carries on
            *_, home = await client.execute(codec.move_joints(HOME_DEG))
            assert close_to(home.pose, (480, 0, 710, 0, 180, 0))

    run_sim(main)


def test_injected_faults_drop_after_mute_and_drop_clients(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock, faults=Faults(drop_after=1)) as (sim, client):
            with pytest.raises(ConnectionLost) as caught:
                await client.execute_joined(codec.ENABLE_AIR, codec.DISABLE_AIR)
            assert [m.command for m, _ in caught.value.exchange.acked] == [codec.ENABLE_AIR]
            assert [m.command for m in caught.value.exchange.unknown] == [codec.DISABLE_AIR]
            assert sim.arm.signals[AIR_SIGNAL]  # disable_air was never run
            sim.faults.mute = {"disable_air"}
            await client.connect()
            with pytest.raises(CommandTimeout):
                await client.execute(codec.DISABLE_AIR, timeout=0.5)
            assert not sim.arm.signals[AIR_SIGNAL]  # run, just never acked
            await sim.drop_clients()
            with pytest.raises(ConnectionLost):
                await client.execute(codec.ENABLE_AIR)

    run_sim(main)


def test_a_late_ack_after_a_timeout_is_tolerated_and_the_link_carries_on(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with cell(clock, faults=Faults(ack_delay=3.0)) as (sim, client):
            with pytest.raises(CommandTimeout):
                await client.execute(codec.ENABLE_AIR, timeout=1.0)
            sim.faults.ack_delay = 0.0
            await clock.sleep(3.0)
            assert [m.command.skill for m, _ in client.late_acks] == [Skill.ENABLE_AIR]
            (ack,) = await client.execute(codec.DISABLE_AIR)
            assert ack.status == "done" and client.connected

    run_sim(main)


def test_connect_gives_up_after_bounded_retries_with_backoff(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        port = free_port()
        client = VPlusClient("127.0.0.1", port, clock, retries=3, backoff=0.2)
        start = clock.now()
        with pytest.raises(ConnectError, match=r"after 4 attempt\(s\)") as caught:
            await client.connect()
        assert clock.now() - start == pytest.approx(0.2 + 0.4 + 0.8, abs=0.01)
        assert str(port) in str(caught.value)

    run_sim(main)


def test_connect_retries_until_the_server_comes_up(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        port = free_port()

        async def late_server() -> VPlusSimulator:
            await clock.sleep(0.5)
            return await VPlusSimulator(clock, port=port).start()

        starting = asyncio.ensure_future(late_server())
        client = VPlusClient("127.0.0.1", port, clock, retries=5, backoff=0.2)
        await client.connect()
        sim = await starting
        (ack,) = await client.execute(codec.ENABLE_AIR)
        assert ack.status == "done"
        await client.close()
        await sim.close()

    run_sim(main)


def test_the_server_refuses_clients_beyond_its_limit(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock, max_clients=2) as sim:
            clients = [VPlusClient("127.0.0.1", sim.port, clock, timeout=1.0) for _ in range(3)]
            for c in clients:
                await c.connect()
            await clock.sleep(0.01)
            assert sim.clients == 2
            with pytest.raises(ConnectionLost, match="the server said: refused: 2 clients already connected"):
                await clients[2].execute(codec.ENABLE_AIR)
            assert "refused" in sim.errors[-1]
            for c in clients:
                await c.close()

    run_sim(main)


def test_idle_clients_cannot_lock_others_out(run_sim: Run) -> None:
    """Silent connections are closed after the idle timeout, so the slots free up; a client that
    was closed for idleness reconnects and carries on."""

    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock, max_clients=2, idle_timeout=5.0) as sim:
            squatters = [await asyncio.open_connection("127.0.0.1", sim.port) for _ in range(2)]
            await clock.sleep(0.01)
            assert sim.clients == 2
            for reader, _ in squatters:  # each is told why, then closed
                assert await clock.wait_for(reader.read(), 10.0) == b"closed: idle for 5 s\r\n"
            assert sim.clients == 0
            client = VPlusClient("127.0.0.1", sim.port, clock, timeout=1.0)
            await client.connect()
            assert (await client.execute(codec.ENABLE_AIR))[0].status == "done"
            for _, writer in squatters:
                writer.close()
            await client.close()

    run_sim(main)


def test_an_endless_line_from_a_client_closes_its_connection(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        async with VPlusSimulator(clock) as sim:
            reader, writer = await asyncio.open_connection("127.0.0.1", sim.port)
            writer.write(b"a" * 1000)
            assert await reader.read() == b""  # closed by the server
            assert "no delimiter" in sim.errors[-1]
            writer.close()

    run_sim(main)


def test_the_motion_keeps_its_speed_when_the_clock_is_simulated(run_sim: Run) -> None:
    """A joint move's duration follows the Viper's joint speeds: joint 1 at 328 deg/s."""

    async def main(clock: Clock) -> None:
        async with cell(clock) as (sim, client):
            acks = await client.execute(codec.move_rel_joints((164, 0, 0, 0, 0, 0)))
            ramp = sim.arm.ramp
            assert acks[-1].t_done - acks[0].t_done == pytest.approx(0.5 + ramp, abs=2e-3)
            assert math.isclose(np.degrees(sim.arm.joints())[0], 164.0)

    run_sim(main)
