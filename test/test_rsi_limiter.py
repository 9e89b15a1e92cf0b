"""The last limiter: whatever an upstream component computes, no correction step leaves faster than
the axes (or the TCP) may move, nor changes faster than they may accelerate.

Here the loop's per-robot logic (:class:`Channel`) and the simulated KR C4 (:class:`KrcModel`)
exchange packets directly in one thread, packet for packet: deterministic, no sockets, no clock --
so a test can reach into the generator between two packets and inject the defect it wants.
"""
from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from core_functions.geometry import Pose
from robot_bridges.kuka_rsi.channel import Channel
from robot_bridges.kuka_rsi.config import default_config
from robot_bridges.kuka_rsi.feedback import FeedbackLogger
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.link import RobotLink
from robot_bridges.kuka_rsi.krc_model import KrcModel, RsiContext
from robot_bridges.kuka_rsi.slots import CommandKind, layout, robot_block_size

READY = (0.0, -80.0, 85.0, 0.0, 30.0, 0.0)
LINK = RobotLink("kr", "127.0.0.1")
DT = LINK.cycle_ms / 1000.0
VMAX = np.array(LINK.max_joint_speed)
AMAX = np.array(LINK.max_joint_accel)


class Bench:
    """One robot's channel and a simulated controller, stepped together."""

    def __init__(self) -> None:
        self.model = KrcModel(default_config(), RsiContext(start_deg=READY))
        self.model.trace = []
        self.slots = layout(memoryview(bytearray(robot_block_size())), 1)[0]
        self.events: list[tuple[object, ...]] = []
        self.logger = FeedbackLogger(1)
        self.channel = Channel(0, LINK, self.slots, self.events.append, self.logger)
        self.slots.flags.write(0b11)  # allow start (B1) and allow move (B2): the KRL program enters RSI_MOVECORR
        self._ids = iter(range(1, 10**6))
        self.cycles(5)
        assert self.channel.correcting

    def cycles(self, n: int) -> None:
        for _ in range(n):
            packet = self.model.packet()
            reply = self.channel.on_packet(packet, self.model.ipoc)
            assert reply is not None and self.model.offer(reply)
            self.model.advance()  # raises RsiStopped if the controller refuses a set point
            self.channel.after_reply(self.model.ipoc)

    def command(self, kind: int, *values: float) -> int:
        cmd = next(self._ids)
        self.slots.command.write(kind, cmd, *values)
        return cmd

    def until_done(self, cmd: int, limit: int = 3000) -> tuple[object, ...]:
        for _ in range(limit):
            self.cycles(1)
            for event in self.events:
                if event[0] == "done" and event[2] == cmd:
                    return event
        raise AssertionError(f"command {cmd} not done within {limit} cycles")

    def warnings(self) -> list[str]:
        return [str(e[2]) for e in self.events if e[0] == "warn"]

    def steps(self) -> np.ndarray:
        assert self.model.trace is not None
        return np.diff(np.array(self.model.trace), axis=0)


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench()
    yield b
    b.logger.close()


def test_an_injected_jump_of_the_generator_is_clamped_and_reported(bench: Bench) -> None:
    """A hold-out peer saw A5 step 46.5 deg in one cycle: here a defect puts that jump into the
    generator mid-motion; the limiter sends what the axis can do instead, says so, and the move
    still ends on its target."""
    target = np.radians([40, -80, 85, 0, 30, 0])
    cmd = bench.command(CommandKind.JOINT, *target, 0.0, 1.0, 5.0, 0.0, 0.0)
    bench.cycles(60)
    bench.channel.motion.joint.position[4] += math.radians(46.5)  # the upstream defect
    bench.cycles(1)
    step = bench.steps()[-1]
    assert abs(step[4]) <= AMAX[4] * DT * DT * (1 + 1e-9)  # A5 was still: it may only start to accelerate
    assert bench.channel.motion.clamps.get("A5", 0) >= 1
    warning = next(w for w in bench.warnings() if "A5" in w)
    assert warning.startswith("kr: limiter: A5 asked to step 46.") and "was not sent" in warning
    event = bench.until_done(cmd)
    assert event[3] is True, event
    assert np.all(np.abs(bench.steps()) <= VMAX * DT * (1 + 1e-9))
    assert np.all(np.abs(np.diff(bench.steps(), axis=0)) <= AMAX * DT * DT * (1 + 1e-6) + 1e-12)
    assert np.allclose(bench.model.trace[-1], target, atol=1e-7)  # type: ignore[index]
    assert bench.slots.state.read()[1][10] == bench.channel.motion.clamped  # counted in the shared record


def test_a_step_within_the_speed_but_beyond_the_acceleration_is_clamped(bench: Bench) -> None:
    """At rest, a correction 0.5 deg away on A1 is under A1's 0.62 deg per cycle, but from a
    standstill only 0.025 deg is possible; the robot gets there by accelerating."""
    motion = bench.channel.motion
    motion.ak = motion.ak + np.array([0.5, 0, 0, 0, 0, 0])  # the upstream defect: a correction that jumps
    motion.moved = True
    bench.cycles(1)
    assert abs(bench.steps()[-1][0]) <= AMAX[0] * DT * DT * (1 + 1e-9)
    assert motion.clamps == {"A1": 1}
    bench.cycles(200)
    assert np.all(np.abs(np.diff(bench.steps(), axis=0)) <= AMAX * DT * DT * (1 + 1e-6) + 1e-12)


def test_a_cartesian_jump_is_held_to_the_tcp_limits(bench: Bench) -> None:
    here = Pose.from_matrix(KukaArm().fk(np.radians(READY)))
    goal = here.translated(0.0, 0.1, 0.0)
    cmd = bench.command(CommandKind.CART, goal.x, goal.y, goal.z, goal.qx, goal.qy, goal.qz, goal.qw, 0.3, 2.0, 1.0, 2.0)
    bench.cycles(40)
    motion = bench.channel.motion
    assert motion.mode == "cart"
    motion.cart.position = motion.cart.position + np.array([0.0, 0.0, 0.05])  # 50 mm in one cycle
    bench.cycles(1)
    tcp = np.array([KukaArm().fk(q)[:3, 3] for q in bench.model.trace[-3:]])  # type: ignore[index]
    shifts = np.diff(tcp, axis=0)
    assert np.linalg.norm(shifts[-1] - shifts[-2]) <= LINK.max_linear_accel * DT * DT * (1 + 1e-6)
    assert motion.clamps.get("TCP translation", 0) == 1
    assert bench.until_done(cmd)[3] is True
