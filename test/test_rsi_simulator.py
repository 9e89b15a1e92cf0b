"""The KR C4 RSI simulator, cycle by cycle without sockets: what a real controller would do with our replies."""
from __future__ import annotations

import math
import socket

import numpy as np
import pytest

from robot_bridges.kuka_rsi.codec import PacketCodec
from robot_bridges.kuka_rsi.config import default_config, default_config_path, parse_config
from robot_bridges.kuka_rsi.kinematics import abc_to_matrix
from robot_bridges.kuka_rsi.krc_model import KrcModel, Program, RsiContext, RsiStopped
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import SimulatorThread, run_lockstep
from robot_bridges.kuka_rsi.simulator import main

CONFIG = default_config()
SEN = PacketCodec.sen(CONFIG)
ROB = PacketCodec.rob(CONFIG)


def _config(holdon: str) -> object:
    text = default_config_path().read_text().replace('HOLDON="1"', f'HOLDON="{holdon}"')
    return parse_config(text)


class Robot:
    """A model and the replies an external system would send it."""

    def __init__(self, context: RsiContext = RsiContext(), config: object = CONFIG, quirks: Quirks = Quirks()) -> None:
        self.model = KrcModel(config, context, quirks=quirks)  # type: ignore[arg-type]
        self.sen = PacketCodec.sen(config)  # type: ignore[arg-type]
        self.model.trace = []

    def cycle(self, reply: dict[str, object] | None = None, *, ipoc_offset: int = 0) -> dict[str, object]:
        """One cycle: read the packet, answer it (None: no answer), close the cycle."""
        ipoc, packet = ROB.decode(self.model.packet())
        if reply is not None:
            self.model.offer(self.sen.encode_map(reply, ipoc + ipoc_offset))  # type: ignore[arg-type]
        self.model.advance()
        return packet | {"IPOC": ipoc}

    def start_correcting(self) -> None:
        self.cycle({"B1": True})
        self.cycle({"B2": True})
        assert self.model.program is Program.MOVECORR


def test_ipoc_steps_by_the_cycle_in_ms() -> None:
    for cycle in (4, 12):
        robot = Robot(RsiContext(cycle_ms=cycle))
        ipocs = [robot.cycle({})["IPOC"] for _ in range(5)]
        assert np.all(np.diff(ipocs) == cycle)


def test_rob_packets_report_the_pose_axes_and_delay() -> None:
    packet = Robot().cycle({})
    assert (packet["RIst.X"], packet["RIst.Z"], packet["RIst.B"]) == pytest.approx((525.0, 890.0, 90.0))
    assert [packet[f"AIPos.A{i}"] for i in range(1, 7)] == pytest.approx([0, -90, 90, 0, 0, 0])
    assert packet["Delay.D"] == 0


def test_late_wrong_ipoc_and_wrong_sentype_replies_count_in_delay() -> None:
    robot = Robot()
    robot.cycle({})
    robot.cycle(None)  # no reply
    robot.cycle({}, ipoc_offset=4)  # the IPOC of another cycle
    ipoc, _ = ROB.decode(robot.model.packet())
    robot.model.offer(SEN.encode_map({}, ipoc).replace(b"DualArmExecutive", b"Server"))  # wrong SENTYPE
    robot.model.offer(b"<Sen garbage")
    robot.model.advance()
    assert robot.cycle({})["Delay.D"] == 3
    assert robot.model.stats.invalid_replies == 3 and robot.model.late_in_row == 0


def test_timeout_stops_rsi_after_that_many_late_packets_in_a_row() -> None:
    robot = Robot(RsiContext(timeout=5))
    for _ in range(4):
        robot.cycle(None)
    robot.cycle({})  # an answer in time resets the count
    for _ in range(4):
        robot.cycle(None)
    with pytest.raises(RsiStopped) as stopped:
        robot.cycle(None)
    assert stopped.value.error and "RSI timeout: 5 packets late in a row" in stopped.value.reason
    with pytest.raises(RsiStopped):
        robot.model.advance()  # it stays stopped


def test_the_krl_program_acknowledges_each_handshake() -> None:
    robot = Robot()
    assert robot.cycle({})["Digout.o1"] is False
    robot.cycle({"B1": True})
    packet = robot.cycle({})
    assert (packet["Digout.o1"], packet["Digout.o2"], packet["Digout.o3"]) == (True, False, True)
    robot.cycle({"B2": True})
    packet = robot.cycle({})
    assert (packet["Digout.o2"], packet["Digout.o3"]) == (True, False)
    robot.cycle({"B4": True})
    packet = robot.cycle({})
    assert (packet["Digout.o2"], packet["Digout.o4"]) == (False, True)
    with pytest.raises(RsiStopped) as stopped:
        robot.cycle({"B3": True})
    assert not stopped.value.error and "finished" in stopped.value.reason


def test_corrections_are_ignored_until_rsi_movecorr() -> None:
    robot = Robot()
    robot.cycle({"AK.A1": 5.0})
    assert robot.model.q_cmd[0] == 0.0


def test_absolute_axis_corrections_move_the_set_point_and_the_servo_follows() -> None:
    robot = Robot()
    robot.start_correcting()
    for k in range(1, 11):
        robot.cycle({"AK.A1": 0.1 * k})
    assert math.degrees(robot.model.q_cmd[0]) == pytest.approx(1.0)
    packet = robot.cycle({"AK.A1": 1.0})
    assert packet["ASPos.A1"] == pytest.approx(1.0)
    assert 0.5 < packet["AIPos.A1"] < 1.0  # the servo lags behind the set point
    for _ in range(30):
        packet = robot.cycle({"AK.A1": 1.0})
    assert packet["AIPos.A1"] == pytest.approx(1.0, abs=1e-6)


def test_cartesian_corrections_move_the_tcp_in_the_base_frame() -> None:
    robot = Robot(RsiContext(start_deg=(0, -90, 90, 0, 30, 0)))  # A5 = 0 would be a wrist singularity
    start = robot.cycle({})
    robot.start_correcting()
    for k in range(1, 21):
        robot.cycle({"RKorr.Y": 0.5 * k, "RKorr.Z": -0.25 * k, "RKorr.A": 0.1 * k})
    packet = robot.cycle({"RKorr.Y": 10.0, "RKorr.Z": -5.0, "RKorr.A": 2.0})
    expected = (start["RSol.X"], start["RSol.Y"] + 10.0, start["RSol.Z"] - 5.0)
    assert [packet[f"RSol.{a}"] for a in "XYZ"] == pytest.approx(expected, abs=1e-4)
    before, after = (abc_to_matrix(*np.radians([p[f"RSol.{a}"] for a in "ABC"])) for p in (start, packet))
    assert np.allclose(after, abc_to_matrix(math.radians(2.0), 0, 0) @ before, atol=1e-6)  # turned about the base Z


def test_axiscorr_clamps_each_correction() -> None:
    robot = Robot(RsiContext(axis_limit_deg=(0.5,) * 6))
    robot.start_correcting()
    for k in range(1, 20):
        robot.cycle({"AK.A2": 0.1 * k})
    assert math.degrees(robot.model.q_cmd[1]) == pytest.approx(-89.5)


def test_axiscorrmon_stops_the_robot_when_the_total_exceeds_its_limit() -> None:
    robot = Robot(RsiContext(axis_monitor_deg=(360.0, 2.0, 360.0, 360.0, 360.0, 360.0)))
    robot.start_correcting()
    with pytest.raises(RsiStopped) as stopped:
        for k in range(1, 100):
            robot.cycle({"AK.A2": 0.1 * k})
    assert stopped.value.error and "AXISCORRMON" in stopped.value.reason and "A2" in stopped.value.reason
    assert math.degrees(robot.model.q_cmd[1]) <= -88.0 + 1e-9  # the offending set point was not applied


def test_relative_corrections_accumulate_and_their_total_is_monitored() -> None:
    robot = Robot(RsiContext(correction_mode="relative", axis_monitor_deg=(1.0,) * 6))
    robot.start_correcting()
    for _ in range(10):
        robot.cycle({"AK.A3": 0.1})
    assert math.degrees(robot.model.q_cmd[2]) == pytest.approx(91.0)
    with pytest.raises(RsiStopped, match="AXISCORRMON"):
        robot.cycle({"AK.A3": 0.1})


def test_holdon_1_repeats_the_last_value_on_a_late_packet() -> None:
    robot = Robot(RsiContext(correction_mode="relative"), _config("1"))
    robot.start_correcting()
    robot.cycle({"AK.A1": 0.2})
    robot.cycle(None)  # late: the increment is applied again
    assert math.degrees(robot.model.q_cmd[0]) == pytest.approx(0.4)


def test_holdon_0_drops_the_value_to_zero_on_a_late_packet() -> None:
    relative = Robot(RsiContext(correction_mode="relative"), _config("0"))
    relative.start_correcting()
    relative.cycle({"AK.A1": 0.2})
    relative.cycle(None)  # late: no increment
    assert math.degrees(relative.model.q_cmd[0]) == pytest.approx(0.2)
    absolute = Robot(RsiContext(), _config("0"))
    absolute.cycle({"B1": True})
    absolute.cycle({"B1": True, "B2": True})
    absolute.cycle({"B1": True, "B2": True, "AK.A1": 0.1})
    absolute.cycle(None)  # late: the absolute correction falls to 0, and the flags with it
    assert math.degrees(absolute.model.q_cmd[0]) == pytest.approx(0.0)


def test_software_limit_switches_and_axis_speeds_stop_rsi() -> None:
    robot = Robot()
    robot.start_correcting()
    with pytest.raises(RsiStopped, match="commanded speed of A1"):
        robot.cycle({"AK.A1": 5.0})  # 5 deg in 4 ms = 1250 deg/s
    robot = Robot(RsiContext(start_deg=(0, -90, 90, 0, 119.9, 0)))
    robot.start_correcting()
    with pytest.raises(RsiStopped, match="software limit switch A5"):
        for k in range(1, 10):
            robot.cycle({"AK.A5": 0.1 * k})


def test_stop_ends_rsi_without_an_error() -> None:
    robot = Robot()
    with pytest.raises(RsiStopped) as stopped:
        robot.cycle({"Stop": True})
    assert not stopped.value.error and "Stop" in stopped.value.reason


def test_tool_outputs_follow_the_reply_and_are_echoed() -> None:
    robot = Robot()
    robot.cycle({"Tool.o2": True})
    assert robot.cycle({"Tool.o2": True})["Tool.o2"] is True


def test_onlysend_configurations_are_refused() -> None:
    text = default_config_path().read_text().replace("<ONLYSEND>FALSE", "<ONLYSEND>TRUE")
    with pytest.raises(ValueError, match="ONLYSEND"):
        KrcModel(parse_config(text, "only.xml"))


def test_injected_loss_and_garbage_are_reproducible_from_the_seed() -> None:
    """Lockstep against nobody: every packet is late; loss and garbage follow the seed exactly."""
    counts = []
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        for _ in range(2):
            faults = Faults(loss=0.3, garbage=0.2, seed=7)
            sim = SimulatorThread(CONFIG, silent.getsockname(), context=RsiContext(timeout=40), faults=faults)
            result = run_lockstep(sim.sock, sim.peer, sim.model, cycles=200, faults=faults, reply_grace=0.0)
            sim.sock.close()
            assert result is not None and "RSI timeout" in result.reason
            counts.append((sim.model.stats.lost, sim.model.stats.garbage_sent, sim.model.stats.packets))
    finally:
        silent.close()
    assert counts[0] == counts[1] and counts[0][0] > 0 and counts[0][1] > 0


# ------------------------------------------------------------ peers that report what they like
def test_a_frozen_set_point_reports_the_start_pose_while_the_robot_moves() -> None:
    robot = Robot(quirks=Quirks(frozen_setpoint=True))
    robot.start_correcting()
    robot.cycle({"AK.A1": 0.5, "B2": True})
    packet = robot.cycle({"AK.A1": 1.0, "B2": True})
    assert packet["ASPos.A1"] == 0.0 and packet["RSol.Y"] == pytest.approx(0.0, abs=1e-6)
    assert packet["AIPos.A1"] > 0.2  # the robot did move: only its report stands still


def test_a_drifting_report_moves_away_from_the_real_set_point_during_rsi_movecorr() -> None:
    robot = Robot(quirks=Quirks(drift_axis=3, drift_deg=0.01))
    assert robot.cycle({})["ASPos.A3"] == pytest.approx(90.0)  # not yet: RSI_MOVECORR has not begun
    robot.start_correcting()
    for _ in range(10):
        packet = robot.cycle({"B2": True})
    assert packet["ASPos.A3"] == pytest.approx(90.0 + 0.1) and math.degrees(robot.model.q_cmd[2]) == pytest.approx(90.0)


def test_root_attribute_spelling_ipoc_step_and_dropped_replies_as_configured() -> None:
    model = KrcModel(CONFIG, quirks=Quirks(root_attribute="TYPE", ipoc_step=1))
    first = model.packet()
    assert first.startswith(b'<Rob TYPE="KUKA">')
    model.advance()
    assert model.ipoc == RsiContext().ipoc_start + 1
    reply = SEN.encode_map({}, model.ipoc)
    model.packet()
    assert model.offer(reply, drop=True) and model.stats.dropped == 1
    model.advance()
    assert model.delay == 2  # the dropped reply counts late like a missing one


def test_the_command_line_takes_the_quirks(capsys: pytest.CaptureFixture[str]) -> None:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        port = silent.getsockname()[1]
        args = ["--to", f"127.0.0.1:{port}", "--accelerated", "--cycles", "3", "--reply-grace", "0", "--root-attribute", "TYPE",
                "--frozen-setpoint", "--drift", "A2:0.5", "--ipoc-step", "1", "--drop", "0.5"]
        assert main(args) == 0
        packets = [silent.recv(4096) for _ in range(3)]
    finally:
        silent.close()
    assert all(p.startswith(b'<Rob TYPE="KUKA">') for p in packets) and b"<IPOC>3741924002</IPOC>" in packets[2]
    assert '"dropped": 0' in capsys.readouterr().out.splitlines()[-1]
    assert main(["--drift", "A9:1"]) == 1
