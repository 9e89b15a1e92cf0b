"""What a real ROS 2 Jazzy does and the fake rclpy now models, each once found on a real Jazzy.

One test (or a few) per defect found there: the start-up race of DDS discovery, stamps that were
not ROS time, rcl's YAML typing of parameter values, malformed ``--ros-args``, an executor
shutdown that does not wait, parameter descriptors lost to automatic declaration, services of a
destroyed node that stayed advertised, and logs that never reached ``/rosout``.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import time
from functools import partial
from pathlib import Path
from typing import Any

import pytest
import ros_fake_context
import ros_fake_graph
import ros_fake_logging
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from scripted_backend import ScriptedBackend
from test_ros_nodes import SMOKE_APP
from test_ros_transport import BOUND, Inbox, matched, run_real, with_transport

from app_functions.registry import full_catalog
from cell_runner import nodes
from cell_runner.bridge_nodes.common import run_bridge
from cell_runner.bridge_nodes.nextage_sim import BACKEND, declare_nextage_parameters
from cell_runner.bridge_nodes.nextage_sim import main as nextage_main
from cell_runner.libraries import APPLICATION_FUNCTIONS
from cell_runner.ros_main import ExitCode, Outcome, run_node
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import load_application
from execution_engine.engine.engine import ExecutionEngine
from node_transport import codec, typed
from node_transport.clock import Clock, FollowingClock
from node_transport.local import LocalTransport
from node_transport.msgs import ClockMessage, JointState, String, Time, Trigger, TriggerRequest, TriggerResponse
from node_transport.port import Node, wait_until_matched
from node_transport.qos import CLOCK, COMMANDS, EVENTS, SENSOR
from node_transport.ros import RosTransport
from node_transport.wire import machine_node_name
from node_transport.wire import SmStatus, bridge_topic, sm_topic
from robot_bridges.bridge_node import BridgeNode


# ============================================================================ 1. discovery
def test_nothing_is_delivered_before_discovery_has_matched_the_endpoints(fake_rclpy: Any) -> None:
    """What a real DDS does: a volatile message published before the match is lost."""

    async def body(transport: RosTransport) -> None:
        ros_fake_graph.GRAPH.match_delay = 0.1
        talker, listener = transport.create_node("talker"), transport.create_node("listener")
        inbox = Inbox()
        sub = listener.create_subscription(String, "/x", inbox, COMMANDS)
        pub = talker.create_publisher(String, "/x", COMMANDS)
        assert pub.get_subscription_count() == 0 and sub.get_publisher_count() == 0
        pub.publish(String("too early"))
        await matched(transport, pub, sub)
        pub.publish(String("after the match"))
        assert await inbox.wait(transport.clock) == [String("after the match")]
        assert ros_fake_graph.GRAPH.lost[0][0] == "/x"

    run_real(lambda clock: with_transport(clock, body))


def test_a_cell_started_all_at_once_runs_without_a_single_retry_despite_slow_discovery(
    fake_rclpy: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    ros_fake_graph.GRAPH.match_delay = 0.3  # every pair of endpoints matches 0.3 s after both exist
    app = tmp_path / "app.xml"
    app.write_text(SMOKE_APP)
    report, statuses = run_real(lambda clock: run_cell(clock, app))
    assert report.ok and report.retries == 0 and not report.errors
    assert [s for s in statuses if s.get("event") == "error"] == []
    assert {s["group"] for s in statuses if s.get("event") == "function_end"} == {"left_arm", "right_arm"}


async def run_cell(clock: Clock, app: Path) -> tuple[Any, list[dict[str, Any]]]:
    """The simulator, one machine per group and the engine, every node created at once (as a
    launch file starts them), the engine running ``app``; (its report, every machine status)."""
    transport = RosTransport(clock, ["cell"])
    tasks: list[asyncio.Task[None]] = []
    statuses: list[dict[str, Any]] = []
    try:
        bridge = transport.create_node("nextage_sim_bridge", parameters={"speed": 20.0})
        tasks.append(asyncio.ensure_future(run_bridge("nextage-sim", declare_nextage_parameters, bridge, Outcome())))
        viewer = transport.create_node("viewer")
        for group in NEXTAGE_OPEN.group_names:
            machine = transport.create_node(machine_node_name(group), parameters={"group": group})
            tasks.append(asyncio.ensure_future(nodes.run_group_machine(machine, Outcome())))
            viewer.create_subscription(
                typed.MachineStatusMsg, sm_topic(group, "status"), lambda m: statuses.append(codec.to_primitive(typed.from_msg(SmStatus, m, clock))), EVENTS
            )
        engine = ExecutionEngine(transport.create_node("execution_engine"), APPLICATION_FUNCTIONS.catalog(None))
        report = await clock.wait_for(engine.run(load_application(app, full_catalog())), BOUND)
        return report, statuses
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await transport.shutdown()


class _SlowStart(ScriptedBackend):
    """A robot whose start-up takes 2 s, as the KUKA RSI handshake takes its time."""

    started_at: float | None = None

    async def start(self) -> None:
        await self.clock.sleep(2.0)
        self.started_at = self.clock.now()


def test_a_bridge_is_matched_for_commands_only_once_its_robot_has_started(run_sim: Any) -> None:
    """On Jazzy the KUKA launch hung: the machine's first move reached the bridge during the RSI
    handshake and was accepted, never carried out.  A machine sends only after the match, so the
    bridge subscribes to commands only once its back end has started."""

    async def main(clock: Clock) -> tuple[bool, float, float | None]:
        transport = LocalTransport(clock)
        backend = _SlowStart(clock, NEXTAGE_OPEN)
        bridge = BridgeNode(transport.create_node("bridge"), backend)
        command = transport.create_node("left_arm_machine").create_publisher(typed.BridgeCommandMsg, bridge_topic("left_arm", "command"), COMMANDS)
        starting = asyncio.ensure_future(bridge.start())
        matched = await wait_until_matched(clock, [command], 5.0)
        matched_at = clock.now()
        await starting
        await bridge.close()
        return matched, matched_at, backend.started_at

    matched, matched_at, started_at = run_sim(main)
    assert matched and started_at is not None and matched_at >= started_at


# ============================================================================== 2. ROS time
def test_stamps_are_ros_time_and_follow_clock_with_use_sim_time(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        wall = transport.create_node("wall")
        stamp = wall.now_stamp().to_seconds()
        assert abs(stamp - time.time()) < 1.0  # seconds since 1970, not since the process started
        sim = transport.create_node("sim", parameters={"use_sim_time": True})
        assert isinstance(sim.clock, FollowingClock)
        source = transport.create_node("simulator").create_publisher(ClockMessage, "/clock", CLOCK)
        await matched(transport, source)
        # published again until seen, as a simulator publishes /clock all along (a loaded machine may deliver late)
        await _until(transport.clock, lambda: sim.clock.ticking, lambda: source.publish(ClockMessage(Time(1_000, 0))))
        await _until(transport.clock, lambda: sim.clock.now() == pytest.approx(2.5), lambda: source.publish(ClockMessage(Time(1_002, 500_000_000))))
        assert sim.now_stamp() == Time(1_002, 500_000_000)
        waited = asyncio.ensure_future(sim.clock.sleep(1.0))  # one second of the simulator's time
        source.publish(ClockMessage(Time(1_003, 0)))
        await asyncio.sleep(0.05)
        assert not waited.done()
        source.publish(ClockMessage(Time(1_003, 600_000_000)))
        await transport.clock.wait_for(waited, BOUND)

    run_real(lambda clock: with_transport(clock, body))


def test_a_simulator_faster_than_real_time_publishes_clock(fake_rclpy: Any) -> None:
    ticks: list[float] = []

    async def listen(node: Node, outcome: Outcome) -> None:
        node.create_subscription(ClockMessage, "/clock", lambda m: ticks.append(m.clock.to_seconds()), CLOCK)

    async def main(clock: Clock) -> None:
        # The simulator node and a listener in one process, through the real bridge entry point's body.
        transport = RosTransport(clock, ["sim", "--ros-args", "-p", "speed:=10.0"])
        try:
            node = transport.create_node("nextage_sim_bridge")
            await listen(transport.create_node("listener"), Outcome())
            serving = asyncio.ensure_future(partial(run_bridge, BACKEND, declare_nextage_parameters)(node, Outcome()))
            await _until(clock, lambda: len(ticks) >= 20)
            serving.cancel()
            await asyncio.gather(serving, return_exceptions=True)
        finally:
            await transport.shutdown()

    run_real(main)
    assert abs(ticks[0] - time.time()) < BOUND  # ROS time: it starts at the wall time of the start
    steps = [b - a for a, b in zip(ticks, ticks[1:])]
    # every 10 ms of wall time, i.e. every 0.1 s of a robot running ten times faster (never less)
    assert min(steps) >= 0.1 - 1e-6


def test_joint_states_of_the_simulator_carry_ros_time(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> JointState:
        transport = RosTransport(clock, ["sim"])
        try:
            inbox = Inbox()
            sub = transport.create_node("viewer").create_subscription(JointState, "/joint_states", inbox, SENSOR)
            serving = asyncio.ensure_future(partial(run_bridge, BACKEND, declare_nextage_parameters)(transport.create_node("nextage_sim_bridge"), Outcome()))
            await matched(transport, sub)
            message: JointState = (await inbox.wait(clock))[0]
            serving.cancel()
            await asyncio.gather(serving, return_exceptions=True)
            return message
        finally:
            await transport.shutdown()

    message = run_real(main)
    assert abs(message.header.stamp.to_seconds() - time.time()) < 1.0 and len(message.name) == 15


def test_a_silent_clock_source_ends_waits_with_a_fault_instead_of_hanging(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], float]:
        stalls: list[str] = []
        following = FollowingClock(stall_timeout=3.0, on_stall=stalls.append)
        following.bind(clock.loop)
        following.advance_to(50.0)
        started = clock.now()
        with pytest.raises(asyncio.TimeoutError):
            await following.wait_for(asyncio.Event().wait(), 100.0)  # 100 s of a clock that stopped
        return stalls, clock.now() - started

    stalls, waited = run_sim(main)
    assert waited == pytest.approx(3.0, abs=1.6) and "no time from the clock source for 3 s" in stalls[0]


async def _until(clock: Clock, condition: Any, again: Any = None) -> None:
    """Wait (bounded) until ``condition()``; ``again()`` first and then every 0.1 s while waiting."""
    deadline, due = clock.now() + 6 * BOUND, clock.now()  # 30 s: only ever reached when something hangs
    while not condition():
        assert clock.now() < deadline, "condition never came true"
        if again is not None and clock.now() >= due:
            again()
            due = clock.now() + 0.1
        await clock.sleep(0.005)


# ======================================================================= 3. rcl's YAML typing
def test_values_a_user_naturally_writes_reach_string_parameters(fake_rclpy: Any, tmp_path: Path) -> None:
    params = tmp_path / "sim.yaml"
    params.write_text("/**/nextage_sim_bridge:\n  ros__parameters:\n    faults: 010\n")
    argv = ["sim", "--ros-args", "-p", "initial_pose:=off", "--params-file", str(params), "-p", "seed:=0x10"]

    async def main(clock: Clock) -> dict[str, Any]:
        transport = RosTransport(clock, argv)
        try:
            node = transport.create_node("nextage_sim_bridge")
            assert node.ros_node.get_parameter("initial_pose").value is False  # what rcl made of it
            return {
                "initial_pose": node.declare_parameter("initial_pose", "initial"),
                "faults": node.declare_parameter("faults", ""),
                "seed": node.declare_parameter("seed", 0),
            }
        finally:
            await transport.shutdown()

    assert run_real(main) == {"initial_pose": "off", "faults": "010", "seed": 16}


def test_a_type_mismatch_says_how_to_quote(fake_rclpy: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert nextage_main(["nextage_sim_bridge", "--ros-args", "-p", "speed:=fast"]) == ExitCode.USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "parameter 'speed' must be a number (double), got string 'fast'" in err

    async def main(clock: Clock) -> None:
        node = (transport := RosTransport(clock, ["x"])).create_node("x", parameters={"label": True})
        try:
            with pytest.raises(Exception, match=r"""quote it: -p label:="'true'" on the command line, label: 'true' in a YAML file"""):
                node.declare_parameter("label", "")
        finally:
            await transport.shutdown()

    run_real(main)


def test_the_simulator_starts_with_initial_pose_off_from_the_command_line(fake_rclpy: Any) -> None:
    async def body(node: Node, outcome: Outcome) -> None:
        setup = declare_nextage_parameters(node)
        outcome.code = ExitCode.OK if setup.options.extra["initial_pose"] == "off" else ExitCode.FAILED

    assert run_node("nextage_sim_bridge", body, ["sim", "--ros-args", "-p", "initial_pose:=off"]) == ExitCode.OK


# ===================================================================== 4. malformed --ros-args
@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["-p", "speed"], "Couldn't parse parameter override rule: '-p speed'. Error: Expected lexeme type (22) not found"),
        (["--speed", "2"], "unknown ROS argument(s) ['--speed', '2']"),
        (["-p"], "Couldn't parse trailing -p flag"),
        (["--params-file", "/nonexistent/params.yaml"], "Couldn't parse params file: '--params-file /nonexistent/params.yaml'"),
    ],
)
def test_malformed_ros_arguments_exit_2_with_one_line(fake_rclpy: Any, capsys: pytest.CaptureFixture[str], args: list[str], says: str) -> None:
    assert nextage_main(["nextage_sim_bridge", "--ros-args", *args]) == ExitCode.USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("nextage_sim_bridge: bad ROS arguments: ") and says in err
    assert "Traceback" not in err and ", at ./src" not in err


def test_a_broken_params_file_is_a_usage_error(fake_rclpy: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("nextage_sim_bridge:\n  ros__parameters: [speed: 2\n")
    assert nextage_main(["nextage_sim_bridge", "--ros-args", "--params-file", str(broken)]) == ExitCode.USAGE
    assert f"Couldn't parse params file: '--params-file {broken}'" in capsys.readouterr().err


# ========================================================================= 5. bounded shutdown
def test_shutdown_waits_for_callbacks_in_flight_although_the_executor_does_not(fake_rclpy: Any) -> None:
    finished: list[str] = []

    async def main(clock: Clock) -> float:
        transport = RosTransport(clock, ["test"], shutdown_timeout=5.0)
        listener = transport.create_node("listener")
        talker = transport.create_node("talker")
        started = asyncio.Event()

        def slow_conversion(mirror: type, ros_msg: Any) -> Any:  # a callback busy on an executor thread
            clock.loop.call_soon_threadsafe(started.set)
            time.sleep(0.5)
            finished.append("converted")
            return String(ros_msg.data)

        sub = listener.create_subscription(String, "/slow", lambda m: None, COMMANDS)
        listener.converter.from_ros = slow_conversion  # type: ignore[method-assign]
        pub = talker.create_publisher(String, "/slow", COMMANDS)
        await matched(transport, pub, sub)
        pub.publish(String("x"))
        await clock.wait_for(started.wait(), BOUND)
        begun = clock.now()
        await transport.shutdown()
        return clock.now() - begun

    took = run_real(main)
    assert finished == ["converted"]  # shutdown returned only after the callback had finished
    assert 0.3 < took < 5.0


def test_a_signal_during_shutdown_is_still_handled(fake_rclpy: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    original = RosTransport.shutdown

    async def shutdown_with_a_signal(self: RosTransport) -> None:
        os.kill(os.getpid(), signal.SIGTERM)  # the launch system's second signal, mid-shutdown
        await asyncio.sleep(0.05)
        await original(self)

    monkeypatch.setattr(RosTransport, "shutdown", shutdown_with_a_signal)

    async def body(node: Node, outcome: Outcome) -> None:
        os.kill(os.getpid(), signal.SIGINT)
        await node.clock.sleep(BOUND)

    assert run_node("engine", body, ["engine"]) == ExitCode.OK  # not killed by SIGTERM's default action
    assert not ros_fake_context.CONTEXT.ok()


# ====================================================================== 6. parameter descriptors
def test_overrides_get_the_declared_type_and_description(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any, Any]:
        transport = RosTransport(clock, ["sim", "--ros-args", "-p", "speed:=2", "-p", "initial_pose:=off"])
        try:
            node = transport.create_node("nextage_sim_bridge")
            declare_nextage_parameters(node)
            ros_node = node.ros_node
            return ros_node.get_parameter("speed").value, ros_node.describe_parameter("speed"), ros_node.describe_parameter("initial_pose")
        finally:
            await transport.shutdown()

    speed, described, pose = run_real(main)
    assert speed == 2.0 and isinstance(speed, float)  # `ros2 param get` shows a double
    assert described.type == 3 and "simulated time per wall second" in described.description  # PARAMETER_DOUBLE
    assert pose.type == 4 and "joint pose" in pose.description  # PARAMETER_STRING, though rcl typed `off` as a bool


# ==================================================================== 7. a destroyed node's services
def test_a_destroyed_nodes_services_leave_the_graph(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        machine, engine = transport.create_node("machine"), transport.create_node("engine")

        async def pause(request: TriggerRequest) -> TriggerResponse:
            return TriggerResponse(True, "paused")

        machine.create_service(Trigger, "/left_arm/sm/pause", pause)
        client = engine.create_client(Trigger, "/left_arm/sm/pause")
        assert (await client.call(TriggerRequest(), timeout=BOUND)).success
        machine.destroy()
        await _until(transport.clock, lambda: not ros_fake_graph.GRAPH.services.get("/left_arm/sm/pause"))
        assert not client.handle.service_is_ready()  # type: ignore[attr-defined]
        assert "/machine" not in transport.node_names() and machine.ros_node.destroyed  # type: ignore[attr-defined]

    run_real(lambda clock: with_transport(clock, body))


def test_destroying_a_node_while_its_service_answers_does_not_kill_the_executor(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        machine, engine = transport.create_node("machine"), transport.create_node("engine")
        entered = asyncio.Event()
        release = asyncio.Event()

        async def slow(request: TriggerRequest) -> TriggerResponse:
            entered.set()
            await release.wait()
            return TriggerResponse(True, "late")

        machine.create_service(Trigger, "/left_arm/sm/stop", slow)
        call = asyncio.ensure_future(engine.create_client(Trigger, "/left_arm/sm/stop").call(TriggerRequest(), timeout=BOUND))
        await transport.clock.wait_for(entered.wait(), BOUND)
        machine.destroy()  # the response is still to be sent: the service must outlive it
        release.set()
        assert (await call).success
        await _until(transport.clock, lambda: not ros_fake_graph.GRAPH.services.get("/left_arm/sm/stop"))
        assert transport.spin_error is None and transport._thread.is_alive()

    run_real(lambda clock: with_transport(clock, body))


# =============================================================================== 8. /rosout
def test_logs_reach_rosout_and_honour_log_level(fake_rclpy: Any) -> None:
    async def body(node: Node, outcome: Outcome) -> None:
        node.logger.info("hello from %s", node.name)
        node.logger.debug("details")
        logging.getLogger("robot_bridges.nextage_sim").warning("a module speaks")

    assert run_node("engine", body, ["engine"]) == ExitCode.OK
    assert ("engine", 20, "hello from engine") in ros_fake_logging.ROSOUT  # and several severities from one handler
    assert not [r for r in ros_fake_logging.ROSOUT if r[2] == "details"]
    assert ("engine", 30, "[robot_bridges.nextage_sim] a module speaks") in ros_fake_logging.ROSOUT
    ros_fake_logging.ROSOUT.clear()
    assert run_node("engine", body, ["engine", "--ros-args", "--log-level", "debug"]) == ExitCode.OK
    assert ("engine", 10, "details") in ros_fake_logging.ROSOUT
