"""The external-system loop against the simulated controller over loopback UDP, in accelerated time.

The simulator runs in lockstep: it sends the next packet as soon as the reply to the previous one
is in (or known missing), so every outcome below depends on what the loop answered, not on how
fast the machine is.  Waits are for events the loop reports, each with a generous bound.
"""
from __future__ import annotations

import math
import socket
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core_functions.geometry import Pose
from node_transport.clock import Clock
from robot_bridges.kuka_rsi.codec import PacketCodec
from robot_bridges.kuka_rsi.config import RsiConfig, default_config, default_config_path, parse_config
from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink, RsiLoop
from robot_bridges.kuka_rsi.interface import RsiInterface
from robot_bridges.kuka_rsi.kinematics import KukaArm
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.pipe import FramedPipe
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import SimulatorThread
from robot_bridges.kuka_rsi.slots import layout, robot_block_size
from robot_bridges.kuka_rsi.spoofer import Flood
from robot_bridges.kuka_rsi.streaming import ToolPathError

CONFIG = default_config()
DT = 0.004
WAIT = 30.0  # s: the bound on any wait for an event; a healthy run needs a fraction of it
ARM = KukaArm()
# AK travels as degrees with 6 decimals: a set point is exact to 1e-6 deg, a velocity to 2e-6 deg per cycle.
V_EPS = math.radians(2e-6) / DT
READY = (0.0, -80.0, 85.0, 0.0, 30.0, 0.0)  # deg, away from the wrist singularity of the home pose
KUKA_A1_ACCEL = RobotLink("kr", "127.0.0.1").max_joint_accel[0]  # rad/s^2, the link's default
# Wall seconds the lockstep simulator waits for a reply before counting it late.  A healthy loop
# answers within a millisecond, so the wide default only absorbs a loaded machine's stalls (a CI
# run counted one late reply at 0.25 s); tests that withhold replies on purpose use the short one.
GRACE = 2.0
WITHHELD_GRACE = 0.25


class Rig:
    """A loop (thread runner) and one simulated controller per robot, wired over loopback."""

    def __init__(
        self,
        *,
        context: RsiContext = RsiContext(start_deg=READY),
        config: RsiConfig = CONFIG,
        faults: Faults = Faults(),
        cycles: int | None = None,
        hosts: tuple[str, ...] = ("127.0.0.1",),
        now_ns: Callable[[], int] | None = None,
        quirks: Quirks = Quirks(),
        link: dict[str, Any] | None = None,
        settings: LoopSettings = LoopSettings(port=0, silence_timeout=0.3),
        reply_grace: float = GRACE,
        flood: Flood = Flood(),
        clock: Clock | None = None,
    ) -> None:
        """``quirks`` shape how the simulated controller reports, ``link`` overrides RobotLink fields
        (tolerances, limits) of every robot, ``flood`` adds a second sender on each controller's IP,
        ``clock`` runs the simulators in real time on it (default: lockstep)."""
        links = [RobotLink(f"kr{i}", host, config=config, correction_mode=context.correction_mode, **(link or {})) for i, host in enumerate(hosts)]
        kwargs = {} if now_ns is None else {"now_ns": now_ns}
        self.iface = RsiInterface(links, settings, mode="thread", **kwargs)  # type: ignore[arg-type]
        self.iface.start()
        self.address = self.iface.wait_ready(WAIT)
        self.sims = [
            SimulatorThread(
                config, self.address, context=context, faults=faults, cycles=cycles, bind=(host, 0), quirks=quirks, reply_grace=reply_grace,
                flood=flood, clock=clock,
            )
            for host in hosts
        ]
        for sim in self.sims:
            sim.model.trace = []
        self.sim = self.sims[0]

    def start(self) -> Rig:
        for sim in self.sims:
            sim.start()
        return self

    def wait(self, predicate: Callable[[], bool], what: str) -> None:
        assert self.iface.wait_event(predicate, WAIT), f"timed out waiting for {what}"

    def correcting(self, robot: int = 0) -> None:
        """ITRA's allowRobotStart and allowRobMove, with their acknowledgements."""
        for flag, ack in (("B1", "Digout.o1"), ("B2", "Digout.o2")):
            self.iface.set_flag(robot, flag, True)
            self.wait(lambda: self.iface.digout(robot, ack), ack)
            self.iface.set_flag(robot, flag, False)
        self.wait(lambda: self.iface.state(robot).correcting, "RSI_MOVECORR")

    def done(self, cmd: int) -> tuple[bool, str, str]:
        self.wait(lambda: cmd in self.iface.events.done, f"command {cmd}")
        return self.iface.events.done[cmd]

    def close(self) -> None:
        for sim in self.sims:
            sim.stop()
        self.iface.close()


@pytest.fixture
def rig() -> Iterator[Callable[..., Rig]]:
    rigs: list[Rig] = []

    def make(**kwargs: object) -> Rig:
        r = Rig(**kwargs)  # type: ignore[arg-type]
        rigs.append(r)
        return r

    yield make
    for r in rigs:
        r.close()


def _velocities(trace: list[np.ndarray]) -> np.ndarray:
    return np.diff(np.array(trace), axis=0) / DT


# ----------------------------------------------------------------------------------- tests
def test_every_packet_is_answered_with_its_ipoc(rig: Callable[..., Rig]) -> None:
    r = rig(cycles=3000).start()
    assert r.sim.join(WAIT)
    stats = r.sim.model.stats
    # The simulator accepts a reply only with the IPOC of the packet it answers.
    assert stats.packets == 3000 and stats.accepted == 3000 and stats.late == 0 and stats.invalid_replies == 0
    # The loop counts a packet after sending its reply: the last count may follow the simulator's end.
    r.wait(lambda: r.iface.loop is not None and r.iface.loop.stats.packets == 3000, "the loop's count")


def test_packets_from_other_addresses_are_ignored(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.wait(lambda: r.iface.events.connected[0], "the robot")
    rogue = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rogue.bind(("127.0.0.3", 0))
    try:
        packet = PacketCodec.rob(CONFIG).encode(list(PacketCodec.rob(CONFIG).defaults), 77)
        rogue.sendto(packet, r.address)
        r.wait(lambda: any("127.0.0.3" in w for w in r.iface.events.warnings), "the warning about the foreign datagram")
        rogue.setblocking(False)
        with pytest.raises(BlockingIOError):
            rogue.recv(4096)  # no reply: it would have been sent before the warning
    finally:
        rogue.close()
    assert r.iface.loop is not None and r.iface.loop.stats.foreign == 1
    assert r.sim.model.stats.late == 0


def test_malformed_packets_are_rejected_without_disturbing_the_loop(rig: Callable[..., Rig]) -> None:
    r = rig(faults=Faults(garbage=0.3, seed=3), cycles=2000).start()
    assert r.sim.join(WAIT)
    stats = r.sim.model.stats
    assert stats.garbage_sent > 400 and stats.late == 0 and stats.accepted == 2000
    assert r.iface.loop is not None and r.iface.loop.stats.rejected == stats.garbage_sent
    source = f"{r.sim.address[0]}:{r.sim.address[1]}"  # the robot's own port: it sent them
    r.wait(lambda: any(f"rejected a packet from {source} (robot kr0's address)" in w for w in r.iface.events.warnings), "the warning")


def test_oversized_datagrams_from_the_robot_address_are_rejected() -> None:
    """From the robot's address and port (before its port is known, any port of its IP): counted
    per reason and refused, never decoded into what the robot reported."""
    ours, theirs = FramedPipe.pair()
    loop = RsiLoop([RobotLink("kr0", "127.0.0.1")], LoopSettings(port=0), layout(memoryview(bytearray(robot_block_size())), 1), FramedPipe(theirs, blocking_send=False))
    try:
        assert loop._packets([(b"<Rob>" + b" " * 9000 + b"</Rob>", ("127.0.0.1", 5000))]) == []
        assert loop.stats.oversized == 1 and loop.channels[0].refused == {"size": 1}
    finally:
        loop.logger.close()
        ours.close()
        theirs.close()


def test_replies_withheld_below_the_timeout_are_only_counted(rig: Callable[..., Rig]) -> None:
    # Wall-clock margins wide enough that a loaded machine adds no late reply of its own: the
    # simulator waits 0.5 s for each reply, the loop calls 2 s without packets silence.
    settings = LoopSettings(port=0, silence_timeout=2.0)
    r = rig(context=RsiContext(start_deg=READY, timeout=5), settings=settings, reply_grace=0.5).start()
    r.correcting()
    r.iface.withhold_replies(0, 4)
    r.wait(lambda: r.iface.state(0).delay >= 4, "the controller's delay count")
    assert r.iface.state(0).delay == 4  # the four withheld, and no more
    assert r.sim.running and not r.iface.events.faults


def test_replies_withheld_n_times_stop_the_simulator_and_the_bridge_reports_it(rig: Callable[..., Rig]) -> None:
    r = rig(context=RsiContext(start_deg=READY, timeout=5), reply_grace=WITHHELD_GRACE).start()
    r.correcting()
    cmd = r.iface.set_axial_pos(0, np.radians([20, -80, 85, 0, 30, 0]), 1.0, 2.0)
    r.iface.withhold_replies(0, 5)
    assert r.sim.join(WAIT)
    assert r.sim.stop_reason is not None and "RSI timeout: 5 packets late in a row" in r.sim.stop_reason
    r.wait(lambda: bool(r.iface.events.faults), "the bridge's fault")
    robot, kind, message = r.iface.events.faults[0]
    assert (robot, kind) == (0, "timeout") and "no packet from kr0" in message and "delay count 4" in message
    ok, why, fault = r.done(cmd)  # the running move is told too
    assert not ok and fault == "timeout"
    assert not r.iface.state(0).connected


def test_a_joint_retarget_mid_motion_keeps_velocity_continuous_and_within_limits(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.correcting()
    speed, accel = 1.0, 3.0
    first = r.iface.set_axial_pos(0, np.radians([60, -60, 100, 30, 60, 90]), speed, accel)
    start = r.iface.state(0).cycles
    r.iface.wake_at(0, start + 80)
    r.wait(lambda: r.iface.state(0).cycles >= start + 80, "80 cycles of motion")
    assert r.iface.state(0).moving
    final = np.radians([-20, -85, 70, -40, 20, -30])
    second = r.iface.set_axial_pos(0, final, speed, accel)
    assert r.done(second)[0]
    assert r.iface.events.done[first][:2] == (False, f"superseded by command {second}")
    v = _velocities(r.sim.model.trace)  # type: ignore[arg-type]
    assert np.max(np.abs(v)) <= speed + V_EPS
    assert np.max(np.abs(np.diff(v, axis=0))) <= accel * DT + 2 * V_EPS  # no jump, anywhere
    assert np.allclose(r.sim.model.trace[-1], final, atol=1e-7)  # type: ignore[index]
    assert np.allclose(r.iface.state(0).actual_joints, final, atol=1e-4)


def test_a_cartesian_retarget_mid_motion_keeps_velocity_continuous_and_within_limits(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.correcting()
    here = r.iface.state(0).tcp()
    speed, accel = 0.4, 2.0
    r.iface.set_cart_pos(0, here.translated(0.15, 0.1, -0.1), speed, accel)
    start = r.iface.state(0).cycles
    r.iface.wake_at(0, start + 60)
    r.wait(lambda: r.iface.state(0).cycles >= start + 60, "60 cycles of motion")
    final = here.translated(0.05, -0.15, -0.05)
    assert r.done(r.iface.set_cart_pos(0, final, speed, accel))[0]
    positions = np.array([ARM.fk(q)[:3, 3] for q in r.sim.model.trace[-400:]])  # type: ignore[index]
    v = np.diff(positions, axis=0) / DT
    assert np.max(np.linalg.norm(v, axis=1)) <= speed * (1 + 1e-5)
    assert np.max(np.linalg.norm(np.diff(v, axis=0), axis=1)) <= accel * DT * (1 + 1e-4)
    assert r.iface.state(0).tcp().distance_to(final) < 1e-4


def test_changing_space_does_not_move_the_set_point(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.correcting()
    assert r.done(r.iface.set_axial_pos(0, np.radians([10, -70, 80, 10, 40, 10]), 1.0, 3.0))[0]
    here = r.iface.state(0).tcp()
    assert r.done(r.iface.set_cart_pos(0, here.translated(0.0, 0.05, 0.0), 0.3, 2.0))[0]
    assert r.done(r.iface.set_axial_pos(0, np.radians(READY), 1.0, 3.0))[0]
    steps = np.linalg.norm(np.diff(np.array(r.sim.model.trace), axis=0), axis=1)  # type: ignore[arg-type]
    starts = [i for i in range(1, len(steps)) if steps[i - 1] < 1e-12 < steps[i]]
    assert len(starts) == 3  # three moves, each from rest
    # Leaving rest, the set point moves by one generator step (a few 1e-5 rad), not by a fold error.
    assert max(steps[i] for i in starts) < 2e-4
    assert np.allclose(r.sim.model.trace[-1], np.radians(READY), atol=1e-7)  # type: ignore[index]


def test_commands_are_refused_until_the_robot_follows_corrections(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.wait(lambda: r.iface.events.connected[0], "the robot")
    ok, message, kind = r.done(r.iface.set_axial_pos(0, np.radians(READY), 1.0, 1.0))
    assert not ok and "RSI_MOVECORR" in message and kind == "controller"
    r.correcting()
    ok, message, kind = r.done(r.iface.set_axial_pos(0, np.radians([0, -80, 85, 0, 130, 0]), 1.0, 1.0))
    assert not ok and "A5" in message and kind == "joint_limit"


def holdon_config(holdon: str) -> RsiConfig:
    return parse_config(default_config_path().read_text().replace('HOLDON="1"', f'HOLDON="{holdon}"'), f"holdon{holdon}.xml")


@pytest.mark.parametrize("holdon", ["1", "0"])
def test_holdon_behaves_as_configured(rig: Callable[..., Rig], holdon: str) -> None:
    """Relative corrections: a late packet repeats the last increment (HOLDON=1) or adds none
    (HOLDON=0); either way the external system knows what the robot did, goes on from there
    without a jump, and the robot ends on the target."""
    r = rig(context=RsiContext(start_deg=READY, correction_mode="relative"), config=holdon_config(holdon), reply_grace=WITHHELD_GRACE).start()
    r.correcting()
    target = np.radians([90, -80, 85, 0, 30, 0])
    cmd = r.iface.set_axial_pos(0, target, 0.5, 5.0)
    start = r.iface.state(0).cycles
    r.iface.wake_at(0, start + 100)
    r.wait(lambda: r.iface.state(0).cycles >= start + 100, "cruise speed")
    before = len(r.sim.model.trace)  # type: ignore[arg-type]
    r.iface.withhold_replies(0, 3)
    r.wait(lambda: r.iface.state(0).delay == 3, "three late packets")
    r.wait(lambda: len(r.sim.model.trace) > before + 60, "60 more cycles")  # type: ignore[arg-type]
    # Still cruising (the move lasts ~800 cycles); the withholding began within these 60 cycles.
    steps = np.degrees(np.diff(np.array(r.sim.model.trace[before - 2 : before + 60])[:, 0]))  # type: ignore[index]
    cruise = math.degrees(0.5 * DT)
    late = steps[np.abs(steps - cruise) > 1e-6]
    if holdon == "1":
        assert np.allclose(steps, cruise)  # the held increment kept the robot moving at cruise speed
    else:
        held = np.nonzero(np.abs(steps) < 1e-9)[0]
        assert len(held) == 3 and np.all(np.diff(held) == 1)  # three cycles without increment
        after = steps[held[-1] :]  # then from rest back to cruise at the move's acceleration, no jump
        assert np.max(np.abs(np.diff(after))) <= math.degrees(5.0 * DT * DT) + 3e-6  # increments travel with 6 decimals
        assert len(late) > 3 and np.allclose(steps[held[-1] + 40 :], cruise)
    assert r.done(cmd)[0]
    assert np.allclose(r.sim.model.trace[-1], target, atol=1e-7)  # type: ignore[index]  # nothing lost


def test_holdon_keeps_an_absolute_correction_so_the_target_is_still_reached(rig: Callable[..., Rig]) -> None:
    r = rig(reply_grace=WITHHELD_GRACE).start()
    r.correcting()
    target = np.radians([40, -80, 85, 0, 30, 0])
    cmd = r.iface.set_axial_pos(0, target, 0.5, 5.0)
    r.iface.withhold_replies(0, 3)
    assert r.done(cmd)[0]
    assert r.iface.state(0).delay == 3
    assert np.allclose(r.sim.model.trace[-1], target, atol=1e-7)  # type: ignore[index]


def test_the_feedback_file_holds_every_packet(rig: Callable[..., Rig], tmp_path: Path) -> None:
    r = rig(cycles=1500)
    path = tmp_path / "kr0.txt"
    r.iface.set_feedback_output(0, str(path))
    r.wait(lambda: r.iface.events.feedback[0] == str(path), "saving to be on")
    r.start()
    assert r.sim.join(WAIT)
    r.wait(lambda: r.iface.loop is not None and r.iface.loop.stats.packets == 1500, "every packet")
    r.iface.close()  # the saving thread empties its queue before the file is closed
    lines = path.read_text().splitlines()
    assert lines[0].startswith("# t_us ipoc delay x_m")
    rows = np.array([[float(v) for v in line.split()] for line in lines[1:]])
    assert len(rows) == 1500
    ipocs = rows[:, 1].astype(np.int64)
    assert ipocs[0] == RsiContext().ipoc_start and np.all(np.diff(ipocs) == 4)
    assert np.all(np.diff(rows[:, 0]) >= 0)  # timestamps in order
    assert np.allclose(rows[0, 9:15], np.radians(READY))  # actual axes, in rad


def test_several_robots_share_one_socket(rig: Callable[..., Rig]) -> None:
    r = rig(hosts=("127.0.0.1", "127.0.0.2")).start()
    r.correcting(0)
    r.correcting(1)
    target = np.radians([30, -70, 80, 0, 30, 0])
    assert r.done(r.iface.set_axial_pos(1, target, 1.0, 3.0))[0]
    assert np.allclose(r.iface.state(1).actual_joints, target, atol=1e-4)
    assert np.allclose(r.iface.state(0).actual_joints, np.radians(READY), atol=1e-9)
    assert all(sim.model.stats.late == 0 for sim in r.sims)


def test_a_tool_path_streams_one_point_per_cycle(rig: Callable[..., Rig], tmp_path: Path) -> None:
    r = rig().start()
    r.correcting()
    n = 300
    a1 = 10.0 * (1 - np.cos(np.linspace(0, math.pi, n))) / 2  # 0 -> 10 deg, smooth
    points = np.tile(np.array(READY), (n, 1))
    points[:, 0] = a1
    path = tmp_path / "path.txt"
    path.write_text("# A1..A6 deg\n" + "\n".join(" ".join(f"{v:.9f}" for v in p) for p in points) + "\n")
    ok, message, _ = r.done(r.iface.set_tool_path_from_file(0, str(path), "joint"))
    assert ok, message
    trace = r.sim.model.trace
    first = int(np.argmax(np.abs(np.degrees(np.array(trace)[:, 0]) - a1[1]) < 1e-6))  # type: ignore[arg-type]  # the second point
    # Done may come a cycle before the controller applies the last point: it is within tolerance already.
    r.wait(lambda: len(trace) >= first - 1 + n, "the last point")  # type: ignore[arg-type]
    trace = np.degrees(np.array(trace))  # type: ignore[arg-type]
    assert np.allclose(trace[first - 1 : first - 1 + n], points, atol=1e-6)


def test_a_tool_path_that_cannot_be_followed_is_refused_before_anything_moves(rig: Callable[..., Rig], tmp_path: Path) -> None:
    r = rig().start()
    r.correcting()
    jump = tmp_path / "jump.txt"
    jump.write_text("0 -80 85 0 30 0\n0.1 -80 85 0 30 0\n5 -80 85 0 30 0\n")
    with pytest.raises(ToolPathError, match=r"jump.txt:3"):
        r.iface.set_tool_path_from_file(0, str(jump), "joint")
    far = tmp_path / "far.txt"
    far.write_text("20 -80 85 0 30 0\n20 -80 85 0 30 0\n")
    ok, message, kind = r.done(r.iface.set_tool_path_from_file(0, str(far), "joint"))
    assert not ok and "far.txt:1" in message and "first point" in message and kind == "unreachable"
    assert np.allclose(r.sim.model.trace[-1], np.radians(READY))  # type: ignore[index]


def test_getters_use_the_injected_clock(rig: Callable[..., Rig]) -> None:
    ticks = iter(range(10**6, 10**12, 1000))
    r = rig(now_ns=lambda: next(ticks)).start()
    r.correcting()
    position = r.iface.get_curr_pos(0)
    assert position.t_us == r.iface.state(0).t_ns / 1000.0 and position.t_us % 1 == 0
    assert r.iface.get_timestamp() > position.t_us
    assert np.allclose(position.joints, np.radians(READY)) and position.cartesian[:3] == pytest.approx(
        Pose.from_matrix(ARM.fk(np.radians(READY))).position
    )


def test_the_loop_runs_in_its_own_process() -> None:
    iface = RsiInterface([RobotLink("kr", "127.0.0.1")], LoopSettings(port=0, silence_timeout=0.3), mode="process")
    iface.start()
    sim = None
    try:
        address = iface.wait_ready(WAIT)
        assert "gc frozen and disabled" in iface.events.tuning
        sim = SimulatorThread(CONFIG, address, context=RsiContext(start_deg=READY), cycles=600).start()
        for flag, ack in (("B1", "Digout.o1"), ("B2", "Digout.o2")):
            iface.set_flag(0, flag, True)
            assert iface.wait_event(lambda: iface.digout(0, ack), WAIT)
            iface.set_flag(0, flag, False)
        cmd = iface.set_axial_pos(0, np.radians([10, -80, 85, 0, 30, 0]), 1.0, 3.0)
        assert iface.wait_event(lambda: cmd in iface.events.done, WAIT) and iface.events.done[cmd][0]
        assert sim.join(WAIT) and sim.model.stats.late == 0
    finally:
        if sim is not None:
            sim.stop()
        process = iface._process
        iface.close()
    assert process is not None and process.returncode == 0


def test_of_several_waiting_packets_only_the_newest_of_each_robot_is_answered() -> None:
    """After a stall the socket holds several packets; the older ones are late already, and
    answering them would step the generator for cycles the robot held still."""
    links = [RobotLink("a", "127.0.0.1"), RobotLink("b", "127.0.0.2")]
    ours, theirs = FramedPipe.pair()
    loop = RsiLoop(links, LoopSettings(port=0), layout(memoryview(bytearray(2 * robot_block_size())), 2), FramedPipe(theirs, blocking_send=False))
    try:
        rob = PacketCodec.rob(CONFIG)
        packet = lambda ipoc: rob.encode(list(rob.defaults), ipoc)  # noqa: E731
        a, b = ("127.0.0.1", 5000), ("127.0.0.2", 5000)
        batch = [(packet(100), a), (packet(200), b), (b"<Rob garbage", a), (packet(104), a), (packet(7), ("127.0.0.9", 1))]
        kept = loop._packets(batch)
        assert [(channel.link.name, ipoc) for channel, ipoc, _ in kept] == [("b", 200), ("a", 104)]
        assert (loop.stats.stale, loop.stats.rejected, loop.stats.foreign) == (1, 1, 1)
    finally:
        loop.logger.close()
        ours.close()
        theirs.close()


def test_after_late_replies_the_generator_starts_again_where_the_robot_is(rig: Callable[..., Rig]) -> None:
    """Replies the robot never applied must not be made up in one cycle: at 2.5 rad/s, the three
    steps it missed would be a 10 rad/s jump, which the controller refuses (A1 does 2.72)."""
    r = rig(reply_grace=WITHHELD_GRACE).start()
    r.correcting()
    target = np.radians([150, -80, 85, 0, 30, 0])
    cmd = r.iface.set_axial_pos(0, target, 2.5, 20.0)
    start = r.iface.state(0).cycles
    r.iface.wake_at(0, start + 60)
    r.wait(lambda: r.iface.state(0).cycles >= start + 60, "cruise at 2.5 rad/s")
    r.iface.withhold_replies(0, 3)
    ok, message, _ = r.done(cmd)
    assert ok, message
    assert r.iface.state(0).delay == 3 and r.sim.running
    assert r.iface.loop is not None and r.iface.loop.channels[0].catch_ups == 3  # once per packet reporting a new late reply
    steps = np.abs(np.diff(np.array(r.sim.model.trace)[:, 0]))  # type: ignore[arg-type]
    assert np.max(steps) <= 2.5 * DT + math.radians(1e-6)
    assert np.allclose(r.sim.model.trace[-1], target, atol=1e-7)  # type: ignore[index]


def test_a_stream_resumes_from_the_point_the_robot_holds(rig: Callable[..., Rig], tmp_path: Path) -> None:
    """The controller held still for the withheld replies; the stream goes on from the point it
    holds, ramping its speed back up within the acceleration limit instead of jumping to the
    path's speed, and then follows the path to its end."""
    r = rig(reply_grace=WITHHELD_GRACE).start()
    r.correcting()
    n = 400
    s = np.linspace(0.0, 1.0, n)
    a1 = 20.0 * (3 * s**2 - 2 * s**3)  # 0 -> 20 deg from rest to rest, up to 0.075 deg per cycle
    points = np.tile(np.array(READY), (n, 1))
    points[:, 0] = a1
    path = tmp_path / "path.txt"
    path.write_text("\n".join(" ".join(f"{v:.9f}" for v in p) for p in points))
    cmd = r.iface.set_tool_path_from_file(0, str(path), "joint")
    start = r.iface.state(0).cycles
    r.iface.wake_at(0, start + 100)
    r.wait(lambda: r.iface.state(0).cycles >= start + 100, "the stream under way")
    r.iface.withhold_replies(0, 4)
    assert r.done(cmd)[0]
    r.wait(lambda: np.degrees(r.sim.model.trace[-1][0]) > 20.0 - 1e-6, "the last point")  # type: ignore[index]
    taken = np.degrees(np.array(r.sim.model.trace)[:, 0])  # type: ignore[arg-type]
    steps = np.diff(taken)
    assert np.max(steps) <= np.max(np.diff(a1)) + 1e-6  # never faster than the path
    assert np.min(steps) >= -1e-9  # never backwards
    moving = np.nonzero(np.abs(steps[1:]) > 1e-9)[0] + 1
    held = np.nonzero((np.abs(steps) < 1e-9) & (taken[1:] > 1.0) & (taken[1:] < 19.0))[0]
    assert len(held) == 4  # the controller held for the four withheld replies, mid-path
    # Leaving the hold (and everywhere else the robot moves) the step changes within A1's acceleration.
    assert np.max(np.abs(steps[moving] - steps[moving - 1])) <= math.degrees(KUKA_A1_ACCEL * DT * DT) + 1e-6
    assert r.iface.loop is not None and r.iface.loop.channels[0].motion.clamped == 0


def test_a_feedback_file_that_cannot_be_opened_is_reported(rig: Callable[..., Rig], tmp_path: Path) -> None:
    r = rig().start()
    r.iface.set_feedback_output(0, str(tmp_path))  # a directory
    r.wait(lambda: any("cannot open feedback file" in w and str(tmp_path) in w for w in r.iface.events.warnings), "the warning")
    r.wait(lambda: r.iface.state(0).cycles > 50, "the loop to go on")
    assert r.sim.model.stats.late == 0


def test_itras_logical_setters_wait_for_the_krl_programs_acknowledgement(rig: Callable[..., Rig]) -> None:
    r = rig().start()
    r.wait(lambda: r.iface.events.connected[0], "the robot")
    r.iface.allow_robot_start(0, WAIT)
    assert r.iface.digout(0, "Digout.o1") and r.iface.digout(0, "Digout.o3")  # task active, move required
    assert not r.iface.flag(0, "B1")  # lowered after the acknowledgement
    r.iface.allow_robot_move(0, WAIT)
    r.wait(lambda: r.iface.state(0).correcting, "RSI_MOVECORR")
    r.iface.request_realtime_end(0, WAIT)
    assert r.iface.digout(0, "Digout.o4") and not r.iface.digout(0, "Digout.o2")
    r.iface.allow_robot_finish(0)
    assert r.sim.join(WAIT) and r.sim.stop_reason is not None and "finished" in r.sim.stop_reason
    with pytest.raises(TimeoutError, match="did not acknowledge B1"):
        r.iface.allow_robot_start(0, 0.2)  # nobody answers any more
